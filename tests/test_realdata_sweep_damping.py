"""The damping misses of two real-data entries (docs/modal.md, under the real-data scoreboard),
checked against an estimate independent of both flexmodal and the entries' reference tool: the free
decay each sine sweep leaves behind a mode once it has passed it (tests/free_decay.py, scipy only).

beam_ring_chirp (the two symmetric sweeps) and beam_ring_output_only (the two antisymmetric sweeps)
are records of the same beam-ring; their references are sdypy-EMA's LSCF on each pair of sweeps' FRFs,
with a damping range that is the spread over model orders (at least +-10 %).  For the same physical
modes those ranges are disjoint between the two entries (22.57 Hz: 0.142-0.173 % against
0.201-0.245 %; 90.1 Hz: 0.114-0.155 % against 0.178-0.218 %; 33.2 Hz: 0.581-0.744 % against
0.251-0.361 %), while the free decays of both kinds of sweep agree within a few per cent and lie outside
the reference's range where flexmodal's estimate misses it."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from free_decay import free_decay_damping

from flexmodal.modal.uff import read_uff

CORPUS = Path(__file__).resolve().parent / "data" / "realdata"
ENTRIES = {"beam_ring_chirp": "beam_ring_chirp.uff", "beam_ring_output_only": "beam_ring_outputs.uff"}
# each mode's band-pass half width [Hz]: narrow enough that the sweep (0.7 Hz/s at 11 Hz, 6 Hz/s at
# 90 Hz) leaves it within about a second, wide enough to keep the filter's own ring-down short
MODES_HZ = {11.23: 0.5, 22.57: 1.5, 33.25: 0.8, 58.3: 3.0, 65.45: 3.0, 90.12: 3.0}
CLEAN = 0.15   # rms log-envelope residual of a clean exponential decay (a beat or a weak channel: more)


def decays(entry: str) -> dict[float, np.ndarray]:
    """Damping ratios [-] of the clean free decays of each mode: both sweeps x both accelerations."""
    rec = read_uff(CORPUS / entry / ENTRIES[entry])
    acc = [k for k, kind in enumerate(rec.kinds) if kind == "acceleration"]
    half = rec.samples.shape[0] // 2                                      # two sweeps end to end
    out = {}
    for fn, half_band in MODES_HZ.items():   # a loop over modes
        fits = [free_decay_damping(rec.samples[k * half:(k + 1) * half, c].astype(float),
                                   rec.sample_rate_hz, fn, half_band) for k in range(2) for c in acc]
        out[fn] = np.array([z for z, rms in fits if rms < CLEAN])
    return out


def reference_range(entry: str, fn: float) -> tuple[float, float]:
    modes = json.loads((CORPUS / entry / "reference.json").read_text())["modes"]
    return tuple(next(m["damping_range"] for m in modes if abs(m["freq_hz"] / fn - 1) < 0.005))


@pytest.fixture(scope="module")
def free():
    return {entry: decays(entry) for entry in ENTRIES}


def test_the_free_decays_of_symmetric_and_antisymmetric_sweeps_agree(free):
    sym, asym = free["beam_ring_chirp"], free["beam_ring_output_only"]
    for fn in (22.57, 65.45, 90.12):   # a loop over modes both kinds of sweep ring clearly
        assert sym[fn].size >= 2 and asym[fn].size >= 2, (fn, sym[fn], asym[fn])
        both = np.concatenate([sym[fn], asym[fn]])
        assert np.ptp(both) < 0.08 * both.mean(), (fn, both)
    # the two entries' references for the same modes do not overlap
    for fn in (22.57, 33.25, 90.12):
        sym_range, asym_range = (reference_range(entry, fn) for entry in ENTRIES)
        assert sym_range[1] < asym_range[0] or asym_range[1] < sym_range[0], (fn, sym_range, asym_range)


@pytest.mark.parametrize("entry, fn", [("beam_ring_chirp", 22.57), ("beam_ring_chirp", 90.12),
                                       ("beam_ring_output_only", 11.23), ("beam_ring_output_only", 33.25),
                                       ("beam_ring_output_only", 58.3)])
def test_the_free_decays_lie_above_the_reference_range(free, entry, fn):
    lo, hi = reference_range(entry, fn)
    z = free[entry][fn]
    assert z.size >= 2 and z.min() > hi, (z, lo, hi)


@pytest.mark.slow   # two default identifications, ~6 s CPU
def test_default_identification_lies_within_ten_percent_of_the_free_decays(free):
    """flexmodal's default damping (pLSCF on the chirp's sweep FRF, SSI on the output-only record) of
    every mode whose free decays are clean: measured 0.93-1.05 times the nearest decay on the chirp
    (its reference range holds 3 of its 6 found modes) and 0.95-1.08 times on the output-only record
    (2 of 6); the widest gaps are the chirp's 33.24 Hz, 0.518 % against decays of 0.558-0.580 %, and
    the output-only 58.32 Hz, 0.312 % against 0.288-0.289 %."""
    from flexmodal import api

    for entry, modes in free.items():   # a loop over the two entries
        table = api.identify(CORPUS / entry / ENTRIES[entry]).to_frame()
        for fn, z in modes.items():
            if z.size < 2:   # the chirp's 58.3 Hz rings clearly in neither channel
                continue
            k = int(np.argmin(np.abs(table["freq_hz"].to_numpy() - fn)))
            assert abs(table["freq_hz"].iloc[k] / fn - 1) < 0.005, (entry, fn, table["freq_hz"].iloc[k])
            assert 0.9 * z.min() <= table["damping_ratio"].iloc[k] <= 1.1 * z.max(), (entry, fn, z)
