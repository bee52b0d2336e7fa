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
from dataclasses import dataclass, replace

import numpy as np
import scipy.fft
import scipy.linalg
import scipy.signal

from flexmodal.checked_io.blas import one_blas_thread
from flexmodal.contract.mac import to_real, unit_max
from flexmodal.modal.errors import ModalError
from flexmodal.modal.identify import Modes
from flexmodal.modal.indicators import mpc, mpd
from flexmodal.modal.lscf import Stabilisation, _flags, chain_medians, pole_clusters
from flexmodal.modal.oma_uncertainty import MAX_DECAY_FRACTION, N_BOOTSTRAP, bootstrap_weights
from flexmodal.modal.stability import SSI_MPC_MIN as MPC_MIN
from flexmodal.modal.stability import SSI_MPD_MAX_DEG as MPD_MAX_DEG
from flexmodal.modal.stability import SSI_STABLE_DAMPING_REL as DZ
from flexmodal.modal.stability import SSI_ZETA_MAX as ZETA_MAX
from flexmodal.modal.stability import STABLE_FREQ_REL, STABLE_MAC_MIN

# A structural mode's SSI pole is stable from a low order on (the demo arm's modes: 90-98 % of orders
# 2..100, an 11-storey frame's 11 modes on 5 channels: >= 60 % of orders 2..60); noise fits appear at
# high orders with long Hankel matrices (the demo arm with 100 block rows: 40 % and, once, 66 %).
MIN_FRACTION = 0.5
# Longer Hankel matrices fit the covariance estimates' errors: on 60 s of the demo arm, 200 block rows
# gave stable noise poles beside the strong modes, 100 did not
MAX_BLOCK_ROWS = 100
# A selected mode whose share of the output covariances is below this fraction of the strongest mode's
# is a noise fit (the demo arm: 5e-4 for a noise pole at 403 Hz, >= 1.3e-2 for its modes); a real mode
# can be this weak where the sensors stand near its nodes: pyOMA's steel frame, 13.87 Hz (in pyOMA's
# own SSI table) at 1.5e-3 (lasers on floor 2) and 1.3e-3 (floor 1), under the former limit 2e-3
MIN_CONTRIBUTION = 1e-3


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


def covariances(y: np.ndarray, references: Sequence[int], max_lag: int) -> np.ndarray:
    """Unbiased output covariances R [max_lag + 1, n_channels, n_refs], ``R_i = 1/n_i sum_k
    y_(k+i) y_ref,k^T`` of the mean-removed record ``y`` [N, n_channels], by one zero-padded real FFT
    per channel (Bendat & Piersol 2010, §11.4.2).  Rows holding NaN are gaps (lost samples): they are
    left out of the sums, and ``n_i`` counts the pairs of valid rows ``i`` apart (one more FFT)."""
    y = np.asarray(y, float)
    valid = ~np.isnan(y).any(axis=1)
    y = np.where(valid[:, None], y - y[valid].mean(axis=0), 0.0)
    n = y.shape[0]
    nfft = scipy.fft.next_fast_len(n + max_lag + 1, real=True)
    Y = scipy.fft.rfft(y, nfft, axis=0)                                       # [f, ch]
    cross = Y[:, :, None] * Y[:, list(references)].conj()[:, None, :]          # [f, ch, ref]
    r = scipy.fft.irfft(cross, nfft, axis=0)[: max_lag + 1]
    if valid.all():
        pairs = n - np.arange(max_lag + 1.0)
    else:
        m = scipy.fft.rfft(valid.astype(float), nfft)
        pairs = np.rint(scipy.fft.irfft(m * m.conj(), nfft)[: max_lag + 1])
        if pairs.min() < 1:
            raise ModalError(f"SSI: no pair of valid samples {int(np.argmin(pairs))} apart (gaps everywhere)")
    return r / pairs[:, None, None]


