"""The acquisition protocol registry, light enough for the command line: listing its names imports no
driver.

Each entry is a subclass of daq.devices.Driver (the one driver interface); a session's ``protocol =``
accepts every registered name.  Built-ins are named here and imported on first use.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from flexmodal.checked_io.registry import Registry
from flexmodal.daq.errors import DaqError

if TYPE_CHECKING:
    from flexmodal.daq.devices import Device, Driver

PROTOCOLS: Registry[type[Driver]] = Registry("protocol", DaqError, {
    "serial": "flexmodal.daq.serial_driver:SerialDriver",
    "can": "flexmodal.daq.can_driver:CanDriver",
    "modbus": "flexmodal.daq.modbus_driver:ModbusDriver",
})


def register_protocol(name: str, driver: type[Driver] | str) -> type[Driver] | str:
    """Make ``protocol = name`` usable in sessions: ``driver`` a Driver subclass or ``"module:Class"``."""
    return PROTOCOLS.register(name, driver)


def unregister_protocol(name: str) -> None:
    """Remove the protocol ``name``."""
    PROTOCOLS.unregister(name)


def registered_protocols() -> tuple[str, ...]:
    """Names of the acquisition protocols, in registration order."""
    return PROTOCOLS.names()


def make_driver(device: Device, sample_rate_hz: float) -> Driver:
    """The driver of the registered protocol of ``device``, for a session sampled at ``sample_rate_hz``
    [Hz]."""
    return PROTOCOLS.entry(device.protocol)(device, sample_rate_hz)
