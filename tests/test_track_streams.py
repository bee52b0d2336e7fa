"""The moving arm streamed like a real one and tracked: `acquire` starts `sim serve --test moving` as an
slcan (LAWICEL) CAN adapter on a pty (examples/sessions/can-moving-sim.toml, 512 Hz, decoded with
fixtures/flexmodal_moving.dbc) and as a pymodbus TCP server on 127.0.0.1 (modbus-moving-sim.toml,
polled at 256 Hz); the stored runs are tracked (`fm.track`) and the modal map judged against the truth
model's frozen-pose modes solved afresh at each bin's pose.  Under a heavy load a link may lose samples:
the run then records a gap, tracking skips the windows holding it (counted) and the map stands on the
rest.  The Modbus simulator is a logger with a FIFO, polled by its sample counter: a starved poller
lags (an ``overrun`` event) and loses nothing the FIFO holds (600 s here); its 90 s test is marked slow."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from flexmodal import api
from flexmodal.daq.acquire import acquire
from flexmodal.daq.session import load_session
from flexmodal.daq.store import read_run
from flexmodal.fixtures.moving_arm import frozen_truth
from flexmodal.fixtures.rig_sim import DEMO_RIG
from flexmodal.fixtures.sim_can import sim_dbc
from flexmodal.fixtures.sim_source import MOVING_ORDERS, MOVING_PERIOD_S, MOVING_SPAN_DEG
from flexmodal.models.rig import load_rig

pytestmark = pytest.mark.timeout(1800)  # 12-90 s of streaming each, simulator start-up and tracking

REPO = Path(__file__).resolve().parents[1]
GEAR_RATIO = 100.0


def _session(tmp_path: Path, name: str) -> Path:
    text = (REPO / "examples" / "sessions" / name).read_text()
    text = text.replace('"../rigs/demo_arm.toml"', f'"{DEMO_RIG}"')
    text = text.replace('"../../fixtures/', f'"{REPO}/fixtures/')
    # the simulated adapter holds what a CPU-starved acquisition leaves unread for 10 min instead of 1 s
    # (at a load of 20 so many batches overran that no window was whole and nothing could be tracked):
    # the map is judged on the stream, not on the machine's load; gaps are tested in test_daq_*
    fifo = "modbus_fifo_s = 600.0\n" if name.startswith("modbus") else ""  # Modbus: a logger's FIFO
    text = text.replace("[simulator]\n", f"[simulator]\noverrun_after_s = 600.0\n{fifo}", 1)
    path = tmp_path / name
    path.write_text(text)
    return path


def _recorded(tmp_path: Path, name: str, duration_s: float):
    out = tmp_path / "moving.h5"
    acquire(load_session(_session(tmp_path, name)), out, duration_s=duration_s, quiet=True, run_id="m1")
    run = read_run(out, "m1")
    names = [c.name for c in run.channels]
    enc = run.samples[:, names.index("enc_elbow")]
    if "counter" in names:   # Modbus: the device's sample counter (equal to the row; a lost one is NaN)
        index = run.samples[:, names.index("counter")]
    else:
        index = next(iter(json.loads(run.attrs["first_index"]).values())) + np.arange(enc.size)
    t = index / run.sample_rate_hz
    expected = MOVING_SPAN_DEG * 0.5 * (1 - np.cos(2 * np.pi * t / MOVING_PERIOD_S))
    kept = np.isfinite(enc)
    np.testing.assert_allclose(enc[kept], expected[kept], atol=360 / 4096)   # one count of the encoder
    return out, run


def _check_map(out: Path, fmax_hz: float, n_modes: int):
    """Bins of the tracked map against the frozen-pose truth mode each is nearest to: >= 80 % within 1 %,
    all within 3 % (where a harmonic crosses a mode its pull shows; the other mode is >= 60 % away), every
    truth mode below ``fmax_hz`` found, and no track on a harmonic of the elbow's motor."""
    result = api.track(str(out), fmax=fmax_hz)
    rig = load_rig(DEMO_RIG)
    frame = result.table.frame
    found, err = set(), []
    for _, row in frame.iterrows():
        truth = frozen_truth(rig, {"theta_deg": row["pose.theta_deg"]}, fmax_hz)[0]
        k = int(np.argmin(np.abs(truth / row["freq_hz"] - 1)))
        err.append(abs(row["freq_hz"] / truth[k] - 1))
        found.add(k)
    assert found == set(range(n_modes))
    assert max(err) < 0.03 and np.mean(np.array(err) < 0.01) >= 0.8, err
    orders = np.array(MOVING_ORDERS) * GEAR_RATIO
    for tr in result.tracks:
        speed = np.array([abs(result.windows[i].rate_deg_per_s["theta_deg"]) / 360 for i in tr.windows])
        on_order = np.abs(tr.freq_hz[:, None] - speed[:, None] * orders[None, :]) < 0.02 * tr.freq_hz[:, None]
        assert on_order.any(axis=1).mean() < 0.5
    assert (result.gapped > 0) == any("lost samples" in w for w in result.warnings)
    return result


