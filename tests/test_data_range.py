"""Measured values near the float limits (checked_io.data_range): refused in one line naming the file and
the field, with no numpy warning on the way.

Before: a UFF of FRFs near 1.8e308 printed numpy's "RuntimeWarning: invalid value encountered in
subtract" and then "pLSCF: the FRFs are zero"; a random run stored 1e200 times too large printed three
RuntimeWarnings and ``frf`` wrote NaN FRFs with exit 0; an impact run so scaled said "every hit was
rejected (low coherence)"; values 1e-200 times too small said "the FRFs are zero" or "channel 'F' is
constant".  Every reader (HDF5 samples streamed or in memory, a stored FRF group, UFF dataset 58, FRFs
given to the API) now names the value, its place and the bound.  Real files (RunWriter, h5py, the UFF
writer), the command line in-process; about 2 s.
"""

from __future__ import annotations

import warnings

import h5py
import numpy as np
import pytest

import flexmodal as fm
from flexmodal.app import main
from flexmodal.daq.store import Channel, RunWriter, read_run
from flexmodal.modal.compute import compute_frf
from flexmodal.modal.runs_io import write_frf
from flexmodal.modal.uff import write_frfs

FS_HZ = 512.0
ABOVE = "above 1e+100 in magnitude (its squares overflow: is the unit right?)"
BELOW = "below 1e-100 (its squares underflow to 0: is the unit right?)"


def _run(path, scale: float, frf: bool = False):
    """A random test of one force and one response (a 40 Hz mode), its samples times ``scale`` (in
    float64), with its FRFs stored when ``frf``."""
    rng = np.random.default_rng(0)
    force = rng.standard_normal(8192)
    t = np.arange(200) / FS_HZ
    impulse = np.exp(-2 * np.pi * 40 * 0.02 * t) * np.sin(2 * np.pi * 40 * t)
    response = np.convolve(force, impulse)[:force.size]
    with RunWriter(path, "r1", sample_rate_hz=FS_HZ, excitation="random", pose={"theta_deg": 0.0},
                   channels=(Channel("F", "force", "N"), Channel("a1", "acceleration", "m/s^2"))) as w:
        w.append(np.column_stack([force, response]))
    with h5py.File(path, "a") as f:   # RunWriter stores float32, whose range ends at 3.4e38
        samples = f["runs/r1/samples"][()].astype(float) * scale
        del f["runs/r1/samples"]
        f.create_dataset("runs/r1/samples", data=samples, maxshape=(None, 2), chunks=True)
    if frf:
        write_frf(path, "r1", compute_frf(read_run(path, "r1"), nfft=512))
    return path


def _refused(argv: list[str], capsys) -> str:
    with warnings.catch_warnings(record=True) as seen:
        warnings.simplefilter("always")
        assert main(["--quiet", *argv]) == 2
    assert [str(w.message) for w in seen] == []
    err = capsys.readouterr().err
    assert err.count("\n") == 1, err
    return err


@pytest.mark.parametrize("method", ["lscf", "ssi"])   # Welch streamed from disk; SSI in memory
def test_samples_too_large_are_named_with_their_sample(tmp_path, capsys, method) -> None:
    run = _run(tmp_path / "big.h5", 1e200)
    err = _refused(["identify", str(run), "--method", method, "--out", str(tmp_path / "m.csv")], capsys)
    assert err.startswith(f"flexmodal: error: {run}:r1: ")
    assert "channel 'F'" in err and "at sample 0" in err and "above 1e+100 in magnitude" in err, err


def test_samples_too_small_are_named_not_called_constant(tmp_path, capsys) -> None:
    run = _run(tmp_path / "tiny.h5", 1e-200)
    err = _refused(["frf", str(run), "--out", str(tmp_path / "o.h5")], capsys)
    assert err.startswith(f"flexmodal: error: {run}:r1: channel 'F' is at most ")
    assert err.endswith(f"{BELOW}\n"), err


@pytest.mark.parametrize("scale", [1e200, 1e-200])
def test_a_stored_frf_group_out_of_range_is_named(tmp_path, capsys, scale) -> None:
    run = _run(tmp_path / "frf.h5", 1.0, frf=True)
    with h5py.File(run, "a") as f:
        f["runs/r1/frf/H"][...] = f["runs/r1/frf/H"][()] * scale
    err = _refused(["identify", str(run), "--out", str(tmp_path / "m.csv")], capsys)
    assert err.startswith(f"flexmodal: error: {run}: run 'r1': frf group: 'H' ")
    assert err.endswith(f"{ABOVE if scale > 1 else BELOW}\n"), err


@pytest.mark.parametrize("scale", [1e300, 1e-300])
def test_uff_frfs_out_of_range_are_named_with_their_point(tmp_path, capsys, scale) -> None:
    run = _run(tmp_path / "frf.h5", 1.0, frf=True)
    frf = compute_frf(read_run(run, "r1"), nfft=512)
    keep = frf.freq_hz > 0
    uff = tmp_path / "frf.uff"
    write_frfs(uff, fm.frf_from_arrays(frf.freq_hz[keep], frf.H[..., keep] * scale, outputs=["1+z"],
                                       inputs=["2+z"]))
    err = _refused(["identify", str(uff), "--out", str(tmp_path / "m.csv")], capsys)
    place = f"data point 1 (at {frf.freq_hz[keep][0]:g} on the abscissa) holds " if scale > 1 \
        else "data is at most "
    assert err.startswith(f"flexmodal: error: {uff}: dataset 58 record 1: {place}"), err
    assert err.endswith(f"{ABOVE if scale > 1 else BELOW}\n"), err


def test_frfs_given_to_the_api_out_of_range_are_named() -> None:
    f = np.linspace(0.0, 100.0, 401)
    s, w0 = 2j * np.pi * f, 2 * np.pi * 40.0
    H = s**2 / (s**2 + 2 * 0.02 * w0 * s + w0**2)
    with warnings.catch_warnings(record=True) as seen, pytest.raises(fm.FlexmodalError) as refused:
        warnings.simplefilter("always")
        fm.identify(fm.frf_from_arrays(f, H * 1e250, outputs=["tip"]))
    assert not seen
    assert str(refused.value).startswith("identify: H[0, 0, 0] holds ")
    assert str(refused.value).endswith(ABOVE)
