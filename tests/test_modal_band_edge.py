"""The default upper band edge of identification (issue 23): FRFs whose coherence falls for good at
the top of the record's band (an anti-aliasing or decimation filter's roll-off, the end of a sweep)
are fitted only below it; --fmax overrides it; the band fitted and why are stated."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from flexmodal.fixtures.modal_sim import modal_frf
from flexmodal.modal.compute import frf_of_record
from flexmodal.modal.identify import coherent_top, identify
from flexmodal.modal.sweep import sweep_plan
from flexmodal.modal.uff import read_uff

FN, ZETA = np.array([12.0, 31.0, 55.0]), np.array([0.01, 0.01, 0.01])
PHI = np.array([[1.0, 0.8, 0.3], [0.5, -0.6, 0.9]])
F = np.arange(0.0, 100.0 + 1e-9, 0.05)
# coherence 0.99 to 85 Hz, then falling linearly to 0.4 at 100 Hz: 0.9 at 85 + 15 * 0.09 / 0.59 Hz
COH = np.where(F < 85.0, 0.99, 0.99 - 0.59 * (F - 85.0) / 15.0)[None, :].repeat(2, axis=0)
EDGE_HZ = F[F <= 85.0 + 15.0 * 0.09 / 0.59].max()   # the last line before 87.288 Hz: 87.25 Hz


def _frfs() -> np.ndarray:
    """Three modes, and above the edge the response of a filter's roll-off plus noise (what a
    measurement there gives), seeded."""
    H = modal_frf(F, FN, ZETA, PHI, PHI[:1, :])
    top = F > 88.0
    rng = np.random.default_rng(7)
    H[..., top] *= 1 / (1 + 1j * (F[top] - 88.0) / 2.0)
    H[..., top] += 0.3 * np.abs(H[..., top]) * (rng.standard_normal(H[..., top].shape)
                                                 + 1j * rng.standard_normal(H[..., top].shape))
    return H


def test_coherent_top_is_the_last_line_before_the_coherence_stays_low():
    assert coherent_top(F, COH) == EDGE_HZ
    assert coherent_top(F, np.ones_like(COH)) is None   # one average: the coherence says nothing
    dips = COH.copy()
    dips[:, (F > 40) & (F < 45)] = 0.2   # an antiresonance's dip inside the band ends nothing
    assert coherent_top(F, dips) == EDGE_HZ
    poor = np.where(F < 50.0, 0.99, 0.5)[None, :]   # half the record poorly measured: no band edge
    assert coherent_top(F, poor) is None


def test_default_band_ends_where_the_coherence_ends_and_fmax_overrides_it():
    H = _frfs()
    modes = identify(F, H, coherence=COH, quantity="accelerance")
    assert modes.band_freq_hz.max() == EDGE_HZ
    assert np.allclose(modes.freq_hz, FN, rtol=1e-4)
    assert modes.band_note.startswith("band fitted 0.05-87.25 Hz, from the first line above 0 Hz to the last "
                                      "line before the FRFs' coherence stays below 0.9 up to 100 Hz")
    manual = identify(F, H, coherence=COH, quantity="accelerance", fmin=5.0, fmax=60.0)
    assert manual.band_freq_hz.min() == 5.0 and manual.band_freq_hz.max() == 60.0
    assert manual.band_note == "band fitted 5-60 Hz, from --fmin to --fmax"
    keep = F <= 80.0   # FRFs without a coherence (e.g. stored in a UFF file): every line is fitted
    stored = identify(F[keep], H[..., keep], quantity="accelerance")
    assert stored.band_note == "band fitted 0.05-80 Hz, from the first line above 0 Hz to the highest line"


def test_the_decimated_chirp_record_is_fitted_below_its_aliased_top():
    """beam_ring_chirp (tests/data/realdata): a sweep record decimated 1000 -> 250 Hz, whose decimation
    filter's transition band lets aliases back in below Nyquist: its coherence falls for good above
    ~115 Hz, while the strong mode at 106.9 Hz stays in the band."""
    path = Path(__file__).parent / "data" / "realdata" / "beam_ring_chirp" / "beam_ring_chirp.uff"
    data = read_uff(path)
    starts = sweep_plan(data.samples[:, [0]])
    frf = frf_of_record(data.samples, data.sample_rate_hz, data.names, data.kinds, sweeps=starts,
                        where=str(path))
    f, coh = frf.freq_hz, frf.coherence.mean(axis=0)
    edge = coherent_top(f[f > 0], frf.coherence[:, f > 0])
    assert 115.0 < edge < 119.0 < f.max()   # docs/modal.md: 117.5 Hz
    assert coh[(f > 100.0) & (f <= 110.0)].mean() > 0.99   # the 106.9 Hz mode is well measured
    assert coh[f > edge].mean() < 0.8
