"""Library code leaves the process's global state as it found it: signal handlers and third-party log
levels a call sets for its own duration come back when it returns (api.serve_simulator may run inside a
Python session or a notebook; a Modbus session's driver runs inside the caller's process)."""

from __future__ import annotations

import io
import logging
import signal
import socket
import threading

import pytest

import flexmodal as fm
from flexmodal.daq.devices import Device, DeviceLost
from flexmodal.daq.modbus_driver import ModbusConfig, ModbusDriver, Register


def _state() -> tuple:
    return (signal.getsignal(signal.SIGINT), signal.getsignal(signal.SIGTERM),
            logging.getLogger("pymodbus").level)


def test_serve_simulator_restores_signal_handlers_and_the_pymodbus_log_level():
    before = _state()
    endpoint = io.StringIO()
    fm.serve_simulator("serial", duration=0.25, stdout=endpoint, quiet=True)
    assert endpoint.getvalue().strip()  # it served (the endpoint: the pty's link)
    assert _state() == before


def test_serve_simulator_runs_in_a_thread_other_than_the_main_one():
    """Python sets signal handlers only in the main thread: elsewhere the duration ends the serving."""
    endpoint, failed = io.StringIO(), []

    def run() -> None:
        try:
            fm.serve_simulator("serial", duration=0.25, stdout=endpoint, quiet=True)
        except Exception as exc:  # noqa: BLE001 - reported below
            failed.append(exc)

    thread = threading.Thread(target=run)
    thread.start()
    thread.join(120)
    assert not thread.is_alive() and failed == [] and endpoint.getvalue().strip()


def test_modbus_driver_restores_the_pymodbus_log_level_when_closed():
    with socket.socket() as s:  # a loopback port nobody listens on: the connection is refused
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    logger = logging.getLogger("pymodbus")
    before = logging.WARNING
    logger.setLevel(before)
    config = ModbusConfig("tcp", (Register("x", 0),), host="127.0.0.1", tcp_port=port, port=str(port))
    driver = ModbusDriver(Device("m", "modbus", config), 100.0)
    with pytest.raises(DeviceLost):
        driver.open()
    assert logger.level == logging.CRITICAL  # quiet while the driver is in use
    driver.close()
    assert logger.level == before