def _decimation(sample_rate_hz: float, fmax: float | None) -> int:
    """Integer decimation factor that keeps the new sample rate at least 4 x ``fmax``: modes up to
    3 ``fmax`` alias above ``fmax`` (and their poles are dropped), modes beyond lie in the stop band
    of the anti-aliasing filter (SSI finds even weak aliased modes, so the margin is wide)."""
    if fmax is None:
        return 1
    return max(1, int(sample_rate_hz // (4 * fmax)))


def default_block_rows(max_order: int, n_refs: int, sample_rate_hz: float, fmin: float | None) -> int:
    """Block rows s: enough for the model order (``s n_refs > max_order``), at least 10, and lags up to
    ``s / f_s`` of at least half a period of ``fmin`` (capped at ``MAX_BLOCK_ROWS``)."""
    s = max(10, max_order // n_refs + 1)
    if fmin:
        s = max(s, min(MAX_BLOCK_ROWS, int(np.ceil(sample_rate_hz / (2 * fmin)))))
    return s


def ssi_cov(y: np.ndarray, sample_rate_hz: float, *, references: Sequence[int] | None = None,
            fmin: float | None = None, fmax: float | None = None, max_order: int = 100,
            min_order: int = 2, order_step: int = 2, block_rows: int | None = None,
            df: float = STABLE_FREQ_REL, dz: float = DZ, mac_min: float = STABLE_MAC_MIN,
            mpc_min: float = MPC_MIN, mpd_max_deg: float = MPD_MAX_DEG, min_fraction: float = MIN_FRACTION,
            lowest_hz: float | None = None, uncertainty_blocks: int = 0) -> SsiResult:
    """SSI-cov of an output-only record ``y`` [n_samples, n_channels] sampled at ``sample_rate_hz``.

    ``references``: channel indices whose covariances with every channel fill the Hankel matrix
    (default all).  ``fmin``/``fmax`` [Hz] bound the poles kept; with ``fmax`` the record is first
    decimated (polyphase FIR) to at least 4 ``fmax``.  Model orders ``min_order .. max_order`` in
    steps of ``order_step``; ``block_rows`` s (default :func:`default_block_rows` for ``lowest_hz``,
    the lowest frequency of interest, default ``fmin``).  Poles are
    validated by damping (0 < zeta < 20 %), MPC >= ``mpc_min`` and MPD <= ``mpd_max_deg`` before
    the stability check; the modes are chosen by
    :func:`_select` (chains of poles stable at ``min_fraction`` of the orders).
    ``uncertainty_blocks``: the record is cut into that many blocks whose covariances' scatter gives
    each mode's ``freq_std_hz``/``damping_std`` (modal/oma_uncertainty.py; 0: not estimated; ``identify``
    uses ``N_BLOCKS``).
    Returns the stabilisation diagram and the modes (unscaled shapes, unit largest entry).
    """
    y = np.asarray(y, float)
    if y.ndim != 2 or y.shape[1] < 1:
        raise ModalError(f"SSI: record of shape {y.shape} is not [n_samples, n_channels]")
    gaps = np.isnan(y).any(axis=1)
    if np.isinf(y).any() or gaps.mean() > 0.5:
        raise ModalError("SSI: the record holds infinite values or more than half of it is gaps (NaN rows)")
    n_ch = y.shape[1]
    refs = tuple(range(n_ch)) if references is None else tuple(int(r) for r in references)
    if not refs or any(r < 0 or r >= n_ch for r in refs) or len(set(refs)) != len(refs):
        raise ModalError(f"SSI: reference channels {list(refs)} must be distinct indices below {n_ch}")
    if max_order < 2 or min_order < 1 or order_step < 1 or min_order > max_order:
        raise ModalError(f"SSI: model orders {min_order}..{max_order} (step {order_step}) are not valid")
    q = _decimation(sample_rate_hz, fmax)
    if q > 1:   # Kaiser FIR, delay compensated; an output sample whose filter reached a gap is a gap
        near_gap = np.abs(scipy.signal.resample_poly(gaps.astype(float), 1, q)) > 1e-6
        y = scipy.signal.resample_poly(np.where(gaps[:, None], 0.0, y), 1, q, axis=0)
        y[near_gap] = np.nan
    fs = sample_rate_hz / q
    s = block_rows or max(default_block_rows(max_order, len(refs), fs, lowest_hz or fmin),
                          -(-max_order // n_ch) + 1)   # the shifted observability matrix holds the order
    if s * len(refs) < max_order or (s - 1) * n_ch < max_order:
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
    with one_blas_thread():
        U, sv, Vt = scipy.linalg.svd(H, full_matrices=False, check_finite=False)
        real = _Realisations(U, sv, Vt, n_ch, len(refs), max_order)
        found = real.poles(orders, fs, band, mpc_min, mpd_max_deg)
        stab = _flags(orders, found, df, dz, mac_min)   # the input-output path's stability flags
        all_shapes = np.hstack([np.zeros((n_ch, 0), complex), *[sh for _, sh in found]])
        modes, uppers = _select(stab, all_shapes, min_fraction, real, fs)
        if uncertainty_blocks:      # freq_std_hz / damping_std from the blocks' scatter (issue 26)
            modes = _with_std(modes, y, refs, s, uncertainty_blocks, max_order,
                              [(stab.order[u], stab.pole[u]) for u in uppers], fs)
    return SsiResult(stab, all_shapes, mpc(all_shapes), mpd(all_shapes), modes, sv, fs, refs)


def _with_std(modes: Modes, y: np.ndarray, refs: tuple[int, ...], s: int, n_blocks: int, max_order: int,
              members: list[tuple[np.ndarray, np.ndarray]], fs: float) -> Modes:
    """``modes`` with the standard deviations of their frequencies and damping ratios: the bootstrap
    over ``n_blocks`` contiguous blocks of ``y`` (modal/oma_uncertainty.py; fewer blocks when one would
    be shorter than 40 s samples), each of ``N_BOOTSTRAP`` replicates re-identifying, from the Hankel
    matrix of the re-weighted blocks, the pole nearest each of the mode's stable poles (``members``:
    their orders and poles) at the same order, and taking the same medians over them as the estimate
    (:func:`_medians`); their standard deviation times ``sqrt(n_b / (n_b - 1))`` (the bootstrap
    variance of a mean of n_b blocks is the plug-in one, (n_b - 1) / n_b of the unbiased).  NaN below
    4 blocks, and for a mode whose decay time ``1 / (zeta omega_n)`` exceeds ``MAX_DECAY_FRACTION`` of
    a block (the blocks are then not independent samples of it)."""
    n_b = min(n_blocks, y.shape[0] // (40 * s))
    nan = np.full(modes.freq_hz.size, np.nan)
    if n_b < 4:
        return replace(modes, freq_std_hz=nan, damping_std=nan.copy())
    n_ch = y.shape[1]
    lag = np.arange(s)[:, None] + np.arange(s)[None, :] + 1
    length = y.shape[0] // n_b
    try:
        H = np.stack([covariances(y[j * length:(j + 1) * length], refs, 2 * s)[lag].transpose(0, 2, 1, 3)
                      .reshape(s * n_ch, s * len(refs)) for j in range(n_b)])     # a loop over blocks
    except ModalError:                                   # a block that is all gaps
        return replace(modes, freq_std_hz=nan, damping_std=nan.copy())
    est = np.array([_medians(np.tensordot(w, H, 1) / n_b, n_ch, len(refs), max_order, members, fs)
                    for w in bootstrap_weights(n_b, N_BOOTSTRAP)])               # a loop over replicates
    # the bootstrap's plug-in variance of a mean of n_b blocks is (n_b - 1) / n_b of the unbiased one
    std = np.std(est, axis=0, ddof=1) * np.sqrt(n_b / (n_b - 1.0))
    tau_s = 1.0 / (modes.damping_ratio * 2 * np.pi * modes.freq_hz)
    std[tau_s > MAX_DECAY_FRACTION * length / fs] = np.nan
    return replace(modes, freq_std_hz=std[:, 0], damping_std=std[:, 1])


def _medians(H: np.ndarray, n_ch: int, n_refs: int, max_order: int,
             members: list[tuple[np.ndarray, np.ndarray]], fs: float) -> np.ndarray:
    """[n_modes, 2] natural frequency [Hz] and damping ratio of each mode from the block Hankel matrix
    ``H``: at each order of the mode's stable poles (``members``: orders, poles [rad/s]) the pole of
    ``H``'s realisation nearest the member, and over them the medians of the estimate
    (:func:`flexmodal.modal.lscf.chain_medians`); for the record's own ``H`` that is the estimate."""
    U, sv, Vt = scipy.linalg.svd(H, full_matrices=False, check_finite=False)
    real = _Realisations(U, sv, Vt, n_ch, n_refs, max_order)
    poles: dict[int, np.ndarray] = {}
    out = np.empty((len(members), 2))
    for m, (orders, member_poles) in enumerate(members):     # a loop over modes
        lam = np.empty(orders.size, complex)
        for k, n in enumerate(orders.tolist()):              # and over their orders (each order's poles once)
            if n not in poles:
                mu = scipy.linalg.eigvals(real.X(n), check_finite=False).astype(complex)
                poles[n] = np.log(mu) * fs
            lam[k] = poles[n][np.argmin(np.abs(poles[n] - member_poles[k]))]
        wn = np.abs(lam)
        out[m] = chain_medians(orders, wn / (2 * np.pi), -lam.real / wn)
    return out


class _Realisations:
    """The state-space realisations of every model order from the SVD ``U S V^T`` of the Hankel matrix,
    in the coordinates where the highest order's least-squares solution is nested (module docstring):
    ``X_n = R_n^-1 (Q^T U^down)_n`` (similar to A_n), output matrix ``U^top_n`` and next-state/output
    covariance ``G_n = S_n V_n^T`` (its first block column over the references)."""

    def __init__(self, U: np.ndarray, sv: np.ndarray, Vt: np.ndarray, n_ch: int, n_refs: int, nmax: int):
        Qm, self.R = scipy.linalg.qr(U[:-n_ch, :nmax], mode="economic", check_finite=False)
        self.M = Qm.T @ U[n_ch:, :nmax]
        self.top = U[:n_ch, :nmax]
        self.G = sv[:nmax, None] * Vt[:nmax, :n_refs]

    def X(self, n: int) -> np.ndarray:
        return scipy.linalg.solve_triangular(self.R[:n, :n], self.M[:n, :n], check_finite=False)

    def poles(self, orders: list[int], fs: float, band: tuple[float, float], mpc_min: float,
              mpd_max_deg: float) -> list[tuple[np.ndarray, np.ndarray]]:
        """Validated poles (rad/s, ascending frequency) and shapes [n_ch, n_poles] of every order."""
        found = []
        for n in orders:   # a loop over model orders: one n x n triangular solve and eigenproblem each
            # LAPACK dgeev (right vectors only): half the time of numpy.linalg.eig, which also builds
            # complex vectors for every eigenvalue; a pair wr +- i wi has vectors vr[:, j] +- i vr[:, j+1]
            wr, wi, _, vr, _ = scipy.linalg.lapack.dgeev(self.X(n), compute_vl=0, overwrite_a=1)
            upper = np.flatnonzero(wi > 0)
            with np.errstate(divide="ignore", invalid="ignore"):
                lam = np.log(wr[upper] + 1j * wi[upper]) * fs
            f = np.abs(lam) / (2 * np.pi)
            zeta = -lam.real / np.abs(lam)
            keep = np.isfinite(lam) & (zeta > 0) & (zeta < ZETA_MAX) & (f >= band[0]) & (f <= band[1])
            j = upper[keep]
            phi = self.top[:, :n] @ (vr[:, j] + 1j * vr[:, j + 1])
            good = (mpc(phi) >= mpc_min) & (mpd(phi) <= mpd_max_deg)
            idx = np.argsort(f[keep][good])
            found.append((lam[keep][good][idx], phi[:, good][:, idx]))
        return found

    def contribution(self, n: int, pole: complex, fs: float) -> float:
        """RMS of the mode's share of the output covariances over all lags, ``|C psi| |g| /
        sqrt(1 - |mu|^2)`` with ``g`` the mode's row of ``psi^-1 G`` (left eigenvector), at order n."""
        mu, vl, vr = scipy.linalg.eig(self.X(n), left=True, right=True, check_finite=False)
        j = int(np.argmin(np.abs(mu - np.exp(pole / fs))))
        g = (vl[:, j].conj() @ self.G[:n]) / (vl[:, j].conj() @ vr[:, j])
        return float(np.linalg.norm(self.top[:, :n] @ vr[:, j]) * np.linalg.norm(g)
                     / np.sqrt(max(1.0 - abs(mu[j]) ** 2, 1e-300)))


def _select(stab: Stabilisation, shapes: np.ndarray, min_fraction: float, real: _Realisations,
            fs: float) -> tuple[Modes, list[np.ndarray]]:
    """The modes of the stabilisation diagram, and the stabilisation indices of each mode's stable
    poles (whose medians are the mode's frequency and damping): the input-output path's chains of poles
    (:func:`~flexmodal.modal.lscf.pole_clusters`) stable at ``min_fraction`` of all the diagram's
    orders.  (pLSCF's selection counts the orders from a chain's first, then rejects noise modes by
    the FRF synthesis; output-only data have no FRFs to synthesise, and SSI's noise poles appear at
    high orders, so here the count is over all orders.)  Each mode's shape is that of the chain's
    stable pole nearest its frequency among the upper half of its orders; a mode contributing less
    than ``MIN_CONTRIBUTION`` of the strongest mode's share of the output covariances is dropped."""
    clusters = pole_clusters(stab)
    clusters = clusters.subset(clusters.n_stable >= min_fraction * np.unique(stab.order).size)
    if clusters.freq_hz.size == 0:
        raise ModalError("SSI: no stable mode in the band (try a higher --max-order, or check the record)")
    picks, uppers = [], []
    for f0, members in zip(clusters.freq_hz, clusters.members, strict=True):   # a loop over modes
        s = members[stab.stable[members]]
        upper = s[stab.order[s] >= np.median(stab.order[s])]
        picks.append(upper[np.argmin(np.abs(stab.freq_hz[upper] - f0))])
        uppers.append(s)
    share = np.array([real.contribution(int(stab.order[k]), stab.pole[k], fs) for k in picks])
    weak = share < MIN_CONTRIBUTION * share.max()
    clusters, picks = clusters.subset(~weak), np.asarray(picks)[~weak]
    uppers = [u for u, w in zip(uppers, weak, strict=True) if not w]
    complex_shapes = unit_max(shapes[:, picks])
    m, d = mpc(complex_shapes), mpd(complex_shapes)
    warnings = tuple(f"mode at {f:.4g} Hz: MPC {a:.2f}, MPD {b:.0f} deg (a complex shape)"
                     for f, a, b in zip(clusters.freq_hz, m, d, strict=True) if a < 0.9 or b > 15)
    selected = np.zeros(stab.freq_hz.size, bool)
    selected[np.concatenate(clusters.members)] = True
    return Modes(clusters.freq_hz, clusters.damping_ratio, to_real(complex_shapes), complex_shapes, "ssi",
                 False, warnings, mpc=m, mpd=d, stabilisation=stab, selected=selected), uppers
