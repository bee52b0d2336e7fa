"""Shared helpers of the real-data corpus build: read a fetched snapshot, write UFF 58 the way an
analyser exports it, and compute reference modal tables with independent tools (sdypy-EMA's LSCF for
FRFs, pyOMA2's SSI for output-only records) — never with flexmodal.

Snapshots are read with ``git --git-dir <MIRROR>/<owner>+<name>/repo cat-file -p <commit>:<path>``,
where MIRROR is ``$REALDATA_MIRROR`` (default ``/work/.mirror``, where the search tool's ``fetch``
puts them).  Each build script pins the commit it read.
"""

from __future__ import annotations

import contextlib
import io
import json
import logging
import os
import subprocess
import warnings
from collections.abc import Iterator, Sequence
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[2]
CORPUS = ROOT / "tests" / "data" / "realdata"
MIRROR = Path(os.environ.get("REALDATA_MIRROR", "/work/.mirror"))


def git_dir(repo: str) -> Path:
    """Git directory of the fetched snapshot of ``owner/name``."""
    base = MIRROR / repo.replace("/", "+") / "repo"
    return base / ".git" if (base / ".git").is_dir() else base


def blob(repo: str, commit: str, path: str) -> bytes:
    """Bytes of ``path`` at ``commit`` in the fetched snapshot of ``repo``."""
    return subprocess.run(["git", "--git-dir", str(git_dir(repo)), "cat-file", "-p", f"{commit}:{path}"],
                          check=True, capture_output=True).stdout


def blob_to_file(repo: str, commit: str, path: str, dest: Path) -> Path:
    dest.parent.mkdir(parents=True, exist_ok=True)
    dest.write_bytes(blob(repo, commit, path))
    return dest


@contextlib.contextmanager
def blob_copy(repo: str, commit: str, path: str, dest: Path) -> Iterator[Path]:
    """``path`` at ``commit`` in ``repo`` copied to ``dest`` for a reader that wants a file name, and
    removed again on leaving."""
    try:
        yield blob_to_file(repo, commit, path, dest)
    finally:
        dest.unlink(missing_ok=True)


def entry_dir(name: str) -> Path:
    d = CORPUS / name
    d.mkdir(parents=True, exist_ok=True)
    return d


def write_json(path: Path, obj: dict) -> None:
    path.write_text(json.dumps(obj, indent=2, ensure_ascii=False) + "\n")


# ---------------------------------------------------------------------------------------- UFF writers

_SPEC = {"accelerance": 12, "mobility": 11, "receptance": 8}


def _header(h: dict) -> str:
    """The 11 ASCII records of a dataset 58 header, in the fixed-width layout of the UFF
    specification (the widths pyuff writes with)."""
    def ax(code: int, lab: str, units: str) -> str:
        return f"{code:10d}{0:5d}{0:5d}{0:5d} {lab:<20s} {units:<20s}\n"

    ids = "".join(f"{h.get(k, 'NONE'):<80s}\n" for k in ("id1", "id2", "id3", "id4", "id5"))
    rec6 = (f"{h['func_type']:5d}{0:10d}{0:5d}{h.get('load_case_id', 0):10d} {'NONE':>10s}{h['rsp_node']:10d}"
            f"{h['rsp_dir']:4d} {'NONE':>10s}{h['ref_node']:10d}{h['ref_dir']:4d}\n")
    rec7 = f"{h['ord_data_type']:10d}{h['num_pts']:10d}{1:10d}{h['x0']:13.5e}{h['dx']:13.5e}{0.0:13.5e}\n"
    return (ids + rec6 + rec7
            + ax(h["abscissa_spec"], h.get("abscissa_lab", "NONE"), h.get("abscissa_units", "NONE"))
            + ax(h["ordinate_spec"], h.get("ordinate_lab", "NONE"), h.get("ordinate_units", "NONE"))
            + ax(h["denom_spec"], "NONE", "NONE") + ax(0, "NONE", "NONE"))


def _write58b(path: Path, sets: list[tuple[dict, np.ndarray]]) -> None:
    """Dataset 58b (binary, little-endian, single precision) — what analysers export for long
    records.  pyuff's own 58b writer always writes doubles (and miscounts complex bytes), so the
    records are laid out here; every file is read back through pyuff by :func:`check_uff`."""
    tmp = path.with_suffix(path.suffix + ".tmp")
    with open(tmp, "wb") as fh:
        for h, data in sets:   # a loop over records
            values = (np.column_stack([data.real, data.imag]).ravel() if np.iscomplexobj(data) else data)
            raw = np.asarray(values, "<f4").tobytes()
            fh.write(f"{-1:6d}\n{58:6d}".encode())
            fh.write(f"b{1:6d}{2:6d}{11:12d}{len(raw):12d}{0:6d}{0:6d}{0:12d}{0:12d}\n".encode())
            fh.write(_header(h).encode())
            fh.write(raw)
            fh.write(f"{-1:6d}\n".encode())
    tmp.replace(path)


