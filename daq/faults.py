"""The faults a simulated device injects, defined once (light: the command line builds ``sim serve``'s
options from it without importing the run store)."""

from __future__ import annotations

from dataclasses import dataclass, field, fields
from typing import Any

from flexmodal.daq.errors import DaqError


def _fault(default: float | None, help: str, lo: float = 0.0, hi: float = 86400.0, *,
           lo_open: bool = False, hi_open: bool = False, stream_time: bool = False) -> Any:
    return field(default=default, metadata={"help": help, "range": {"lo": lo, "hi": hi, "lo_open": lo_open,
                                                                     "hi_open": hi_open},
                                            "stream_time": stream_time})


@dataclass(frozen=True)
class Faults:
    """The faults a simulated device injects, defined once: the keys of a session's ``[simulator]``
    table (docs/acquisition.md), the options of ``flexmodal sim serve`` (``--`` + the field name
    without ``_s``, dashed: ``drop_at_s`` is ``--drop-at``) and what the simulators read.  Each field's
    metadata holds its help and its range; a value outside it raises DaqError.

    Parameters
    ----------
    corrupt_rate : float
        Fraction [-] of frames corrupted, in [0, 1) (0.01 = 1 %).
    drop_at_s : float or None
        Time [s] into the stream at which a burst of frames is dropped (None: none).
    drop_s : float
        Length of the dropped burst [s].
    disconnect_after_s : float or None
        Time [s] after which the device disconnects (None: never).
    disconnect_s : float
        Length of the disconnect [s].
    double_hit_at_s : float or None
        Impact test: the hit nearest this time [s] into the record bounces back (a double hit).
    overload_at_s : float or None
        Impact test: the hit nearest this time [s] into the record overloads the ADC.
    overrun_after_s : float
        Serial and slcan: what the reader leaves unread this long [s] is dropped (the device's
        buffer overruns).
    modbus_fifo_s : float
        Modbus: 0 (default) the registers hold the latest sample, as a PLC's; > 0 the device is a logger
        whose FIFO holds this many seconds of samples, each read handing out the oldest one not read yet.
    """

    corrupt_rate: float = _fault(0.0, "fraction of frames corrupted (0.01 = 1 %%)", hi=1.0, hi_open=True)
    drop_at_s: float | None = _fault(None, "drop a burst of frames starting at S seconds", stream_time=True)
    drop_s: float = _fault(0.2, "length of the dropped burst, s", lo_open=True)
    disconnect_after_s: float | None = _fault(None, "disconnect after S seconds", stream_time=True)
    disconnect_s: float = _fault(0.5, "length of the disconnect, s", lo_open=True)
    double_hit_at_s: float | None = _fault(
        None, "impact test: the hit nearest S s into the record bounces back (a double hit)")
    overload_at_s: float | None = _fault(None, "impact test: the hit nearest S s into the record overloads "
                                               "the ADC")
    overrun_after_s: float = _fault(1.0, "serial/slcan: what the reader leaves unread this long, s, "
                                         "is dropped (the device's buffer overruns)", lo_open=True)
    modbus_fifo_s: float = _fault(0.0, "Modbus: a logger whose FIFO holds S s of samples, each read "
                                       "handing out the oldest (0: the registers hold the latest sample)")

    def __post_init__(self) -> None:
        """Refuse a fault outside its range (the Python API reaches here without the option types)."""
        for f in fields(self):
            value, r = getattr(self, f.name), f.metadata["range"]
            if value is None and f.default is None:
                continue
            number = isinstance(value, int | float) and not isinstance(value, bool)
            if not number or not ((value > r["lo"]) if r["lo_open"] else (value >= r["lo"])) or not (
                    (value < r["hi"]) if r["hi_open"] else (value <= r["hi"])):
                raise DaqError(f"fault {f.name} = {value!r} is not a number in {'(' if r['lo_open'] else '['}"
                               f"{r['lo']:g}, {r['hi']:g}{')' if r['hi_open'] else ']'}")

    def check_within(self, duration_s: float | None, duration: str, error: type[Exception],
                     flag=None) -> None:
        """Refuse a fault timed at or after the end of the stream (``duration_s``; None: no end): it
        would never fire, and the run would look like one that survived it.

        Parameters
        ----------
        duration_s : float or None
            How long the stream runs [s].
        duration : str
            How the caller names the duration (``--duration``, ``duration_s``).
        error : type
            The error family to raise.
        flag : callable, optional
            How the caller names a field (default: the field name itself).

        Examples
        --------
        >>> Faults(drop_at_s=5.0).check_within(2.0, "--duration", ValueError, fault_flag)
        Traceback (most recent call last):
        ...
        ValueError: --drop-at 5 s is not before the end of the stream (--duration 2 s): it would never happen
        """
        if duration_s is None:
            return
        for f in fields(self):
            value = getattr(self, f.name)
            if f.metadata["stream_time"] and value is not None and value >= duration_s:
                raise error(f"{(flag or str)(f.name)} {value:g} s is not before the end of the stream "
                            f"({duration} {duration_s:g} s): it would never happen")

    @property
    def on_link(self) -> bool:
        """Whether the link itself misbehaves (corruption, a dropped burst or a disconnect)."""
        return bool(self.corrupt_rate) or self.drop_at_s is not None or self.disconnect_after_s is not None


def fault_flag(name: str) -> str:
    """The ``sim serve`` option of a :class:`Faults` field.

    Parameters
    ----------
    name : str
        A field of :class:`Faults` (a time in seconds ends in ``_s``).

    Returns
    -------
    str
        The command-line option: the name without its unit suffix, dashed.

    Examples
    --------
    >>> fault_flag("drop_at_s")
    '--drop-at'
    """
    return "--" + name.removesuffix("_s").replace("_", "-")
