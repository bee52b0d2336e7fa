"""Where a change lands (docs/architecture.md): a new FRF estimator is one function plus one registry
entry in modal/frf.py, and the CLI, the stored provenance and the Python API all see it; one sign
convention for every mode shape; one home for the impact-window defaults."""

from __future__ import annotations

import h5py
import numpy as np
import pytest

from flexmodal.app import main
from flexmodal.contract.mac import largest_positive, to_real
from flexmodal.daq.store import Channel, RunWriter
from flexmodal.fixtures.modal_sim import modal_response
from flexmodal.modal import frf as frf_mod
from flexmodal.modal.compute import frf_of_record
from flexmodal.modal.registry import register_estimator, registered_estimators, unregister_estimator
from flexmodal.modal.windows import impact_windows, window

FS = 256.0
FN, ZETA = np.array([12.0, 31.0]), np.array([0.02, 0.01])
PHI = np.array([[1.0, 0.7], [0.4, -0.8]])
CHANNELS = (Channel("hammer", "force", "N"), Channel("a1", "acceleration", "m/s^2"),
            Channel("a2", "acceleration", "m/s^2"))


def _record(seed: int = 1, n: int = 4096) -> np.ndarray:
    rng = np.random.default_rng(seed)
    f = rng.standard_normal((n, 1))
    x = modal_response(f, FS, FN, ZETA, PHI, PHI[[0]])
    return np.column_stack([f, x + 0.05 * rng.standard_normal(x.shape)])


def _h_mean(s) -> np.ndarray:
    """A toy estimator: the arithmetic mean of H1 and H2."""
    return 0.5 * (frf_mod.h1(s) + frf_mod.h2(s))


@pytest.fixture
def toy_estimator():
    register_estimator("Hmean", _h_mean)   # one registry entry, undone afterwards
    yield "Hmean"
    unregister_estimator("Hmean")


def test_a_registered_estimator_reaches_compute_cli_and_provenance(toy_estimator, tmp_path, capsys):
    samples = _record()
    names, kinds = [c.name for c in CHANNELS], [c.kind for c in CHANNELS]
    ref = {e: frf_of_record(samples, FS, names, kinds, estimator=e, nfft=256) for e in ("H1", "H2")}
    toy = frf_of_record(samples, FS, names, kinds, estimator="hmean", nfft=256)
    assert toy.estimator == "Hmean"
    band = toy.freq_hz > 0
    np.testing.assert_allclose(toy.H[..., band], 0.5 * (ref["H1"].H + ref["H2"].H)[..., band], rtol=1e-12)

    path = tmp_path / "run.h5"
    with RunWriter(path, "r1", sample_rate_hz=FS, channels=CHANNELS, excitation="random", pose={}) as w:
        w.append(samples)
    assert main(["--quiet", "frf", str(path), "--estimator", "HMEAN", "--nfft", "256", "--workers", "0"]) == 0
    assert capsys.readouterr().out.strip() == f"{path}:r1"
    with h5py.File(path, "r") as f:
        assert f["runs/r1/frf"].attrs["estimator"] == "Hmean"
        np.testing.assert_allclose(f["runs/r1/frf/H"][()], toy.H.astype(f["runs/r1/frf/H"].dtype),
                                   rtol=1e-5, atol=1e-12)
    with pytest.raises(SystemExit):
        main(["frf", "--help"])
    assert "H1, H2, Hv, Hmean" in capsys.readouterr().out


def test_an_unknown_estimator_is_one_line_and_exit_2(tmp_path, capsys):
    assert main(["frf", str(tmp_path / "x.h5"), "--estimator", "H3"]) == 2
    err = capsys.readouterr().err.strip()
    assert "\n" not in err and "'H3'" in err and "'Hv'" in err


def test_register_estimator_replaces_a_name_of_another_case():
    register_estimator("h1", _h_mean)
    try:
        assert registered_estimators() == ("h1", "H2", "Hv") and frf_mod.estimator_name("H1") == "h1"
    finally:
        register_estimator("H1", frf_mod.h1)
    assert registered_estimators() == ("H1", "H2", "Hv")


def test_one_sign_convention_for_shapes():
    ref = np.array([[0.2, -3.0, 0.0], [-0.9, 1.0, 0.0]])
    np.testing.assert_array_equal(largest_positive(ref), [-1.0, -1.0, 1.0])
    assert largest_positive(np.zeros((0, 2))).tolist() == [1.0, 1.0]
    # complex shapes rotated to real keep the same convention: largest entry positive
    phi = np.array([[1 + 1j, -0.2], [-2 - 2j, 0.5 + 0.01j]])
    real = to_real(phi)
    np.testing.assert_allclose(real[:, 0], np.sqrt(2) * np.array([-1.0, 2.0]))
    assert real[1, 1] > 0 and abs(real[0, 1] / real[1, 1] + 0.4) < 1e-3


def test_impact_window_defaults_have_one_home():
    assert impact_windows(None) == ("force:0.05", "exponential:1")
    assert impact_windows("exponential:0.2") == ("force:0.05", "exponential:0.2")
    assert impact_windows("force:0.1,exponential") == ("force:0.1", "exponential:0.01")
    np.testing.assert_array_equal(window("force", 100), window("force:0.05", 100))
    assert window("force", 100).sum() == 5