def write_frf_uff(path: Path, freq_hz: np.ndarray, H: np.ndarray, rsp: Sequence[tuple[int, int]],
                  ref: Sequence[tuple[int, int]], *, quantity: str = "accelerance", binary: bool = False,
                  id1: str = "FRF", id3: str = "NONE") -> None:
    """FRFs H [n_rsp, n_ref, n_freq] as dataset 58, function type 4, one set per pair; ``rsp``/``ref``
    are (node, direction code) pairs.  ``binary``: 58b with single-precision complex ordinates."""
    import pyuff

    freq_hz = np.asarray(freq_hz, float)
    if binary:
        sets = [({"id1": f"{id1} {rn}:{rd}/{fn}:{fd}", "id3": id3, "func_type": 4, "rsp_node": rn,
                  "rsp_dir": rd, "ref_node": fn, "ref_dir": fd, "ord_data_type": 5, "num_pts": freq_hz.size,
                  "x0": freq_hz[0], "dx": freq_hz[1] - freq_hz[0], "abscissa_spec": 18,
                  "abscissa_lab": "Frequency", "abscissa_units": "Hz", "ordinate_spec": _SPEC[quantity],
                  "denom_spec": 13}, np.asarray(H[o, i], complex))
                for o, (rn, rd) in enumerate(rsp) for i, (fn, fd) in enumerate(ref)]
        _write58b(path, sets)
        return
    sets = [pyuff.prepare_58(
        func_type=4, id1=f"{id1} {rn}:{rd}/{fn}:{fd}", id3=id3, rsp_node=rn, rsp_dir=rd, ref_node=fn,
        ref_dir=fd, ordinate_spec_data_type=_SPEC[quantity], orddenom_spec_data_type=13,
        abscissa_spec_data_type=18, data=np.asarray(H[o, i], complex), x=freq_hz, abscissa_spacing=1,
        abscissa_min=float(freq_hz[0]), abscissa_inc=float(freq_hz[1] - freq_hz[0]), num_pts=freq_hz.size)
        for o, (rn, rd) in enumerate(rsp) for i, (fn, fd) in enumerate(ref)]
    _write_ascii(path, sets)


def write_time_uff(path: Path, fs_hz: float, channels: Sequence[dict], *, id3: str = "NONE") -> None:
    """Time histories as dataset 58b, function type 1, single precision.  Each channel: ``node``,
    ``dir``, ``kind`` ('force' -> ordinate data type 13, 'acceleration' -> 12, 'velocity' -> 11),
    ``records`` (a list of 1-D arrays: one record, or one per hit, told apart by load
    case id 1, 2, ...), optional ``id1``."""
    spec = {"force": (13, "Force", "N"), "acceleration": (12, "Acceleration", "m/s2"),
            "velocity": (11, "Velocity", "m/s")}
    sets = []
    for ch in channels:   # a loop over channels
        records = ch["records"]
        code, lab, units = spec[ch["kind"]]
        for k, rec in enumerate(records):
            rec = np.asarray(rec, float)
            sets.append(({"id1": ch.get("id1", f"{lab} {ch['node']}:{ch['dir']}"), "id3": id3, "func_type": 1,
                          "load_case_id": k + 1 if len(records) > 1 else 0, "rsp_node": ch["node"],
                          "rsp_dir": ch["dir"], "ref_node": 0, "ref_dir": 0, "ord_data_type": 2,
                          "num_pts": rec.size, "x0": 0.0, "dx": 1.0 / fs_hz, "abscissa_spec": 17,
                          "abscissa_lab": "Time", "abscissa_units": "s", "ordinate_spec": code,
                          "ordinate_lab": lab, "ordinate_units": ch.get("units", units), "denom_spec": 0},
                         rec))
    _write58b(path, sets)


def _write_ascii(path: Path, sets: list[dict]) -> None:
    import pyuff

    tmp = path.with_suffix(path.suffix + ".tmp")
    tmp.unlink(missing_ok=True)
    pyuff.UFF(str(tmp)).write_sets(sets, mode="overwrite")
    tmp.replace(path)


