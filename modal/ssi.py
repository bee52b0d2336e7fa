"""Output-only modal identification by covariance-driven stochastic subspace identification (SSI-cov,
Peeters & De Roeck 1999, Mech. Syst. Signal Process. 13(6); Reynders 2012, Arch. Comput. Methods Eng. 19)
with a stabilisation diagram, pole validation by modal phase collinearity (MPC, Pappa et al. 1993) and
mean phase deviation (MPD, Reynders et al. 2012), and the automatic selection of the input-output path
(:func:`flexmodal.modal.lscf.select_stable`).

Method.  Output covariances ``R_i = E[y_(k+i) y_ref,k^T]`` (unbiased, by FFT) fill the block Hankel
matrix ``H[a, b] = R_(a+b+1)`` (a, b = 0 .. s-1; lag 0 is left out, so white sensor noise does not bias
it), ``H = O G`` with the observability matrix ``O = [C; CA; ...]``.  One SVD ``H = U S V^T`` serves
every model order n: ``O_n = U_n S_n^(1/2)``, and ``A_n`` solves ``O_n^up A_n = O_n^down`` (the block
rows without the last / first).  The orders are nested, so one QR factorisation ``U^up = Q R`` of the
highest order gives every order's least-squares solution as ``R_n^-1 (Q^T U^down)_n`` (n x n, one
triangular solve), which is similar to ``A_n`` (``S^(1/2)`` scaling): the same eigenvalues ``mu``, and
shapes ``C_n psi = U^top_n psi_X``.  Continuous poles ``lambda = ln(mu) f_s``.

Mode shapes are unscaled (output-only data carry no force, so no modal mass): each is normalised to
unit largest entry.  A pole is stable against the nearest pole of the previous order within ``df`` in
frequency, ``dz`` in damping and MAC >= ``mac_min``, as in the input-output path.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import scipy.fft
import scipy.linalg
import scipy.signal
from threadpoolctl import threadpool_limits

from flexmodal.modal.errors import ModalError
from flexmodal.modal.identify import Modes
from flexmodal.modal.lscf import Stabilisation, select_stable
from flexmodal.modal.mac import mac_pairs, to_real, unit_max

MPC_MIN = 0.7       # poles below this modal phase collinearity are noise (real modes have MPC ~ 1)
MPD_MAX_DEG = 30.0  # poles whose entries scatter more than this from one phase line are noise
ZETA_MAX = 0.2      # poles damped more than 20 % are not structural modes of an arm


@dataclass(frozen=True)
class SsiResult:
    """Every validated pole of every order (``stabilisation``), their unscaled complex shapes
    [n_channels, n_poles], MPC and MPD (degrees) [n_poles], the selected ``modes``, the singular
    values of the block Hankel matrix, the sample rate the poles were computed at (after decimation)
    and the reference channel indices."""

    stabilisation: Stabilisation
    shapes: np.ndarray
    mpc: np.ndarray
    mpd_deg: np.ndarray
    modes: Modes
    singular_values: np.ndarray
    sample_rate_hz: float
    references: tuple[int, ...]


def mpc(phi: np.ndarray) -> np.ndarray:
    """Modal phase collinearity [n_modes] of complex shapes [n_points, n_modes]: ``|phi^T phi|^2 /
    (phi^H phi)^2``, 1 for a shape whose entries lie on one line through the origin of the complex
    plane (a normal mode), 0 for a circular scatter (Pappa, Elliott & Schenk 1993, J. Guid. Control
    Dyn. 16(5), eigenvalue form of the 2 x 2 real/imaginary covariance)."""
    p = np.atleast_2d(np.asarray(phi, complex))
    num = np.abs(np.einsum("ir,ir->r", p, p)) ** 2
    den = np.einsum("ir,ir->r", p.conj(), p).real ** 2
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.nan_to_num(num / den)


def mpd(phi: np.ndarray) -> np.ndarray:
    """Mean phase deviation [n_modes], degrees: the magnitude-weighted mean angle between each entry
    and the best-fit line through the origin (direction ``0.5 arg(phi^T phi)``, the principal axis of
    the real/imaginary scatter), 0 for a normal mode (Reynders, Houbrechts & De Roeck 2012, MSSP 29)."""
    p = np.atleast_2d(np.asarray(phi, complex))
    theta = 0.5 * np.angle(np.einsum("ir,ir->r", p, p))
    mag = np.abs(p)
    with np.errstate(divide="ignore", invalid="ignore"):
        cos = np.clip(np.abs((p * np.exp(-1j * theta)).real) / mag, 0.0, 1.0)
        dev = np.degrees(np.arccos(np.where(mag > 0, cos, 1.0)))
        return np.nan_to_num(np.sum(mag * dev, axis=0) / np.sum(mag, axis=0))


def covariances(y: np.ndarray, references: Sequence[int], max_lag: int) -> np.ndarray:
    """Unbiased output covariances R [max_lag + 1, n_channels, n_refs], ``R_i = 1/(N-i) sum_k
    y_(k+i) y_ref,k^T`` of the mean-removed record ``y`` [N, n_channels], by one zero-padded real FFT
    per channel (Bendat & Piersol 2010, §11.4.2)."""
    y = np.asarray(y, float)
    y = y - y.mean(axis=0)
    n = y.shape[0]
    nfft = scipy.fft.next_fast_len(n + max_lag + 1, real=True)
    Y = scipy.fft.rfft(y, nfft, axis=0)                                       # [f, ch]
    cross = Y[:, :, None] * Y[:, list(references)].conj()[:, None, :]          # [f, ch, ref]
    r = scipy.fft.irfft(cross, nfft, axis=0)[: max_lag + 1]
    return r / (n - np.arange(max_lag + 1))[:, None, None]


def stability_flags(orders: Sequence[int], poles: Sequence[np.ndarray], shapes: Sequence[np.ndarray], *,
                    df: float = 0.01, dz: float = 0.05, mac_min: float = 0.98) -> Stabilisation:
    """Stabilisation diagram of per-order poles (rad/s, complex) and shapes [n_points, n_poles]: each
    pole is compared with the pole of the previous order nearest in frequency."""
    fn = [np.abs(p) / (2 * np.pi) for p in poles]
    flags = [np.zeros((3, p.size), bool) for p in poles]
    for k in range(1, len(poles)):   # a loop over model orders
        if fn[k].size == 0 or fn[k - 1].size == 0:
            continue
        near = np.argmin(np.abs(fn[k][:, None] - fn[k - 1][None, :]), axis=1)
        z_now, z_prev = -poles[k].real / np.abs(poles[k]), -poles[k - 1].real / np.abs(poles[k - 1])
        flags[k][0] = np.abs(fn[k] - fn[k - 1][near]) <= df * fn[k]
        flags[k][1] = np.abs(z_now - z_prev[near]) <= dz * z_now
        flags[k][2] = mac_pairs(shapes[k], shapes[k - 1][:, near]) >= mac_min
    pole = np.concatenate(poles) if poles else np.zeros(0, complex)
    f = np.hstack([np.zeros((3, 0), bool), *flags])
    order = np.concatenate([np.full(p.size, o) for p, o in zip(poles, orders, strict=True)])
    return Stabilisation(order, np.abs(pole) / (2 * np.pi), -pole.real / np.abs(pole), pole, f[0], f[1], f[2])


def _decimation(sample_rate_hz: float, fmax: float | None) -> int:
    """Integer decimation factor that keeps 2.5 x ``fmax`` below the new sample rate."""
    if fmax is None:
        return 1
    return max(1, int(sample_rate_hz // (2.5 * fmax)))


def ssi_cov(y: np.ndarray, sample_rate_hz: float, *, references: Sequence[int] | None = None,
            fmin: float | None = None, fmax: float | None = None, max_order: int = 100,
            min_order: int = 2, order_step: int = 2, block_rows: int | None = None, df: float = 0.01,
            dz: float = 0.05, mac_min: float = 0.98, mpc_min: float = MPC_MIN,
            mpd_max_deg: float = MPD_MAX_DEG, min_fraction: float = 0.3) -> SsiResult:
    """SSI-cov of an output-only record ``y`` [n_samples, n_channels] sampled at ``sample_rate_hz``.

    ``references``: channel indices whose covariances with every channel fill the Hankel matrix
    (default all).  ``fmin``/``fmax`` [Hz] bound the poles kept; with ``fmax`` the record is first
    decimated (zero-phase FIR) to at least 2.5 ``fmax``.  Model orders ``min_order .. max_order`` in
    steps of ``order_step``; ``block_rows`` s (default the least with ``s * n_refs > max_order`` and
    ``s >= 10``).  Poles are validated by damping (0 < zeta < 20 %), MPC >= ``mpc_min`` and MPD <=
    ``mpd_max_deg`` before the stability check; the modes are chosen by
    :func:`~flexmodal.modal.lscf.select_stable` (clusters present in ``min_fraction`` of the orders).
    Returns the stabilisation diagram and the modes (unscaled shapes, unit largest entry).
    """
    y = np.asarray(y, float)
    if y.ndim != 2 or y.shape[1] < 1:
        raise ModalError(f"SSI: record of shape {y.shape} is not [n_samples, n_channels]")
    if not np.all(np.isfinite(y)):
        raise ModalError("SSI: the record contains NaN or infinite values")
    n_ch = y.shape[1]
    refs = tuple(range(n_ch)) if references is None else tuple(int(r) for r in references)
    if not refs or any(r < 0 or r >= n_ch for r in refs) or len(set(refs)) != len(refs):
        raise ModalError(f"SSI: reference channels {list(refs)} must be distinct indices below {n_ch}")
    if max_order < 2 or min_order < 1 or order_step < 1 or min_order > max_order:
        raise ModalError(f"SSI: model orders {min_order}..{max_order} (step {order_step}) are not valid")
    q = _decimation(sample_rate_hz, fmax)
    if q > 1:
        y = scipy.signal.decimate(y, q, ftype="fir", axis=0, zero_phase=True)
    fs = sample_rate_hz / q
    s = block_rows or max(10, max_order // len(refs) + 1)
    if s * len(refs) <= max_order or s * n_ch <= max_order:
        raise ModalError(f"SSI: {s} block rows x {len(refs)} references (and {n_ch} channels) cannot hold "
                         f"model order {max_order}; use more block rows or a lower --max-order")
    if y.shape[0] < 20 * 2 * s:
        raise ModalError(f"SSI: {y.shape[0]} samples are too few for {s} block rows (need {40 * s})")
    R = covariances(y, refs, 2 * s)
    lag = np.arange(s)[:, None] + np.arange(s)[None, :] + 1                   # [a, b] -> a + b + 1
    H = R[lag].transpose(0, 2, 1, 3).reshape(s * n_ch, s * len(refs))
    orders = list(range(min_order, max_order + 1, order_step))
    band = (fmin if fmin is not None else 0.0, min(fmax if fmax is not None else np.inf, 0.5 * fs))
    # one BLAS thread: the matrices are at most a few hundred wide (threads only spin on them)
    with threadpool_limits(1, "blas"):
        U, sv, _ = scipy.linalg.svd(H, full_matrices=False, check_finite=False)
        found = _poles(U, n_ch, orders, fs, band, mpc_min, mpd_max_deg)
    poles, shapes = [p for p, _ in found], [s for _, s in found]
    stab = stability_flags(orders, poles, shapes, df=df, dz=dz, mac_min=mac_min)
    all_shapes = np.hstack([np.zeros((n_ch, 0), complex), *shapes])
    modes = _select(stab, all_shapes, min_fraction)
    return SsiResult(stab, all_shapes, mpc(all_shapes), mpd(all_shapes), modes, sv, fs, refs)


def _poles(U: np.ndarray, n_ch: int, orders: list[int], fs: float, band: tuple[float, float],
           mpc_min: float, mpd_max_deg: float) -> list[tuple[np.ndarray, np.ndarray]]:
    """Validated poles (rad/s, ascending frequency) and shapes [n_ch, n_poles] of every order from the
    left singular vectors ``U`` of the Hankel matrix (see module docstring)."""
    nmax = orders[-1]
    Qm, Rm = scipy.linalg.qr(U[:-n_ch, :nmax], mode="economic", check_finite=False)
    M = Qm.T @ U[n_ch:, :nmax]
    top = U[:n_ch, :nmax]
    found = []
    for n in orders:   # a loop over model orders: one n x n triangular solve and eigenproblem each
        X = scipy.linalg.solve_triangular(Rm[:n, :n], M[:n, :n], check_finite=False)
        # LAPACK dgeev (right vectors only): half the time of numpy.linalg.eig, which also builds
        # complex vectors for every eigenvalue; a pair wr +- i wi has vectors vr[:, j] +- i vr[:, j+1]
        wr, wi, _, vr, _ = scipy.linalg.lapack.dgeev(X, compute_vl=0, overwrite_a=1)
        upper = np.flatnonzero(wi > 0)
        with np.errstate(divide="ignore", invalid="ignore"):
            lam = np.log(wr[upper] + 1j * wi[upper]) * fs
        f = np.abs(lam) / (2 * np.pi)
        zeta = -lam.real / np.abs(lam)
        keep = np.isfinite(lam) & (zeta > 0) & (zeta < ZETA_MAX) & (f >= band[0]) & (f <= band[1])
        j = upper[keep]
        phi = top[:, :n] @ (vr[:, j] + 1j * vr[:, j + 1])
        good = (mpc(phi) >= mpc_min) & (mpd(phi) <= mpd_max_deg)
        idx = np.argsort(f[keep][good])
        found.append((lam[keep][good][idx], phi[:, good][:, idx]))
    return found


def _select(stab: Stabilisation, shapes: np.ndarray, min_fraction: float) -> Modes:
    """The modes of the stabilisation diagram: frequency and damping from ``select_stable``; the shape
    of the stable pole nearest to each selected frequency among the upper half of its orders."""
    fn, zeta, _ = select_stable(stab, min_fraction=min_fraction)
    if fn.size == 0:
        raise ModalError("SSI: no stable mode in the band (try a higher --max-order, or check the record)")
    stable = np.flatnonzero(stab.stable)
    picks = []
    for f0 in fn:   # a loop over modes
        near = stable[np.abs(stab.freq_hz[stable] - f0) <= 0.005 * f0]
        upper = near[stab.order[near] >= np.median(stab.order[near])]
        picks.append(upper[np.argmin(np.abs(stab.freq_hz[upper] - f0))])
    complex_shapes = unit_max(shapes[:, picks])
    warnings = tuple(f"mode at {f:.4g} Hz: MPC {m:.2f}, MPD {d:.0f} deg (a complex shape)"
                     for f, m, d in zip(fn, mpc(complex_shapes), mpd(complex_shapes), strict=True)
                     if m < 0.9 or d > 15)
    return Modes(fn, zeta, to_real(complex_shapes), complex_shapes, "ssi", False, warnings)
