"""HDF5 run store: the docs/hdf5-format.md layout with plain h5py, round trip, appending runs, SWMR and
SIGKILL."""

from __future__ import annotations

import json
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

import h5py
import numpy as np
import pytest

from flexmodal.daq.errors import DaqError
from flexmodal.daq.h5file import _lookup3, recover
from flexmodal.daq.store import Channel, Event, RunWriter, list_runs, read_run

REPO = Path(__file__).resolve().parents[1]

CHANNELS = (
    Channel("hammer", "force", "N", 2.25, "mV/N", "link2@0.9", "+y"),
    Channel("a1", "acceleration", "m/s^2", 10.2, "mV/g", "link1@0.5", "transverse"),
    Channel("sg1", "strain", "µε", 2.0, "µε/V", "link1@0.1", "axial"),
    Channel("enc1", "encoder", "deg", 4096.0, "counts/rev", "shoulder", ""),
)


def _write_run(path: Path, run_id: str, samples: np.ndarray, events=()) -> None:
    with RunWriter(path, run_id, sample_rate_hz=2048.0, channels=CHANNELS, excitation="impact",
                   pose={"theta_deg": 60, "payload_kg": 0}, attrs={"notes": "bench", "n_hits": 5}) as w:
        for block in np.array_split(samples, 7):
            w.append(block)
        for e in events:
            w.add_event(e)


# Uses only h5py and json: the layout must be readable with no flexmodal import.
PLAIN_H5PY_CHECK = r"""
import json, sys, h5py
f = h5py.File(sys.argv[1], "r")
run = f["runs"][sys.argv[2]]
a = run.attrs
assert isinstance(a["sample_rate_hz"], float) and a["sample_rate_hz"] == 2048.0
from datetime import datetime
datetime.fromisoformat(a["start_time"])
assert a["excitation"] in ("impact", "random", "sweep", "free-decay", "operational")
assert json.loads(a["pose"]) == {"theta_deg": 60, "payload_kg": 0}
s = run["samples"]
assert s.ndim == 2 and s.dtype.kind == "f" and s.chunks is not None and s.maxshape[0] is None
ch = run["channels"]
assert set(ch.dtype.names) >= {"name", "kind", "unit", "sensitivity", "sensitivity_unit", "location",
                               "direction"}
assert len(ch) == s.shape[1]
ev = run["events"]
assert set(ev.dtype.names) >= {"kind", "sample_index", "count", "detail"}
print(json.dumps({"shape": list(s.shape), "names": [n.decode() for n in ch["name"]],
                  "units": [u.decode() for u in ch["unit"]],
                  "events": [[k.decode(), int(i), int(c)] for k, i, c in zip(ev["kind"], ev["sample_index"],
                                                                            ev["count"])]}))
"""


def test_layout_readable_with_plain_h5py(tmp_path):
    path = tmp_path / "run.h5"
    samples = np.random.default_rng(1).normal(size=(5000, 4)).astype(np.float32)
    _write_run(path, "r1", samples, [Event("trigger", 1024), Event("corrupt", 3000, 2, "crc")])
    out = subprocess.run([sys.executable, "-c", PLAIN_H5PY_CHECK, str(path), "r1"], capture_output=True,
                         text=True, check=True, cwd=tmp_path)
    seen = json.loads(out.stdout)
    assert seen["shape"] == [5000, 4]
    assert seen["names"] == [c.name for c in CHANNELS]
    assert seen["units"] == ["N", "m/s^2", "µε", "deg"]
    assert seen["events"] == [["trigger", 1024, 1], ["corrupt", 3000, 2]]


def test_round_trip(tmp_path):
    path = tmp_path / "run.h5"
    samples = np.random.default_rng(2).normal(size=(3333, 4)).astype(np.float32)
    events = (Event("gap", 100, 40, "sequence 17->18"), Event("note", 0, 1, "ünïcode ok"))
    _write_run(path, "r1", samples, events)
    run = read_run(path, "r1")
    np.testing.assert_array_equal(run.samples, samples)
    assert run.channels == CHANNELS
    assert run.events == events
    assert run.sample_rate_hz == 2048.0 and run.excitation == "impact"
    assert run.pose == {"theta_deg": 60, "payload_kg": 0}
    assert run.attrs == {"notes": "bench", "n_hits": 5}


def _chunk_offsets(path: Path, run_id: str) -> list[int]:
    with h5py.File(path, "r") as f:
        d = f["runs"][run_id]["samples"]
        return [d.id.get_chunk_info(i).byte_offset for i in range(d.id.get_num_chunks())]


def test_partial_chunks_flushed_then_completed_stay_exact(tmp_path):
    """Whole chunks go to disk directly; a flushed partial chunk is later overwritten by the whole one."""
    path = tmp_path / "run.h5"
    x = np.random.default_rng(3).standard_normal((150_001, 4)).astype(np.float32)
    with RunWriter(path, "r", sample_rate_hz=1.0, channels=CHANNELS, excitation="random", pose={}) as w:
        for block in np.array_split(x, 61):
            w.append(block)
            w.flush()
            with h5py.File(path, "r", libver="latest", swmr=True) as f:  # what a reader sees meanwhile
                last = slice(w.n_samples - 5, w.n_samples)
                np.testing.assert_array_equal(f["runs/r/samples"][last], x[last])
    np.testing.assert_array_equal(read_run(path, "r").samples, x)