def check_uff(path: Path, expected: list[np.ndarray]) -> None:
    """Read ``path`` back through pyuff and compare its dataset-58 ordinates with ``expected`` (in
    file order) to single precision."""
    import pyuff

    sets = pyuff.UFF(str(path)).read_sets()
    sets = [sets] if isinstance(sets, dict) else sets
    assert len(sets) == len(expected), (len(sets), len(expected))
    for s, e in zip(sets, expected, strict=True):
        got = np.asarray(s["data"])
        assert got.shape == np.shape(e), (got.shape, np.shape(e))
        scale = float(np.max(np.abs(e))) or 1.0
        assert np.max(np.abs(got - e)) <= 1e-6 * scale, np.max(np.abs(got - e)) / scale


# ------------------------------------------------------------------------------ reference modal tables

def ema_reference(freq_hz: np.ndarray, frf: np.ndarray, approx_hz: Sequence[float], *, lower: float,
                  upper: float, orders: Sequence[int] = (40, 60, 80), frf_form: str = "accelerance",
                  window_rel: float = 0.005, pick_spacing: float = 4.0) -> list[dict]:
    """Reference modes of FRFs [n_frf, n_freq] with sdypy-EMA (LSCF + stabilisation).

    For each highest model order in ``orders`` sdypy-EMA picks the stable pole closest to each
    approximate frequency (``select_closest_poles``); the reference value is the median over those
    picks, and its scatter the spread of the stable poles (within ``window_rel`` of it) over the upper
    half of the model orders of every run — the estimator's own sensitivity to its order; poles of
    negative damping (unstable, which sdypy-EMA can flag stable) are left out of it."""
    from sdypy import EMA

    # sdypy-EMA's pole picking narrows its window around each guess down to +-2 Hz; the frequency
    # axis is scaled so that the closest two guesses stand ``pick_spacing`` "Hz" apart (4: that last
    # window spans half their spacing; LSCF poles scale with it, damping ratios do not), and the
    # results scaled back.  The scale sets the picking windows only, and where LSCF gives a mode two
    # stable pole families (heavily damped modes of a single FRF) it decides which one is picked.
    guesses = np.sort(np.asarray(approx_hz, float))
    spacing = float(np.min(np.diff(guesses))) if guesses.size > 1 else float(guesses[0])
    scale = max(1.0, pick_spacing / spacing)
    picks_f, picks_z, pool = [], [], [[] for _ in approx_hz]
    for n in orders:   # a loop over reference runs
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            m = EMA.Model(frf=np.atleast_2d(frf), freq=np.asarray(freq_hz, float) * scale,
                          lower=lower * scale, upper=upper * scale, pol_order_high=int(n), frf_form=frf_form)
            m.get_poles(show_progress=False)
            m.select_closest_poles([a * scale for a in approx_hz], f_window=0.5 * spacing * scale)
        picks_f.append(np.asarray(m.nat_freq, float) / scale)
        picks_z.append(np.asarray(m.nat_xi, float))
        fs = np.asarray(m.f_stable, float) / scale
        for j, fr in enumerate(picks_f[-1]):
            if not fr > 0:   # no stable pole picked for this guess
                continue
            for k in range(fs.shape[1] // 2, fs.shape[1]):   # a loop over model orders
                col = fs[:, k]
                hit = np.flatnonzero((col > 0) & (np.abs(col / fr - 1) < window_rel))
                if hit.size:
                    pole = m.all_poles[k] / scale
                    wn = np.abs(pole)
                    zz = -np.real(pole) / wn
                    ff = wn / 2 / np.pi
                    best = np.argmin(np.abs(ff - col[hit[0]]))
                    if zz[best] > 0:   # sdypy-EMA's stability flags do not check the sign of damping
                        pool[j].append((ff[best], zz[best]))
    F, Z = np.array(picks_f), np.array(picks_z)
    possible = sum(n - n // 2 for n in orders)
    modes = []
    for j in range(len(approx_hz)):
        f0, z0 = float(np.median(F[:, j])), float(np.median(Z[:, j]))
        pf = np.array([p[0] for p in pool[j]] + list(F[:, j]))
        pz = np.array([p[1] for p in pool[j]] + list(Z[:, j]))
        mode = reference_mode(f0, z0, pf, pz, f"sdypy-EMA LSCF, orders {list(orders)}")
        # a pick that wandered off its guess (to a neighbour's poles: a quarter of the way to this
        # guess's nearest neighbour) confirms nothing
        others = np.delete(guesses, np.searchsorted(guesses, approx_hz[j]))
        own = float(np.min(np.abs(others - approx_hz[j]))) if others.size else float(approx_hz[j])
        wandered = abs(f0 / approx_hz[j] - 1) > min(0.01, 0.25 * own / approx_hz[j])
        mode["stable_share"] = 0.0 if wandered else round(len(pool[j]) / possible, 3)
        if wandered:
            mode["freq_hz"] = float(approx_hz[j])
        modes.append(mode)
    return modes


def split_confident(modes: list[dict], min_share: float = 0.5,
                    max_damping: float = 0.2) -> tuple[list[dict], list[float]]:
    """Reference modes whose stable poles appear in at least ``min_share`` of the model orders with a
    damping ratio below ``max_damping``, and the frequencies of the others (uncertain: neither
    required nor counted as extras)."""
    def ok(m: dict) -> bool:
        return (m["stable_share"] >= min_share and m.get("damping_ratio", 1.0) < max_damping
                and m.get("well_determined", True))

    return [m for m in modes if ok(m)], sorted({m["freq_hz"] for m in modes if not ok(m)})


def reference_mode(f0: float, z0: float, pf: np.ndarray, pz: np.ndarray, how: str) -> dict:
    """A reference mode with its scatter: frequency std and range; damping range, widened to at least
    +-10 % of the value (the spread any two good estimators of light damping show)."""
    lo, hi = float(np.min(pz)), float(np.max(pz))
    lo, hi = min(lo, 0.9 * z0), max(hi, 1.1 * z0)
    return {"freq_hz": round(f0, 6), "damping_ratio": float(f"{z0:.6g}"),
            "freq_scatter_hz": float(f"{np.std(pf):.3g}"),
            "freq_range_hz": [round(float(np.min(pf)), 6), round(float(np.max(pf)), 6)],
            "damping_range": [float(f"{lo:.6g}"), float(f"{hi:.6g}")], "n_estimates": int(pf.size),
            "estimator": how}


def tolerance_pct(modes: Sequence[dict]) -> float:
    """0.1 % where every reference frequency's scatter (std) is below a third of it, else 0.5 %."""
    worst = max(m["freq_scatter_hz"] / m["freq_hz"] for m in modes)
    return 0.1 if worst < 0.001 / 3 else 0.5


def reference_json(modes: list[dict], *, band_hz: Sequence[float], source: str, tol_pct: float | None = None,
                   notes: str = "", uncertain_hz: Sequence[float] = (), extra: dict | None = None) -> dict:
    """reference.json: the band, the tolerance, the reference modes, and ``uncertain_hz`` — candidate
    modes the reference could not confirm (an identified mode within 0.5 % of one is not an extra)."""
    return {"band_hz": [float(band_hz[0]), float(band_hz[1])],
            "tolerance_pct": tol_pct if tol_pct is not None else tolerance_pct(modes),
            "reference_source": source, "notes": notes, "modes": modes,
            "uncertain_hz": [round(float(f), 3) for f in uncertain_hz], **(extra or {})}


def stable_clusters(freq_hz: np.ndarray, frf: np.ndarray, *, lower: float, upper: float, order: int = 60,
                    frf_form: str = "accelerance", min_share: float = 0.5,
                    width_rel: float = 0.003) -> tuple[list[float], list[float]]:
    """Frequencies where sdypy-EMA's stable poles cluster (within ``width_rel``) in at least
    ``min_share`` of all the model orders up to ``order`` (persistent: an analyst's reading of the
    stabilisation chart), and those where they do so in the upper half of the orders (the orders
    :func:`ema_reference` counts a mode's stable share over)."""
    from sdypy import EMA

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        m = EMA.Model(frf=np.atleast_2d(frf), freq=np.asarray(freq_hz, float), lower=lower, upper=upper,
                      pol_order_high=order, frf_form=frf_form)
        m.get_poles(show_progress=False)
        m.select_closest_poles([0.5 * (lower + upper)])
    fs = np.asarray(m.f_stable, float)
    ok = fs > 0
    persistent = order_clusters(fs[ok], np.nonzero(ok)[1], fs.shape[1], min_share=min_share,
                                width_rel=width_rel)
    fs = fs[:, fs.shape[1] // 2:]
    ok = fs > 0
    return persistent, order_clusters(fs[ok], np.nonzero(ok)[1], fs.shape[1], min_share=min_share,
                                      width_rel=width_rel)


def h1(force: np.ndarray, resp: np.ndarray, fs_hz: float) -> tuple[np.ndarray, np.ndarray]:
    """H1 FRFs [n_resp, n_freq] averaged over hits or blocks: ``force`` [n_blocks, n], ``resp``
    [n_blocks, n_resp, n]; rectangular window (impact records that decay within the record)."""
    F = np.fft.rfft(force, axis=-1)
    Y = np.fft.rfft(resp, axis=-1)
    H = np.einsum("brf,bf->rf", Y, F.conj()) / np.sum(np.abs(F) ** 2, axis=0)
    return np.fft.rfftfreq(force.shape[-1], 1 / fs_hz), H


@contextlib.contextmanager
def _quiet_pyoma2() -> Iterator[None]:
    """pyOMA2's loggers at WARNING, and its stderr output and warnings swallowed, while inside."""
    import pyoma2.algorithms.ssi  # noqa: F401  (its loggers exist once it is imported)
    import pyoma2.setup.single  # noqa: F401

    for name in [n for n in logging.root.manager.loggerDict if n.startswith("pyoma2")]:
        logging.getLogger(name).setLevel(logging.WARNING)
    with contextlib.redirect_stderr(io.StringIO()), warnings.catch_warnings():
        warnings.simplefilter("ignore")
        yield


def _ssicov(y: np.ndarray, fs_hz: float, *, br: int, ordmax: int) -> tuple[object, object]:
    """One pyOMA2 SSI-cov run (``br`` block rows, orders to ``ordmax`` in steps of 2) on y
    [n_samples, n_channels]; returns its setup (for ``mpe``) and algorithm (with ``result``)."""
    from pyoma2.algorithms.ssi import SSI
    from pyoma2.setup.single import SingleSetup

    setup = SingleSetup(np.asarray(y, float), fs=fs_hz)
    alg = SSI(name="ssicov", method="cov", br=int(br), ordmax=ordmax, step=2)
    setup.add_algorithms(alg)
    setup.run_by_name("ssicov")
    return setup, alg


def oma_reference(y: np.ndarray, fs_hz: float, approx_hz: Sequence[float], *,
                  block_rows: Sequence[int] = (30, 40, 50), ordmax: int = 60) -> list[dict]:
    """Reference modes of output-only records y [n_samples, n_channels] with pyOMA2's SSI-cov: one run
    per number of block rows, ``mpe`` picking the stable pole nearest each approximate frequency
    (order_in="find_min"); value = median over runs, scatter = their spread (at least +-10 % on
    damping, as in :func:`reference_mode`).  ``picks_agree``: every run picked a pole, the runs agree
    within 0.5 % and the value lies within 1 % of its guess (what confirms an output-only mode);
    ``stable_share``: the share of the upper half of the model orders of every run holding a stable
    pole (label 1, damping 0-20 %) within 0.5 % of the value, as :func:`ema_reference` counts it (what
    tells an uncertain candidate from a rejected one)."""
    F = np.full((len(block_rows), len(approx_hz)), np.nan)
    Z = np.full_like(F, np.nan)
    stable = []   # per run: the stable poles of the upper half of its orders [order column, pole]
    for r, br in enumerate(block_rows):   # a loop over reference runs
        with _quiet_pyoma2():
            setup, alg = _ssicov(y, fs_hz, br=br, ordmax=ordmax)
            Fp, Xp, Lp = (np.asarray(a, float) for a in (alg.result.Fn_poles, alg.result.Xi_poles,
                                                         alg.result.Lab))
            upper = Fp[:, Fp.shape[1] // 2:]
            ok = (Lp[:, Fp.shape[1] // 2:] == 1) & (Xp[:, Fp.shape[1] // 2:] > 0) & (
                Xp[:, Fp.shape[1] // 2:] < 0.2)
            stable.append(np.where(ok, upper, np.nan))
            for j, guess in enumerate(approx_hz):   # one pick per guess: a guess without poles is NaN
                setup.mpe("ssicov", sel_freq=[float(guess)], order_in="find_min")
                if np.size(alg.result.Fn):
                    F[r, j], Z[r, j] = float(np.ravel(alg.result.Fn)[0]), float(np.ravel(alg.result.Xi)[0])
    modes = []
    for j, guess in enumerate(approx_hz):
        if np.isnan(F[:, j]).all():
            modes.append({"freq_hz": float(guess), "stable_share": 0.0, "picks_agree": False})
            continue
        f0, z0 = float(np.nanmedian(F[:, j])), float(np.nanmedian(Z[:, j]))
        how = f"pyOMA2 SSI-cov, block rows {list(block_rows)}, orders to {ordmax}"
        ok = ~np.isnan(F[:, j])
        mode = reference_mode(f0, z0, F[ok, j], Z[ok, j], how)
        near = [np.any(np.abs(s / f0 - 1) < 0.005, axis=0) for s in stable]   # per order column
        share = float(np.sum([n.sum() for n in near]) / np.sum([n.size for n in near]))
        mode["stable_share"] = round(share, 3) if abs(f0 / guess - 1) < 0.01 else 0.0
        mode["picks_agree"] = bool(ok.all() and abs(f0 / guess - 1) < 0.01 and np.ptp(F[:, j]) / f0 < 0.005)
        if not ok.all() or abs(f0 / guess - 1) >= 0.01:
            mode["freq_hz"] = float(guess)
        modes.append(mode)
    return modes


# ------------------------------------------------------------------ candidate modes: one rule for all

PROMINENCE_DB = 6.0   # a candidate peak stands this far over its neighbouring minima ...
FLOOR_DB = 10.0       # ... and this far over the noise floor (running 10th percentile of the curve in dB)
FLOOR_PERCENTILE = 10
FLOOR_WINDOW_REL = 0.1   # the running percentile spans this fraction of the band's lines
REJECT_SHARE = 0.1    # a candidate whose stable share is below this is rejected (no mode, not uncertain)


def peak_candidates(freq_hz: np.ndarray, curve: np.ndarray, *, lower: float, upper: float,
                    prominence_db: float = PROMINENCE_DB, floor_db: float = FLOOR_DB) -> list[float]:
    """The candidate-mode rule on a magnitude curve (mean |H| of FRFs, or the first singular value of
    output spectra): every local maximum in ``lower..upper`` that stands ``prominence_db`` over its
    neighbouring minima (scipy ``find_peaks`` prominence, in dB) and ``floor_db`` over the noise floor,
    the running 10th percentile of the curve in dB over ``FLOOR_WINDOW_REL`` of the band's lines."""
    from scipy.ndimage import percentile_filter
    from scipy.signal import find_peaks

    freq_hz = np.asarray(freq_hz, float)
    band = (freq_hz >= lower) & (freq_hz <= upper)
    f, db = freq_hz[band], 20 * np.log10(np.maximum(np.asarray(curve, float)[band], 1e-300))
    floor = percentile_filter(db, FLOOR_PERCENTILE, size=max(5, int(FLOOR_WINDOW_REL * db.size) | 1),
                              mode="nearest")
    peaks, _ = find_peaks(db, prominence=prominence_db)
    return [float(f[k]) for k in peaks if db[k] >= floor[k] + floor_db]


def mean_abs(frf: np.ndarray) -> np.ndarray:
    """Mean |H| over the FRFs of ``frf`` [..., n_freq]."""
    h = np.asarray(frf)
    return np.mean(np.abs(h.reshape(-1, h.shape[-1])), axis=0)


def output_sv1(y: np.ndarray, fs_hz: float, nperseg: int) -> tuple[np.ndarray, np.ndarray]:
    """First singular value of the output cross-spectral matrix of y [n_samples, n_channels] (Welch,
    Hann, half overlap) — the curve frequency-domain decomposition reads modes from."""
    from scipy.signal import csd

    y = np.asarray(y, float)
    n = y.shape[1]
    G = np.array([[csd(y[:, i], y[:, j], fs=fs_hz, nperseg=nperseg)[1] for j in range(n)] for i in range(n)])
    f = np.fft.rfftfreq(nperseg, 1 / fs_hz)
    return f, np.linalg.svd(G.transpose(2, 0, 1), compute_uv=False)[:, 0]


def merge_candidates(primary: Sequence[float], secondary: Sequence[float], *, min_sep_hz: float,
                     min_sep_rel: float = 0.002, exclude: Sequence[tuple[float, str]] = (),
                     exclude_hz: float = 0.0) -> tuple[list[float], list[dict]]:
    """Sorted candidates: ``primary`` (pole clusters: the finer estimate) then each of ``secondary``
    (peaks) not closer than max(``min_sep_hz``, ``min_sep_rel`` of the frequency) to one already kept;
    those within max(``exclude_hz``, 0.05 %, the exclusion's own half-width if it names one) of an
    excluded frequency (mains and its harmonics, rotor harmonics: (frequency, reason[, half-width])
    tuples) taken out; returns the candidates and the exclusions applied."""
    out: list[float] = []
    for fr in [*primary, *secondary]:   # a loop over candidates
        if not any(abs(fr - x) < max(min_sep_hz, min_sep_rel * fr) for x in out):
            out.append(float(fr))
    keep, gone = [], []
    for fr in sorted(out):
        hit = [(x, why) for x, why, *w in exclude if abs(fr - x) <= max(exclude_hz, 5e-4 * x, *w)]
        if hit:
            gone.append({"candidate_hz": round(fr, 4), "excluded_as": hit[0][1],
                         "at_hz": round(hit[0][0], 4)})
        else:
            keep.append(fr)
    return keep, gone


def mains_harmonics(mains_hz: float, upper: float) -> list[tuple[float, str]]:
    """Mains frequency and its harmonics up to ``upper``, as exclusions."""
    return [(k * mains_hz, f"mains {mains_hz:g} Hz x {k}") for k in range(1, int(upper // mains_hz) + 1)]


def classify(modes: list[dict], min_share: float = 0.5, max_damping: float = 0.2,
             reject_share: float = REJECT_SHARE) -> tuple[list[dict], list[float], list[float]]:
    """Confirmed modes (:func:`split_confident`'s thresholds; for output-only references, whose modes
    carry ``picks_agree``, the runs' agreement instead of the share), uncertain candidates (stable share
    from ``reject_share`` up, not confirmed) and rejected ones (stable share below ``reject_share``: no
    stable pole there, not a mode)."""
    if any("picks_agree" in m for m in modes):
        sure = [m for m in modes if m["picks_agree"] and m["damping_ratio"] < max_damping]
        rest = sorted({m["freq_hz"] for m in modes if m not in sure})
    else:
        sure, rest = split_confident(modes, min_share, max_damping)
    by_f = {m["freq_hz"]: m for m in modes}
    unsure = [f for f in rest if by_f[f]["stable_share"] >= reject_share]
    rejected = [f for f in rest if by_f[f]["stable_share"] < reject_share]
    return sure, unsure, rejected


def rule_candidates(freq_hz: np.ndarray, frf: np.ndarray, *, lower: float, upper: float,
                    frf_form: str = "accelerance", cluster_order: int = 60,
                    exclude: Sequence[tuple[float, str]] = ()) -> tuple[list[float], dict]:
    """The candidate rule for FRFs: the peaks of the mean |H| (:func:`peak_candidates`) and the
    clusters of sdypy-EMA's stable poles (:func:`stable_clusters`, order ``cluster_order``: close pairs
    that share one peak), merged within max(2 lines, 0.2 %), exclusions taken out.  Returns the
    candidates and the JSON record of the rule; ``well_determined_hz`` in it: the candidates that are a
    peak or a persistent cluster (in half of all the orders) — a cluster of the upper orders only (the
    signature of poles that model noise, though it may be a weak mode) is at most uncertain."""
    freq_hz = np.asarray(freq_hz, float)
    h = np.atleast_2d(np.asarray(frf).reshape(-1, np.shape(frf)[-1]))
    peaks = peak_candidates(freq_hz, mean_abs(h), lower=lower, upper=upper)
    persistent, late = stable_clusters(freq_hz, h, lower=lower, upper=upper, order=cluster_order,
                                       frf_form=frf_form)
    late = [x for x in late if not any(abs(x / y - 1) < 0.003 for y in persistent)]
    df = float(freq_hz[1] - freq_hz[0])
    cands, gone = merge_candidates(persistent + late, peaks, min_sep_hz=2 * df, exclude=exclude,
                                   exclude_hz=df)
    strong = [x for x in cands if any(abs(x - y) <= max(2 * df, 0.002 * x) for y in [*peaks, *persistent])]
    rule = {"rule": f"peaks of the mean |H| over {lower:g}-{upper:g} Hz standing {PROMINENCE_DB:g} dB over "
                    f"their neighbouring minima and {FLOOR_DB:g} dB over the noise floor (running "
                    f"{FLOOR_PERCENTILE}th percentile over {FLOOR_WINDOW_REL:g} of the band), and clusters "
                    f"(0.3 %) of sdypy-EMA's stable poles in at least half of the upper half of the model "
                    f"orders up to {cluster_order}, merged within max(2 lines, 0.2 %); each confirmed "
                    f"(stable share >= 0.5, damping < 0.2), uncertain (share >= {REJECT_SHARE:g}) or "
                    "rejected by sdypy-EMA's stable share",
            "peaks_hz": [round(x, 4) for x in peaks],
            "pole_clusters_hz": [round(x, 4) for x in persistent],
            "late_pole_clusters_hz": [round(x, 4) for x in late],
            "well_determined_hz": [round(x, 4) for x in strong], "excluded": gone}
    return cands, rule


def rule_reference(freq_hz: np.ndarray, frf: np.ndarray, *, lower: float, upper: float,
                   orders: Sequence[int], frf_form: str = "accelerance",
                   exclude: Sequence[tuple[float, str]] = ()) -> tuple[list[dict], list[float], dict]:
    """Reference of FRFs [..., n_freq] by the one rule: candidates from :func:`rule_candidates`, each
    estimated by :func:`ema_reference` and sorted by :func:`classify`.  Returns the confirmed modes, the
    uncertain frequencies and the JSON record of the rule (with the rejected candidates)."""
    h = np.atleast_2d(np.asarray(frf).reshape(-1, np.shape(frf)[-1]))
    cands, rule = rule_candidates(freq_hz, h, lower=lower, upper=upper, frf_form=frf_form,
                                  cluster_order=max(orders), exclude=exclude)
    modes = ema_reference(freq_hz, h, cands, lower=lower, upper=upper, orders=orders, frf_form=frf_form)
    sure, unsure = classify_candidates(modes, cands, rule)
    return sure, unsure, rule


def classify_candidates(modes: list[dict], cands: Sequence[float],
                        rule: dict) -> tuple[list[dict], list[float]]:
    """Sort the modes estimated from ``cands`` (one per candidate) by :func:`classify` and record the
    candidates, the rejected ones and the stable shares in ``rule`` (changed in place); where the rule
    names ``well_determined_hz`` (:func:`rule_candidates`), each mode is first marked well determined
    when its candidate is one.  Returns the confirmed modes and the uncertain frequencies."""
    if "well_determined_hz" in rule:
        strong = set(rule["well_determined_hz"])
        for m, c in zip(modes, cands, strict=True):   # a late cluster alone confirms nothing
            m["well_determined"] = round(c, 4) in strong
    sure, unsure, rejected = classify(modes)
    rule["candidates_hz"] = [round(x, 4) for x in cands]
    rule["rejected_hz"] = [round(x, 4) for x in rejected]
    rule["stable_share"] = {f"{m['freq_hz']:.4f}": m["stable_share"] for m in modes}
    return sure, unsure


def order_clusters(freq_hz: np.ndarray, order_idx: np.ndarray, n_orders: int, *, min_share: float = 0.5,
                   width_rel: float = 0.005) -> list[float]:
    """Frequencies where poles (``freq_hz``, each with the index of its model order) cluster within
    ``width_rel`` in at least ``min_share`` of ``n_orders`` model orders: the median of each cluster."""
    k = np.argsort(freq_hz)
    fs, od = np.asarray(freq_hz, float)[k], np.asarray(order_idx)[k]
    out, i = [], 0
    while i < fs.size:   # a loop over clusters
        j = np.searchsorted(fs, fs[i] * (1 + width_rel), side="right")
        if np.unique(od[i:j]).size >= min_share * n_orders:
            out.append(float(np.median(fs[i:j])))
            i = j
        else:
            i += 1
    return out


def oma_rule_candidates(y: np.ndarray, fs_hz: float, *, lower: float, upper: float, nperseg: int,
                        poles: tuple[np.ndarray, np.ndarray, int], pole_source: str,
                        exclude: Sequence[tuple[float, str]] = ()) -> tuple[list[float], dict]:
    """The candidate rule for output-only records y [n_samples, n_channels]: the peaks of the first
    singular value of the output spectra (:func:`output_sv1`, :func:`peak_candidates`) and the clusters
    of the reference estimator's poles (``poles``: frequencies, order indices, number of orders;
    :func:`order_clusters`), merged within max(2 lines, 0.2 %), exclusions taken out."""
    f, sv = output_sv1(y, fs_hz, nperseg)
    peaks = peak_candidates(f, sv, lower=lower, upper=upper)
    pf, po, n = poles
    inband = (pf >= lower) & (pf <= upper)
    clusters = order_clusters(pf[inband], po[inband], n)
    df = float(f[1] - f[0])
    cands, gone = merge_candidates(clusters, peaks, min_sep_hz=2 * df, exclude=exclude, exclude_hz=df)
    rule = {"rule": f"peaks of the first singular value of the output spectra (Welch, {nperseg} samples, "
                    f"Hann) over {lower:g}-{upper:g} Hz standing {PROMINENCE_DB:g} dB over their "
                    f"neighbouring minima and {FLOOR_DB:g} dB over the noise floor (running "
                    f"{FLOOR_PERCENTILE}th percentile over {FLOOR_WINDOW_REL:g} of the band), and clusters "
                    f"(0.5 %) of {pole_source} present in at least half the model orders, merged within "
                    "max(2 lines, 0.2 %); each confirmed (every run picks it, the runs agree within 0.5 %), "
                    f"uncertain (stable share >= {REJECT_SHARE:g}) or rejected",
            "peaks_hz": [round(x, 4) for x in peaks], "pole_clusters_hz": [round(x, 4) for x in clusters],
            "excluded": gone}
    return cands, rule


def pyoma2_stable_poles(y: np.ndarray, fs_hz: float, *, br: int, ordmax: int) -> tuple[np.ndarray, np.ndarray,
                                                                                        int]:
    """pyOMA2 SSI-cov's stable poles (label 1, damping 0-20 %) of y [n_samples, n_channels]: their
    frequencies, order indices and the number of orders."""
    with _quiet_pyoma2():
        _, alg = _ssicov(y, fs_hz, br=br, ordmax=ordmax)
    F, X, L = (np.asarray(a, float) for a in (alg.result.Fn_poles, alg.result.Xi_poles, alg.result.Lab))
    ok = (L == 1) & (X > 0) & (X < 0.2) & np.isfinite(F)
    return F[ok], np.nonzero(ok)[1], F.shape[1]
