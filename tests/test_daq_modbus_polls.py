"""Polls that come late never invent a sample: `acquire` polls the pymodbus simulator on 127.0.0.1
(fixtures/sim_modbus.py) into a real HDF5 run while the device stalls.

The stall is injected deterministically (``drop_at_s``/``drop_s``: the device answers a read arriving in
that window only when it ends), not by loading the machine, and the driver's answer timeout is raised
above it.  A logger with a FIFO polled by its ``counter`` register: each answer is stored at the sample
it names, every stored row is the sample of its row, once, and the rows missing are exactly the samples
the device's FIFO dropped during the stall (its fault log).  A device whose registers hold the latest
sample (the simulator's default) polled without a counter: the stalled answer comes too late to be its
slot's value and is dropped, so it and every slot due while the poller waited are one gap, counted in the
run's ``polls`` attribute, and no row holds the value the device had when the stall ended.
"""

from __future__ import annotations

import json
import threading

import numpy as np
import pytest

from flexmodal.daq import modbus_driver
from flexmodal.daq.acquire import acquire
from flexmodal.daq.errors import DaqError
from flexmodal.daq.faults import Faults
from flexmodal.daq.session import parse_session
from flexmodal.daq.store import read_run
from flexmodal.fixtures.sim_common import FaultLog, FaultPlan
from flexmodal.fixtures.sim_modbus import free_port, serve
from flexmodal.fixtures.sim_source import SimChannel, SimSource

RATE_HZ = 200.0
DURATION_S = 1.2
STALL_AT_S, STALL_S = 0.2, 0.6  # stream time of the stall and how long it may last (< the answer timeout)
ANSWER_TIMEOUT_S = 5.0  # the driver's, raised: a stalled answer is never taken for a lost device
FIFO_S = 0.05  # the device buffers 10 samples: a stall longer than that loses samples


def _source() -> SimSource:
    """Two channels whose counts name their sample: n % 30000 and -(n % 20000)."""
    n = np.arange(1 << 14)
    chans = tuple(SimChannel(f"c{i}", "voltage", "mV", 1.0, "", 1.0, 1.0, "", "") for i in range(2))
    return SimSource(chans, RATE_HZ, np.column_stack([n % 30000, -(n % 20000)]).astype(np.int32))


def _session(port: int, counter: bool, tmp_path):
    regs = [{"name": "counter", "address": 0, "type": "uint32"}, {"name": "c0", "address": 2},
            {"name": "c1", "address": 3}]
    device = {"name": "plc", "protocol": "modbus", "transport": "tcp", "host": "127.0.0.1", "port": port,
              "register": regs} | ({"counter": "counter"} if counter else {})
    channels = [{"name": r["name"], "kind": "other", "unit": "count", "device": "plc"} for r in regs]
    doc = {"sample_rate_hz": RATE_HZ, "excitation": "operational", "device": [device], "channel": channels}
    return parse_session(doc, tmp_path / "session.toml")


def _record(tmp_path, monkeypatch, counter: bool):
    """The run, the device's fault log and the summary of a run through a stall of the device (a logger
    with a FIFO when polled by its counter, else a latest-value device)."""
    monkeypatch.setattr(modbus_driver, "ANSWER_TIMEOUT_S", ANSWER_TIMEOUT_S)
    log_path = tmp_path / "faults.jsonl"
    faults = FaultPlan(Faults(drop_at_s=STALL_AT_S, drop_s=STALL_S, modbus_fifo_s=FIFO_S if counter else 0.0))
    port, stop, ready = free_port(), threading.Event(), threading.Event()
    server = threading.Thread(target=serve, args=(_source(),), daemon=True, kwargs={
        "port": port, "faults": faults, "log": FaultLog(log_path), "stop": stop,
        "announce": lambda _: ready.set()})
    server.start()
    try:
        assert ready.wait(30)
        summary = acquire(_session(port, counter, tmp_path), tmp_path / "run.h5", duration_s=DURATION_S,
                          quiet=True, run_id="r")
    finally:
        stop.set()
        server.join(10)
    log = [json.loads(line) for line in log_path.read_text().splitlines()]
    return read_run(tmp_path / "run.h5", "r"), log, summary