def test_moving_dbc_is_the_generators():
    import cantools

    shipped = cantools.database.load_file(str(REPO / "fixtures" / "flexmodal_moving.dbc"))
    generated = sim_dbc(["a1", "a2", "a3", "a4", "a5", "enc_elbow"])
    spec = lambda db: sorted((s.name, s.start, s.length, s.scale, s.multiplexer_ids)   # noqa: E731
                             for s in db.get_message_by_name("FlexScan").signals)
    assert spec(shipped) == spec(generated)


def test_moving_arm_over_can_slcan_recorded_and_tracked(tmp_path):
    """12 s over slcan at 512 Hz (elbow 0 -> 25 deg; harmonics of two orders cross the two modes): the
    two modes below 230 Hz tracked.  (The claim holds as on the 20 s, 0 -> 62 deg it used: the source's
    record written directly and tracked put every bin within 0.72 % of the truth on 20 s, 0.44 % on
    12 s and 0.53 % on 10 s, both modes found; the stored run holds exactly duration x rate samples.)"""
    out, run = _recorded(tmp_path, "can-moving-sim.toml", 12.0)
    assert run.excitation == "operational" and run.sample_rate_hz == 512.0
    _check_map(out, 200.0, 2)


@pytest.mark.slow   # 90 s streamed, then tracked: 110 s at a load of 5
def test_moving_arm_over_modbus_tcp_recorded_and_tracked(tmp_path):
    """90 s polled over Modbus TCP at 256 Hz, the simulator's whole period (elbow 0 -> 150 -> 0 deg, every
    pose bin crossed twice): the mode below 60 Hz tracked.  A window's frequency errs by 0.8-0.9 % rms
    (that of the first mode in the stream's frozen excitation, correlated over ~4 hops of its 2.4 s
    windows), so on the 30 s outward third (0 -> 113 deg, one crossing, ~1 independent window per 5-deg
    bin) a bin was within 1 % with a chance near the test's 80 %: 17, 17, 18 of 21 bins as harmonic
    3600 was removed at orders 3599.0, 3599.5 and 3600.0; the source's record tracked directly with
    seeds 0-4 gave 81, 90, 82, 95 and 77 % of its bins within 1 %.  Two crossings average two
    independent stretches: on the 90 s of the same seeds 94, 100, 97, 97 and 94 % of 31 bins, the
    largest error 1.45 % (a stored 30 s run tracked exactly as the source's record; streamed twice at a
    load of 5-11 the poller of the time lost 57 and 66 % of the samples after the first 15-30 s: 20 of 23
    and 9 of 10 bins within 1 %; polled by the counter, 30 s streamed at a load of 9 and of 16 lost none
    of 7680 samples, every row its own sample, with one ``overrun`` event each)."""
    out, run = _recorded(tmp_path, "modbus-moving-sim.toml", 90.0)
    counter = run.samples[:, 0]
    kept = np.isfinite(counter)
    np.testing.assert_array_equal(counter[kept], np.flatnonzero(kept))   # every row its own sample
    _check_map(out, 60.0, 1)
