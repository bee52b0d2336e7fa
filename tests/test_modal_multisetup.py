"""Multi-setup OMA (modal/multisetup.py, PoSER): exact re-scaling of known shapes, and 3 setups x
(2 references + 3 roving) of an 11-storey shear frame under white noise of a different level in each
setup, merged into 11-point shapes compared with the exact modes."""

from __future__ import annotations

import numpy as np
import pytest

from flexmodal.contract.mac import mac, unit_max
from flexmodal.fixtures.shear_frame import shear_frame_modes, shear_frame_record
from flexmodal.modal.errors import ModalError
from flexmodal.modal.identify import Modes
from flexmodal.modal.multisetup import OmaSetup, merge_setups, ssi_multisetup

N = 11
MASS, STIFF = np.full(N, 2000.0), np.full(N, 1e8)        # modes 4.86 .. 70.5 Hz
NAMES = tuple(f"floor{i + 1}" for i in range(N))
REFS = [10, 5]
ROVING = [[0, 1, 2], [3, 4, 6], [7, 8, 9]]


def _setup(samples: np.ndarray, rows: list[int]) -> OmaSetup:
    cols = REFS + rows
    return OmaSetup(samples[:, cols], 256.0, tuple(NAMES[c] for c in cols), tuple(NAMES[c] for c in REFS))


def test_poser_recovers_known_shapes_from_arbitrarily_scaled_setups():
    rng = np.random.default_rng(0)
    fn, phi = shear_frame_modes(MASS, STIFF)
    setups, found = [], []
    for rows in ROVING:
        cols = REFS + rows
        scale = rng.normal(size=fn.size) * np.exp(1j * rng.uniform(0, 2 * np.pi, fn.size))  # per mode
        sh = phi[cols] * scale[None, :]
        found.append(Modes(fn, np.full(fn.size, 0.01), sh.real, sh, "ssi", False))
        setups.append(_setup(np.zeros((10, N)), rows))
    merged = merge_setups(found, setups)
    truth = unit_max(phi[[NAMES.index(p) for p in merged.points]])
    assert merged.points[:2] == (NAMES[10], NAMES[5]) and len(merged.points) == N
    assert np.allclose(merged.modes.complex_shapes, truth, atol=1e-12)
    assert np.allclose(merged.modes.freq_hz, fn) and np.all(merged.freq_spread_hz == 0)


def test_three_setups_of_the_shear_frame_merge_to_eleven_point_shapes():
    records = [shear_frame_record(MASS, STIFF, 0.01, duration_s=300.0, seed=10 + s,
                                  force_rms_N=100.0 * (1 + s)) for s in range(3)]
    setups = [_setup(rec.samples, rows) for rec, rows in zip(records, ROVING, strict=True)]
    merged = ssi_multisetup(setups, max_order=60)
    fn, phi = shear_frame_modes(MASS, STIFF)
    truth = phi[[NAMES.index(p) for p in merged.points]]
    assert merged.modes.freq_hz.size == N, merged.modes.freq_hz
    assert np.max(np.abs(merged.modes.freq_hz / fn - 1)) < 0.002
    assert np.diag(mac(merged.modes.shapes, truth)).min() >= 0.98


def test_a_mode_missing_from_one_setup_is_named_and_left_out():
    fn, phi = shear_frame_modes(MASS, STIFF)
    found, setups = [], []
    for k, rows in enumerate(ROVING):
        keep = np.arange(fn.size) if k != 1 else np.arange(1, fn.size)   # setup 2 lost mode 1
        sh = phi[REFS + rows][:, keep].astype(complex)
        found.append(Modes(fn[keep], np.full(keep.size, 0.01), sh.real, sh, "ssi", False))
        setups.append(_setup(np.zeros((10, N)), rows))
    merged = merge_setups(found, setups)
    assert merged.modes.freq_hz.size == N - 1
    assert "4.857 Hz" in merged.modes.warnings[0]


def test_bad_layouts_are_one_clear_error():
    rec = np.zeros((10, N))
    bad = OmaSetup(rec[:, :4], 256.0, NAMES[:4], (NAMES[10],))
    with pytest.raises(ModalError, match="lacks reference"):
        ssi_multisetup([_setup(rec, ROVING[0]), bad])
    with pytest.raises(ModalError, match="two setups"):
        ssi_multisetup([_setup(rec, ROVING[0]), _setup(rec, ROVING[0])])
    with pytest.raises(ModalError, match="0 sets of modes for 1 setups"):
        merge_setups([], [_setup(rec, ROVING[0])])