def _gap_rows(run) -> np.ndarray:
    """Mask of the rows the run's gap events cover (none beyond the run)."""
    mask = np.zeros(run.samples.shape[0], bool)
    for e in run.events:
        if e.kind == "gap":
            assert e.sample_index + e.count <= mask.size
            mask[e.sample_index:e.sample_index + e.count] = True
    return mask


def test_a_stalled_device_polled_by_its_counter_loses_only_what_it_dropped(tmp_path, monkeypatch):
    run, log, summary = _record(tmp_path, monkeypatch, counter=True)
    n = run.samples.shape[0]
    assert n == DURATION_S * RATE_HZ and not [e for e in run.events if e.kind == "corrupt"]
    counter = run.samples[:, 0]
    good = np.isfinite(counter)
    rows = np.flatnonzero(good)
    # no sample invented: each stored row holds the sample of that row, once, with its own values
    np.testing.assert_array_equal(counter[good], rows)
    np.testing.assert_array_equal(run.samples[good, 1:], np.column_stack([rows % 30000, -(rows % 20000)]))
    # every missing row is a gap event, and they are exactly the samples the device dropped
    np.testing.assert_array_equal(~good, _gap_rows(run))
    assert np.isnan(run.samples[~good]).all()
    dropped = np.zeros(n, bool)
    for f in log:
        if f["fault"] == "overrun":
            dropped[f["first_index"]:f["first_index"] + f["n_samples"]] = True
    np.testing.assert_array_equal(~good, dropped)
    stall = next(f for f in log if f["fault"] == "stall")
    assert stall["n_samples"] > FIFO_S * RATE_HZ + 1   # the stall outlasted the FIFO: samples were lost ...
    assert (~good).sum() >= stall["n_samples"] - FIFO_S * RATE_HZ - 1   # ... all but what it buffered
    polls = json.loads(run.attrs["polls"])["plc"]
    assert polls["missed"] >= (~good).sum() and summary.polls == {"plc": polls}
    assert summary.polls_line().startswith(f"polls: plc {polls['missed']} samples missed in ")
    assert "counter" not in summary.polls_line()   # placed by its counter already: no hint


def test_without_a_counter_the_polls_a_stall_delays_are_gaps_not_caught_up(tmp_path, monkeypatch):
    run, log, summary = _record(tmp_path, monkeypatch, counter=False)
    counter = run.samples[:, 0]
    good = np.isfinite(counter)
    np.testing.assert_array_equal(~good, _gap_rows(run))
    stall = next(f for f in log if f["fault"] == "stall")
    # the poller waited for the stalled answer: it and every slot due meanwhile are one gap, none polled
    # late, and no row holds the value the device answered with when the stall ended (a row's value is
    # its slot's within half a period plus a round trip allowance: far less than the stall)
    assert max(e.count for e in run.events if e.kind == "gap") >= stall["n_samples"]
    assert np.abs(counter[good] - np.flatnonzero(good)).max() < stall["n_samples"] / 2
    polls = json.loads(run.attrs["polls"])["plc"]
    assert polls["missed"] >= (~good).sum()
    # one line, with the session file's field that would have placed the late answers
    assert summary.polls_line() == (f"polls: plc {polls['missed']} samples missed in {polls['polls']} polls "
                                    "(too late to read them: recorded as gaps); a counter = \"<register>\" "
                                    "field (the device's sample counter) in [[device]] plc lets the poller "
                                    "place late answers")


@pytest.mark.parametrize(("register", "why"), [
    ({"name": "n", "address": 9, "type": "int16"}, "must be uint16 or uint32"),
    ({"name": "n", "address": 9, "type": "uint16", "scale": 2.0}, "with scale 1 and offset 0"),
    (None, "is not one of its registers")])
def test_a_counter_register_is_an_unscaled_unsigned_register(tmp_path, register, why):
    device = {"name": "plc", "protocol": "modbus", "port": 502, "counter": "n",
              "register": [{"name": "c0", "address": 2}] + ([register] if register else [])}
    doc = {"sample_rate_hz": RATE_HZ, "device": [device],
           "channel": [{"name": "c0", "kind": "other", "unit": "count", "device": "plc"}]}
    with pytest.raises(DaqError, match=why):
        parse_session(doc, tmp_path / "session.toml")
