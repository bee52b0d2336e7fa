"""CAN without a counter signal and with two DBC messages per scan, on python-can's virtual bus: frames are
placed by their (hardware-like) timestamps; every sample arrives exactly and a dropped frame is a missing
part of its scan, recorded as an event."""

from __future__ import annotations

import threading
import time

import can
import numpy as np
from cantools.database import Database
from cantools.database.can import Message, Signal
from stand_in import record_with

from flexmodal.daq.session import load_session

RATE = 500.0
DROP = 600  # scan whose second frame is never sent


def _dbc(path):
    sig = lambda tag, i: Signal(f"{tag.lower()}{i}", 16 * i, 16, "little_endian", is_signed=True)
    messages = [Message(0x200 + m, f"Scan{tag}", 8, [sig(tag, i) for i in range(4)])
                for m, tag in enumerate("AB")]
    path.write_text(Database(messages=messages).as_dbc_string())


def _values(k: np.ndarray) -> np.ndarray:
    """The 8 values of scans ``k``: a0 = k mod 30000 identifies the scan."""
    return np.column_stack([k % 30000] + [(k * (7 + j)) % 20001 - 10000 for j in range(7)]).astype(np.int16)


def _device(channel: str, stop: threading.Event) -> None:
    bus = can.Bus(interface="virtual", channel=channel, preserve_timestamps=True)
    listeners = can.interfaces.virtual.channels[channel]
    while len(listeners) < 2 and not stop.is_set():  # the acquisition's bus, however late it comes (a
        time.sleep(0.01)  # frame sent before it exists is lost: the dropped one would not be in the run)
    t0, k = time.time(), 0
    while not stop.is_set() and k < 20 * RATE:
        due = int((time.time() - t0) * RATE)
        for s in range(k, due):
            v = _values(np.array([s]))[0]
            ts = t0 + s / RATE
            bus.send(can.Message(arbitration_id=0x200, data=v[:4].tobytes(), timestamp=ts,
                                 is_extended_id=False))
            if s != DROP:
                bus.send(can.Message(arbitration_id=0x201, data=v[4:].tobytes(), timestamp=ts + 2e-4,
                                     is_extended_id=False))
        k = max(k, due)
        time.sleep(0.005)
    bus.shutdown()


def test_two_messages_without_counter_lossless_and_a_dropped_frame_detected(tmp_path):
    _dbc(tmp_path / "two.dbc")
    names = [f"a{i}" for i in range(4)] + [f"b{i}" for i in range(4)]
    channels = "".join(f'[[channel]]\nname = "{n}"\nkind = "voltage"\nunit = "count"\ndevice = "bus"\n'
                       for n in names)
    config = tmp_path / "can.toml"
    config.write_text(f'sample_rate_hz = {RATE}\n[[device]]\nname = "bus"\nprotocol = "can"\n'
                      f'interface = "virtual"\nchannel = "flexmodal-two-messages"\ndbc = "two.dbc"\n'
                      f'messages = ["ScanA", "ScanB"]\ncounter = ""\n{channels}')
    run = record_with(lambda stop: _device("flexmodal-two-messages", stop), load_session(config),
                      tmp_path / "run.h5", 3.0)
    n = int(3.0 * RATE)
    assert run.samples.shape == (n, 8)
    k = int(run.samples[0, 0]) + np.arange(n)  # the scans stored, from the first one received
    assert k[0] < DROP < k[-1], "the dropped frame fell outside the run"
    row = DROP - k[0]
    expected = _values(k).astype(float)
    expected[row, 4:] = np.nan  # the missing frame: its four signals, in its scan only
    np.testing.assert_array_equal(run.samples, expected)
    # (an `overrun` event only says the writer fell > 1 s behind real time: seen at load 10+, every sample
    # above still stored)
    lost = [(e.kind, e.sample_index, e.count) for e in run.events if e.kind != "overrun"]
    assert lost == [("corrupt", row, 1)]  # one part of one scan missing


def _stream_one(channel: str, arbitration_id: int, delay_s: float, stop: threading.Event) -> None:
    """A stand-in device sending one message per scan on ``channel``, from ``delay_s`` after the
    acquisition's bus has joined (a device still starting up, as a cold simulator on a loaded machine)."""
    bus = can.Bus(interface="virtual", channel=channel, preserve_timestamps=True)
    listeners = can.interfaces.virtual.channels[channel]
    while len(listeners) < 2 and not stop.is_set():
        time.sleep(0.01)
    stop.wait(delay_s)
    t0, k = time.time(), 0
    while not stop.is_set() and k < 20 * RATE:
        due = int((time.time() - t0) * RATE)
        for s in range(k, due):
            v = _values(np.array([s]))[0]
            bus.send(can.Message(arbitration_id=arbitration_id, data=v[:4].tobytes(), timestamp=t0 + s / RATE,
                                 is_extended_id=False))
        k = max(k, due)
        time.sleep(0.005)
    bus.shutdown()


def test_a_device_starting_later_than_the_lost_device_timeout_is_not_lost(tmp_path):
    """The lost-device clock of a device starts at its own first block: one that starts 1 s after the
    other (3 x reconnect_timeout_s) is recorded from then on, neither device is lost and the session
    completes.  (Before, the clock of a device that had not delivered yet ran from the other's first
    block.)  Being later than the delay never fails the test: no wall-clock bound."""
    _dbc(tmp_path / "two.dbc")
    devices, channels = "", ""
    for tag in "ab":
        devices += (f'[[device]]\nname = "{tag}"\nprotocol = "can"\ninterface = "virtual"\n'
                    f'channel = "flexmodal-late-{tag}"\ndbc = "two.dbc"\nmessages = ["Scan{tag.upper()}"]\n'
                    'counter = ""\n')
        channels += "".join(f'[[channel]]\nname = "{tag}{i}"\nkind = "voltage"\nunit = "count"\n'
                            f'device = "{tag}"\n' for i in range(4))
    config = tmp_path / "late.toml"
    config.write_text(f"sample_rate_hz = {RATE}\nreconnect_timeout_s = 0.3\n{devices}{channels}")

    def both(stop):
        late = threading.Thread(target=_stream_one, args=("flexmodal-late-b", 0x201, 1.0, stop), daemon=True)
        late.start()
        _stream_one("flexmodal-late-a", 0x200, 0.0, stop)
        late.join(5)

    run = record_with(both, load_session(config), tmp_path / "run.h5", 3.0)
    assert [e for e in run.events if e.kind in ("device_lost", "stopped")] == []
    assert run.samples.shape == (int(3.0 * RATE), 8)
    assert np.isfinite(run.samples[:, :4]).all()  # the device streaming from the start: every sample
    late = run.samples[:, 4:]
    started = int(np.argmax(np.isfinite(late[:, 0])))
    assert np.isfinite(late[:, 0]).any() and np.isfinite(late[started:]).all()
    k = late[started:, 0].astype(int)  # a0 of the late device counts its scans: none lost or repeated
    np.testing.assert_array_equal(np.diff(k), 1)