def test_closed_file_reopens_to_append_a_run(tmp_path):
    path = tmp_path / "runs.h5"
    first = np.arange(40000, dtype=np.float32).reshape(10000, 4)
    _write_run(path, "first", first)
    before = _chunk_offsets(path, "first")
    second = -first[:777]
    _write_run(path, "second", second)
    assert list_runs(path) == ["first", "second"]
    assert _chunk_offsets(path, "first") == before  # old run's data not moved or rewritten
    np.testing.assert_array_equal(read_run(path, "first").samples, first)
    np.testing.assert_array_equal(read_run(path, "second").samples, second)


def test_bad_input_is_one_line(tmp_path):
    with pytest.raises(DaqError, match="kind 'accel'"):
        Channel("a", "accel", "g")
    with pytest.raises(DaqError, match="event kind 'glitch'"):
        Event("glitch", 0)
    with pytest.raises(DaqError, match="excitation 'tap'"):
        RunWriter(tmp_path / "x.h5", "r", sample_rate_hz=1.0, channels=CHANNELS, excitation="tap", pose={})
    _write_run(tmp_path / "x.h5", "r", np.zeros((3, 4)))
    with pytest.raises(DaqError, match="already exists"):
        _write_run(tmp_path / "x.h5", "r", np.zeros((3, 4)))
    with pytest.raises(DaqError, match="no run 'q'"):
        read_run(tmp_path / "x.h5", "q")
    with pytest.raises(DaqError, match="does not exist"):
        _write_run(tmp_path / "nodir" / "x.h5", "r", np.zeros((3, 4)))


# Child: 16 channels at 10 kHz in 0.05 s blocks, paced in real time; value = sample index + channel/100.
# After each append it prints the samples appended so far and the time (RunWriter flushes every 0.5 s).
CHILD = r"""
import sys, time, numpy as np
from flexmodal.daq.store import Channel, RunWriter
ch = [Channel(f"c{i}", "voltage", "V") for i in range(16)]
w = RunWriter(sys.argv[1], "live", sample_rate_hz=10000.0, channels=ch, excitation="operational", pose={})
assert w.flush_interval_s == 0.5
t0 = time.monotonic(); n = 0
while True:
    block = (np.arange(n, n + 500)[:, None] + np.arange(16)[None, :] / 100).astype("f8")
    w.append(block); n += 500
    print(n, time.monotonic(), flush=True)
    time.sleep(max(0.0, t0 + n / 10000 - time.monotonic()))
"""


def test_sigkill_leaves_all_but_last_second(tmp_path):
    """SIGKILL loses only what was appended after the last flush: every block the writer had appended
    0.5 s (its flush interval) before its last completed append is in the file, counted on the
    writer's own clock, so the bound holds however the load delays it (every wait here is for an event,
    with a generous limit)."""
    path = tmp_path / "live.h5"
    child = subprocess.Popen([sys.executable, "-c", CHILD, str(path)], stdout=subprocess.PIPE, text=True,
                             cwd=REPO)
    reported: list[tuple[int, float]] = [(0, 0.0)]  # (samples appended, its time) per append

    def follow():
        for line in child.stdout:
            n, t = line.split()
            reported.append((int(n), float(t)))

    def wait_until(condition, what: str) -> None:
        deadline = time.monotonic() + 300  # a hang guard: the child's start alone takes a minute at load 40
        while not condition():
            assert time.monotonic() < deadline, f"no {what} within 300 s"
            assert child.poll() is None
            time.sleep(0.05)

    reader = threading.Thread(target=follow, daemon=True)
    reader.start()
    try:
        wait_until(lambda: reported[-1][0] >= 10000, "first second")
        with h5py.File(path, "r", libver="latest", swmr=True) as f:  # watch it grow from this process
            d = f["runs/live/samples"]
            first = d.shape[0]
            wait_until(lambda: d.refresh() or d.shape[0] >= first + 5000, "growth seen by a SWMR reader")
        wait_until(lambda: reported[-1][0] >= 40000, "four seconds of samples")
    finally:
        child.send_signal(signal.SIGKILL)
        child.wait()
    reader.join(timeout=60)
    assert not reader.is_alive()
    written, t_before_last = reported[-1][0], reported[-2][1]
    flushed = max(n for n, t in reported if t <= t_before_last - 0.5)
    run = read_run(path, "live")
    n = run.samples.shape[0]
    print(f"SIGKILL after {written} samples: {n} stored, {flushed} flushed for sure")
    assert flushed <= n <= written + 500
    expected = np.arange(n)[:, None] + np.arange(16)[None, :] / 100
    np.testing.assert_allclose(run.samples, expected, rtol=0, atol=0.01)  # float32 storage
    with pytest.raises(DaqError, match="not closed cleanly"):
        _write_run(path, "after", np.zeros((3, 4)))
    assert recover(path) and not recover(path)  # clears the killed writer's flags once
    _write_run(path, "after", np.ones((3, 4)))
    assert list_runs(path) == ["after", "live"]
    np.testing.assert_array_equal(read_run(path, "live").samples, run.samples)


def test_lookup3_known_answers():
    # Bob Jenkins' lookup3.c self-test values for hashlittle
    assert _lookup3(b"") == 0xDEADBEEF
    assert _lookup3(b"Four score and seven years ago") == 0x17770551
    assert _lookup3(b"Four score and seven years ago", 1) == 0xCD628161
