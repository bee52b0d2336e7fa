"""A protocol registered from outside flexmodal (the toy driver of tests/toys/toy_protocol.py), the writer's
overrun warning, and per-device release of rows on the timeline."""

from __future__ import annotations

import importlib
import sys
from types import SimpleNamespace

import numpy as np
import pytest

from flexmodal.daq.acquire import acquire
from flexmodal.daq.devices import Block
from flexmodal.daq.protocols import registered_protocols, unregister_protocol
from flexmodal.daq.session import ChannelMap, load_session
from flexmodal.daq.store import Channel, read_run
from flexmodal.daq.timeline import Timeline

SESSION = """
sample_rate_hz = 1000.0
[[device]]
name = "toy1"
protocol = "toy"
rate_factor = {factor}
[[channel]]
name = "up"
kind = "voltage"
unit = "V"
device = "toy1"
[[channel]]
name = "down"
kind = "voltage"
unit = "V"
device = "toy1"
"""


@pytest.fixture(autouse=True)
def _toy_unregistered_after():
    yield
    if "toy" in registered_protocols():
        unregister_protocol("toy")
        sys.modules.pop("toys.toy_protocol", None)


def _toy_session(tmp_path, factor: float):
    importlib.import_module("toys.toy_protocol")   # registers the toy protocol (tests/toys/)
    path = tmp_path / "toy.toml"
    path.write_text(SESSION.format(factor=factor))
    return load_session(path)


def test_a_registered_protocol_records_exactly(tmp_path):
    session = _toy_session(tmp_path, 1.0)
    assert "toy" in registered_protocols()
    summary = acquire(session, tmp_path / "run.h5", duration_s=1.0, quiet=True)
    run = read_run(tmp_path / "run.h5", summary.run_id)
    i = np.arange(1000.0)
    np.testing.assert_array_equal(run.samples, np.column_stack([i, -i]))
    assert not run.events and summary.signal == 0 and not summary.error


def test_writer_behind_real_time_is_an_overrun_event_and_a_warning(tmp_path, capsys):
    session = _toy_session(tmp_path, 0.4)  # the device delivers 400 of the 1000 samples/s it should
    summary = acquire(session, tmp_path / "run.h5", duration_s=1.5, quiet=False)
    run = read_run(tmp_path / "run.h5", summary.run_id)
    over = [e for e in run.events if e.kind == "overrun"]
    assert len(over) == 1 and "behind real time" in over[0].detail
    assert over[0].count >= 1000  # at least 1 s behind when it fired
    assert "OVERRUN: the file lags real time" in capsys.readouterr().err


def _session(devices: dict[str, int], rate: float = 100.0):
    maps = tuple(ChannelMap(Channel(f"{d}{i}", "voltage", "V"), d, f"s{i}") for d, n in devices.items()
                 for i in range(n))
    return SimpleNamespace(sample_rate_hz=rate, channels=maps,
                           devices=tuple(SimpleNamespace(name=d) for d in devices))


def test_a_silent_device_is_padded_and_its_late_samples_dropped():
    tl = Timeline(_session({"a": 1, "b": 1}), {"a": ("s0",), "b": ("s0",)})
    col = lambda n, v: np.full((n, 1), v)
    tl.add(Block("a", 0, col(30, 1.0), 0.0))
    tl.add(Block("b", 0, col(10, 2.0), 0.0))
    assert tl.ready() == 10 and tl.ready(skip={"b"}) == 30
    tl.pad("b", 30)  # b silent: the writer releases a's rows without it
    rows = tl.take(30)
    assert np.isnan(rows[10:, 1]).all() and (rows[:, 0] == 1).all()
    tl.add(Block("a", 30, col(20, 1.0), 0.0))
    events = tl.add(Block("b", 20, col(25, 3.0), 0.0))  # back: rows 20..29 were released already
    assert [(e.kind, e.sample_index, e.count) for e in events] == [("gap", 10, 20)]
    rows = tl.take()
    assert rows.shape == (15, 2) and (rows[:, 1] == 3.0).all()
    tl.pad("b", 60)
    assert [(e.kind, e.sample_index, e.count) for e in tl.close_gaps(55)] == [("gap", 45, 10)]
