"""The Modbus driver's placement of answers, against a fake clock (no socket): without a counter an
answer that comes back too late is dropped as a gap, never stored at its slot, while an RTU link's
2-5 ms round trips keep every sample; with a uint16 counter a wrap is continuous, a restart is placed at
the wall-clock slot, a long silence keeps its length, a FIFO's backlog is not a restart, and a counter
faster than the session's rate is refused."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from flexmodal.daq import modbus_driver
from flexmodal.daq.errors import DaqError
from flexmodal.daq.modbus_driver import ModbusDriver
from flexmodal.daq.session import parse_session


class Clock:
    """time.monotonic/time/sleep of a clock that moves only when slept or advanced."""

    def __init__(self) -> None:
        self.t = 1000.0

    def monotonic(self) -> float:
        return self.t

    def time(self) -> float:
        return self.t

    def sleep(self, s: float) -> None:
        self.t += max(s, 0.0)


def _driver(fs: float, counter: bool) -> ModbusDriver:
    regs = [{"name": "value", "address": 0, "type": "uint16"}]
    dev = {"name": "plc", "protocol": "modbus", "port": 502, "register": regs} | (
        {"counter": "value"} if counter else {})
    doc = {"sample_rate_hz": fs, "device": [dev],
           "channel": [{"name": "value", "kind": "other", "unit": "count", "device": "plc"}]}
    return ModbusDriver(parse_session(doc, Path("session.toml")).devices[0], fs)


def _polled(monkeypatch, fs: float, round_trip_s, reads: int = 30) -> tuple[dict[int, int], ModbusDriver]:
    """Rows stored from a latest-value device whose value is the sample index (nearest sample) at the
    moment it answers, ``round_trip_s(k)`` the k-th poll's round trip [s]."""
    clock = Clock()
    monkeypatch.setattr(modbus_driver, "time", clock)
    d = _driver(fs, counter=False)
    d._t0 = clock.t
    polls = [0]

    def poll() -> list[int]:
        polls[0] += 1
        clock.t += round_trip_s(polls[0])
        return [int(np.floor((clock.t - d._t0) * fs + 0.5)) & 0xFFFF]

    d._poll = poll
    stored = {}
    for _ in range(reads):
        for b in d.read():
            stored |= {b.first_index + i: int(v) for i, v in enumerate(b.values[:, 0])}
    return stored, d


def test_an_answer_later_than_its_allowance_is_a_gap_not_another_samples_value(monkeypatch):
    fs = 200.0
    stored, d = _polled(monkeypatch, fs, lambda k: 0.3 if k == 40 else 0.001)  # the 40th answer 0.3 s late
    rows = np.array(sorted(stored))
    assert {k: v for k, v in stored.items() if v != k} == {}   # no row holds another sample's value
    missing = np.setdiff1d(np.arange(rows[-1] + 1), rows)
    assert missing[0] == 39 and missing.size >= 0.3 * fs   # the late answer's row starts the gap ...
    np.testing.assert_array_equal(missing, np.arange(39, 39 + missing.size))  # ... one gap, counted
    assert d.poll_counts()["missed"] == missing.size


def test_rtu_round_trips_of_2_to_5_ms_at_a_5_ms_period_keep_every_sample(monkeypatch):
    rng = np.random.default_rng(0)
    stored, d = _polled(monkeypatch, 200.0, lambda k: rng.uniform(0.002, 0.005))
    rows = np.array(sorted(stored))
    np.testing.assert_array_equal(rows, np.arange(rows.size))
    assert rows.size > 250 and d.poll_counts()["missed"] == 0


def _placed(fs: float, answers: list[tuple[float, int]]) -> list[int | None]:
    """Indices the counter mode gives answers (time [s], uint16 counter)."""
    d = _driver(fs, counter=True)
    return [d._sample_index([raw], t) for t, raw in answers]


def test_a_uint16_counter_wraps_continuously():
    fs = 256.0
    placed = _placed(fs, [(k / fs, c) for k, c in enumerate([65534, 65535, 0, 1])])
    assert placed == [65534, 65535, 65536, 65537]


def test_a_restarted_device_is_placed_at_the_wall_clock_slot():
    """60000 at t = 0, power-cycled, 5 s later it answers 1280 (5 s at 256 Hz since its restart): that is
    sample 60000 + 5 s x 256 Hz, not 1280 - 60000 + 65536 = 6816 samples (26.6 s) on."""
    fs = 256.0
    d = _driver(fs, counter=True)
    assert d._sample_index([59999], -1 / fs) == 59999 and d._sample_index([60000], 0.0) == 60000
    assert d._sample_index([1280], 5.0) == 60000 + 1280
    assert d._sample_index([1281], 5.0 + 1 / fs) == 60000 + 1281
    assert d.poll_counts()["missed"] == 1279


def test_a_silence_longer_than_the_counter_range_keeps_its_length():
    fs = 256.0   # 200 s silent: 51200 samples, more than half the uint16 range
    assert _placed(fs, [(0.0, 60000), (200.0, (60000 + 51200) % 65536)]) == [60000, 60000 + 51200]


def test_a_fifo_backlog_after_a_silence_is_not_a_restart():
    fs = 256.0   # 3 s silent, then the logger hands out its oldest samples, 3 s behind
    assert _placed(fs, [(0.0, 60000), (3.0, 60001), (3.0, 60002)]) == [60000, 60001, 60002]


def test_a_counter_faster_than_the_session_rate_is_refused():
    d = _driver(200.0, counter=True)   # polled at 800 Hz, counting at 400 Hz
    with pytest.raises(DaqError, match=r"'value' advanced .* 400 Hz, not the session's 200 Hz"):
        for k in range(8000):
            d._sample_index([(k // 2) & 0xFFFF], k / 800.0)


def test_a_logger_draining_a_backlog_is_not_taken_for_a_fast_counter():
    """A FIFO holding 3 s at the start, drained at 400 polls/s, then polled at 400 polls/s for 10 s."""
    fs = 200.0
    d = _driver(fs, counter=True)
    t = np.arange(5200) / 400.0
    held = np.minimum(np.arange(5200), (t * fs).astype(int) + 600)   # the oldest sample not read yet
    placed = [d._sample_index([int(c) & 0xFFFF], float(s)) for s, c in zip(t, held, strict=True)]
    kept = [p for p in placed if p is not None]
    assert kept == list(range(held[-1] + 1)) and d.poll_counts()["missed"] == 0
