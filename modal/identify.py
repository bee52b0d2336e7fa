"""Modal identification from FRFs to natural frequencies, damping ratios and shapes, and on to the
modal table (docs/formats.md).  Methods: ``lscf`` (pLSCF poles over a stabilisation diagram whose order
adapts to the data, automatic selection of stable pole chains, shapes by LSFD with residuals, and
validation: a mode the synthesis does not need or with a phase-scattered shape is dropped; or the
poles nearest frequencies the user names) and ``peak`` (CMIF peak picking, half-power damping, quadrature
shapes).  Damping added by an exponential window is removed from the identified poles."""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pandas as pd
from scipy.ndimage import uniform_filter1d

from flexmodal.checked_io.blas import one_blas_thread
from flexmodal.checked_io.data_range import range_fault
from flexmodal.checked_io.output import atomic_path
from flexmodal.checked_io.plural import counted
from flexmodal.contract.mac import mac, mass_normalised, to_real, unit_max
from flexmodal.contract.table import ModalTable
from flexmodal.modal.damping import half_power
from flexmodal.modal.diagrams import DiagramStore, StoredDiagram, inputs_key
from flexmodal.modal.errors import ModalError
from flexmodal.modal.frf import convert
from flexmodal.modal.indicators import frac, mpc, mpd
from flexmodal.modal.lscf import (
    PoleClusters,
    Stabilisation,
    adaptive_stabilisation,
    default_caps,
    pole_clusters,
    stable_clusters,
)
from flexmodal.modal.lsfd import LsfdResult, lsfd, refine_pole, synthesis_of
from flexmodal.modal.order_note import BASIS_WORDS
from flexmodal.modal.peaks import clear_peaks, cmif, pick_peaks, quadrature_shapes, visible_peaks
from flexmodal.modal.registry import METHODS, output_only
from flexmodal.modal.stability import PICKED
from flexmodal.modal.windows import remove_added_damping

INDICATORS = {"mpc": "mpc", "mpd": "mpd_deg", "synthesis_corr": "synthesis_corr"}
"""Per-mode validation indicators (``Modes`` attribute: modal table column, its unit in its name)."""
TOP_ORDERS = 0.75   # a mode's frequency: median over its upper quarter of stable orders (least noise)
VISIBLE_DB = 3.0   # a peak this prominent in some FRF or CMIF curve is a resonance the data show
BROAD = 3.0   # a pole of this many times a close mode's half-power bandwidth, covering it, is background
MIN_LINES_PER_BANDWIDTH = 8   # below this the Hann-window leakage bias on damping exceeds a few %
SYNTHESIS_HEADER = b"config,output,input,synthesis_corr"   # the first line of MODES.synthesis.csv
ZOOM_LINES = 16      # lines per misfit window (windows overlap by half)
ZOOM_MISFIT = 3.0    # a window misfit this many times the band's median misfit...
ZOOM_ZETA = 0.01     # ...and fitted with one pole starting at this damping ratio at its largest residual
ZOOM_ABOVE_NOISE = 2.0  # ...standing this many times above the FRFs' own noise there
ZOOM_COHERENCE = 0.9  # ...where the FRFs' mean coherence is at least this (when it is known)
SUSPENSION = 0.2     # below this share of the lowest mode a resonance is taken as the suspension's
EDGE_COHERENCE = 0.9  # the default band ends below a top stretch where the FRFs' coherence stays under this
EDGE_SMOOTH = 0.005   # ...averaged over outputs and over about this share of the band's lines (>= 5)
EDGE_SHARE = 0.25     # ...unless that stretch holds more than this share of the band (no band edge then)
BASIS_MISFIT = 1.25  # one reference: the second basis's misfit share may be this many times the first's
BASIS_PEAKS = 2      # ...and it explains this many more clear CMIF peaks, or one more and loses none
@dataclass(frozen=True)
class Modes:
    """Identified modes: ``freq_hz``, ``damping_ratio`` [n_modes]; ``shapes`` [n_out, n_modes] real
    (mass-normalised when a driving point was given, else unit maximum); ``complex_shapes`` the
    modal constants of the reference column before conversion; ``warnings`` met on the way, one line
    per kind (a summary of what is said mode by mode), and ``details`` those per-mode lines.

    Validation (pLSCF): ``mpc`` [-] and ``mpd`` [deg] of the complex shapes, ``synthesis_corr`` [-]
    the FRAC of measured and synthesised FRFs (all of them) within three half-power bandwidths of each
    mode, ``need`` the F statistic of the mode in the synthesis (:mod:`modal.lsfd`),
    ``frf_synthesis_corr`` [n_out, n_in] the FRAC of each FRF over the band, ``synthesis`` [n_out,
    n_in, n_band] the synthesised FRFs on ``band_freq_hz``, ``stabilisation`` the diagram with
    ``selected`` [n_poles] marking the poles of the chosen modes, ``order_note`` which model order
    was used and why, ``band_note`` which band was fitted and why."""

    freq_hz: np.ndarray
    damping_ratio: np.ndarray
    shapes: np.ndarray
    complex_shapes: np.ndarray
    method: str
    mass_normalised: bool
    warnings: tuple[str, ...] = ()
    mpc: np.ndarray | None = None
    mpd: np.ndarray | None = None
    synthesis_corr: np.ndarray | None = None
    need: np.ndarray | None = None
    frf_synthesis_corr: np.ndarray | None = None
    band_freq_hz: np.ndarray | None = None
    synthesis: np.ndarray | None = None
    stabilisation: Stabilisation | None = None
    selected: np.ndarray | None = None
    order_note: str = ""
    details: tuple[str, ...] = ()
    freq_std_hz: np.ndarray | None = None      # 1-sigma [Hz], modal/uncertainty.py (None: not estimated)
    damping_std: np.ndarray | None = None      # 1-sigma [-]
    diagram_key: str = ""   # modal.diagrams.inputs_key of the FRFs and options behind ``stabilisation``
    band_note: str = ""     # which band [Hz] was fitted and why (identify's band_note)
    excitation: str | None = None   # how the FRFs were made (random, impact, sweep; None unknown)


@dataclass(frozen=True)
class Thresholds:
    """Automatic selection limits: a mode is dropped when the measured FRFs do not need it, or when its
    shape is scattered in phase (a computational pole).

    Parameters
    ----------
    need_min : float
        Least F statistic [-] of a mode in the synthesis (:mod:`modal.lsfd`): below it the FRFs fit
        as well without the mode.
    mpc_min : float
        Least modal phase collinearity [-] (0-1) of a mode's shape, applied with two or more outputs.
    """

    need_min: float = 10.0
    mpc_min: float = 0.5


def nyquist_note(fmax_hz: float, top_hz: float) -> str:
    """The warning for an upper band edge above the data's highest frequency line (it is clipped)."""
    return (f"--fmax {fmax_hz:g} Hz is above the highest frequency line, {top_hz:g} Hz (Nyquist); "
            "clipped to it")


def _band(freq_hz: np.ndarray, fmin: float | None, fmax: float | None) -> np.ndarray:
    f = np.asarray(freq_hz, float)
    lo = fmin if fmin is not None else (f[f > 0].min() if np.any(f > 0) else 0.0)
    hi = fmax if fmax is not None else f.max()
    band = (f >= lo) & (f <= hi) & (f > 0)
    if band.sum() < 8:
        raise ModalError(f"identify: only {int(band.sum())} frequency lines between {lo:g} and {hi:g} Hz")
    return band


def coherent_top(freq_hz: np.ndarray, coherence: np.ndarray | None) -> float | None:
    """The upper band edge [Hz] below the FRFs' poorly measured top, or None when they have none.

    The top of a record's band is where its anti-aliasing (or decimation) filter rolls off and where a
    sweep or an impact stops exciting: there the coherence ``coherence`` [n_out, n_freq] (on the lines
    ``freq_hz`` [Hz]), averaged over the outputs and over EDGE_SMOOTH of the lines, falls below
    EDGE_COHERENCE and stays there to the highest line.  The edge is the highest line at which the
    smoothed coherence is still EDGE_COHERENCE or more; None when the top line is well measured, or when
    the poorly measured stretch holds more than EDGE_SHARE of the lines (a noisy record, not a band
    edge).  A coherence of one everywhere (one average) says nothing and gives None.  Dips at
    antiresonances within the band do not end it.  Why analysers show only fs/2.56 of a record:
    J. S. Bendat, A. G. Piersol, "Random Data", 4th ed., Wiley 2010, §10.3.3 (anti-aliasing filters),
    §9.2.3 (coherence and the random error of FRF estimates).

    Examples
    --------
    Coherence 0.99 up to 110 Hz, falling linearly to 0.4 at 125 Hz (a filter's roll-off): it is 0.9
    at 110 + 15 * 0.09 / 0.59 = 112.29 Hz, and the last line below that is 112.25 Hz:

    >>> f = np.linspace(0.0, 125.0, 1001)
    >>> coh = np.where(f < 110.0, 0.99, 0.99 - 0.59 * (f - 110.0) / 15.0)[None, :]
    >>> coherent_top(f, coh)
    112.25
    >>> coherent_top(f, np.ones((1, f.size))) is None
    True
    """
    if coherence is None:
        return None
    f = np.asarray(freq_hz, float)
    c = np.nan_to_num(np.mean(np.reshape(coherence, (-1, f.size)), axis=0), nan=0.0)
    width = 2 * max(2, int(EDGE_SMOOTH * f.size / 2)) + 1   # odd: centred on each line
    smooth = uniform_filter1d(c, width, mode="nearest")
    good = np.flatnonzero(smooth >= EDGE_COHERENCE)
    if good.size == 0 or good[-1] == f.size - 1 or f.size - 1 - good[-1] > EDGE_SHARE * f.size:
        return None
    return float(f[good[-1]])


def band_note(f: np.ndarray, fmin: float | None, fmax: float | None, top_hz: float,
              edge_hz: float | None) -> str:
    """The line saying which band [Hz] was fitted (lines ``f``) and why: the options given, every
    line of the FRFs, or an upper edge at ``edge_hz`` below a poorly measured top up to ``top_hz``
    (:func:`coherent_top`)."""
    lower = "--fmin" if fmin is not None else "the first line above 0 Hz"
    if fmax is not None:
        upper = "--fmax"
    elif edge_hz is not None:
        upper = (f"the last line before the FRFs' coherence stays below {EDGE_COHERENCE:g} up to "
                 f"{top_hz:.4g} Hz (an anti-aliasing filter's roll-off or the end of the excitation: --fmax "
                 "to fit those lines)")
    else:
        upper = "the highest line"
    return f"band fitted {f.min():.3g}-{f.max():.4g} Hz, from {lower} to {upper}"


def _shapes(constants: np.ndarray, driving_point: int | None) -> tuple[np.ndarray, bool]:
    if driving_point is not None:
        return to_real(mass_normalised(constants, driving_point)), True
    return to_real(unit_max(constants)), False


def _pick(clusters: PoleClusters, poles_hz: Sequence[float], tol: float = 0.05) -> PoleClusters:
    """The cluster nearest each requested frequency (within relative ``tol``), in the order given."""
    if clusters.freq_hz.size == 0:
        raise ModalError("identify --poles: the stabilisation diagram holds no stable pole")
    want = np.asarray(poles_hz, float)
    k = np.argmin(np.abs(want[:, None] - clusters.freq_hz[None, :]), axis=1)
    far = np.abs(clusters.freq_hz[k] / want - 1) > tol
    if far.any():
        j = int(np.flatnonzero(far)[0])
        raise ModalError(f"identify --poles: no stable pole within {100 * tol:g} % of {want[j]:g} Hz "
                         f"(nearest {clusters.freq_hz[k[j]]:.4g} Hz)")
    if np.unique(k).size < k.size:
        dup = [w for w, kk in zip(want, k, strict=True) if np.sum(k == kk) > 1]
        raise ModalError(f"identify --poles: {dup[0]:g} and {dup[1]:g} Hz pick the same stable pole "
                         f"({clusters.freq_hz[k[want == dup[0]][0]]:.4g} Hz)")
    return clusters.subset(k)


def _near(f: np.ndarray, fn: np.ndarray, zeta: np.ndarray) -> np.ndarray:
    """[n_modes, n_freq] lines within three half-power bandwidths (and three lines) of each mode."""
    width = np.maximum(3 * 2 * zeta * fn, 3 * np.median(np.diff(f)))
    return np.abs(f[None, :] - fn[:, None]) <= width[:, None]


def _fit(f: np.ndarray, H: np.ndarray, clusters: PoleClusters, quantity: str) -> LsfdResult:
    """LSFD of the clusters' poles, each mode's F statistic taken against the residual variance near
    the mode (:func:`_near`) rather than over the band: FRF noise is rarely uniform (it grows with the
    response at resonances)."""
    fit = lsfd(f, H, clusters.pole, quantity=quantity)
    if clusters.freq_hz.size == 0:
        return fit
    res = np.sum(np.abs(H - fit.synthesis) ** 2, axis=(0, 1))                # [f]
    near = _near(f, clusters.freq_hz, clusters.damping_ratio)
    local = (near @ res) / near.sum(axis=1)
    return dataclasses.replace(fit, need=fit.need * (res.mean() / np.maximum(local, 1e-300)))


def rank_one_misfit(residues: np.ndarray) -> np.ndarray:
    """[n_modes] second over first singular value of each mode's residue matrix ``residues`` [n_out,
    n_in, n_modes] (two or more references): 0 for the rank-one residue ``psi L^T`` of a single
    physical pole, near 1 where a pole's residues in the several reference columns do not share one
    shape (a pole that fits part of a resonance in one column and part in another; Peeters et al.
    2004, Shock Vib. 11, §3: each pole's residue matrix has rank one).

    Examples
    --------
    >>> A = np.stack([np.outer([1.0, 2.0], [1.0, -0.5]), np.eye(2)], axis=-1)
    >>> np.round(rank_one_misfit(A), 3).tolist()
    [0.0, 1.0]
    """
    s = np.linalg.svd(np.moveaxis(np.asarray(residues), -1, 0), compute_uv=False)   # [n_modes, k]
    return np.where(s[:, 0] > 0, s[:, 1] / np.where(s[:, 0] > 0, s[:, 0], 1.0), 0.0)


def _split(clusters: PoleClusters, constants: np.ndarray, split_mac: float = 0.9,
           misfit: np.ndarray | None = None, split_misfit: float = 0.3,
           background: np.ndarray | None = None, apart: np.ndarray | None = None) -> tuple[int, str] | None:
    """The neighbouring pair (index of the lower one, why) that is one mode the model split in two:
    their half-power bands [f(1 - zeta), f(1 + zeta)] overlap and they have the same shape (MAC >=
    ``split_mac``; with one output any such pair not marked ``apart`` [n_modes - 1], two resonances
    the FRF shows: :func:`_resolved`), or (several references) the residue matrix of
    either is not of rank one (:func:`rank_one_misfit` ``misfit`` >= ``split_misfit``: neither pole
    alone is a mode).  An FRF whose resonance is not a single pole, e.g.
    biased by leakage at a few lines per bandwidth (Welch-averaged random tests: a split pair about
    0.6 of a bandwidth apart straddling the mode), is fitted by such a pair at high orders; two
    physical modes that close with the same shape cannot be told apart by these references.  Poles
    marked ``background`` [n_modes] pair with none."""
    fn, zeta = clusters.freq_hz, clusters.damping_ratio
    if fn.size < 2:
        return None
    gap = np.diff(fn) / (zeta[:-1] * fn[:-1] + zeta[1:] * fn[1:])
    macs = np.array([mac(constants[:, [k]], constants[:, [k + 1]])[0, 0] for k in range(fn.size - 1)]) \
        if constants.shape[0] > 1 else np.ones(fn.size - 1)
    worst = np.maximum(misfit[:-1], misfit[1:]) if misfit is not None else np.zeros(fn.size - 1)
    pairs = (gap < 1) & ((macs >= split_mac) | (worst >= split_misfit))
    if apart is not None:
        pairs &= ~apart
    if background is not None:
        pairs &= ~background[:-1] & ~background[1:]
    pairs = np.flatnonzero(pairs)
    if pairs.size == 0:
        return None
    k = int(pairs[np.argmin(gap[pairs])])
    return k, (f"with the same shape (MAC {macs[k]:.2f})" if macs[k] >= split_mac else
               f"residues not of rank one (second singular value {worst[k]:.2f} of the first)")


def _local_pole(f: np.ndarray, H: np.ndarray, clusters: PoleClusters, fit: LsfdResult, quantity: str,
                skip: Sequence[int], start: complex, half_widths: float = 3.0) -> complex:
    """The single pole fitting the FRFs ``H`` near ``start`` once the modes of ``fit`` other than
    those at indices ``skip`` are taken out (:func:`modal.lsfd.refine_pole`; ``start`` when the fit
    leaves its half-power band)."""
    others = np.setdiff1d(np.arange(clusters.freq_hz.size), skip)
    rest = H - synthesis_of(f, clusters.pole[others], fit.residues[..., others], quantity)
    return refine_pole(f, rest, start, quantity=quantity, half_widths=half_widths)


def _with_pole(clusters: PoleClusters, k: int, pole: complex) -> PoleClusters:
    """``clusters`` with the pole of mode k replaced by ``pole`` (rad/s)."""
    at = np.arange(clusters.freq_hz.size) == k
    return dataclasses.replace(clusters, freq_hz=np.where(at, np.abs(pole) / (2 * np.pi), clusters.freq_hz),
                               damping_ratio=np.where(at, -pole.real / np.abs(pole), clusters.damping_ratio),
                               pole=np.where(at, pole, clusters.pole))


def _merge(clusters: PoleClusters, k: int, constants: np.ndarray, f: np.ndarray, H: np.ndarray,
           fit: LsfdResult, quantity: str) -> PoleClusters:
    """Clusters k and k + 1 replaced by one whose pole is their average weighted by the size of their
    modal constants: a pair that leakage splits straddles the mode it models.  With two or more
    references (columns often measured in separate runs, e.g. one sine sweep per input, each seeing
    the resonance slightly moved) the pair is not symmetric about the mode and the average is biased
    towards the broader pole's damping (0.20 % for 0.18 % at 65.45 Hz on beam_ring_mimo_frf): there
    the merged pole is the single pole that best fits the FRFs within three half-power bandwidths,
    the other modes taken out (:func:`_local_pole`), when it lies between the pair."""
    w = np.linalg.norm(constants[:, [k, k + 1]], axis=0)
    pole = np.sum(w * clusters.pole[[k, k + 1]]) / np.sum(w)
    if H.shape[1] > 1:
        single = _local_pole(f, H, clusters, fit, quantity, (k, k + 1), pole)
        if clusters.freq_hz[k] <= np.abs(single) / (2 * np.pi) <= clusters.freq_hz[k + 1]:
            pole = single
    at = np.arange(clusters.freq_hz.size) == k
    joined = dataclasses.replace(clusters, n_stable=np.where(at, clusters.n_stable[[k, k + 1]].max(),
                                                             clusters.n_stable),
                                 members=clusters.members[:k] + (np.concatenate(clusters.members[k:k + 2]),)
                                 + clusters.members[k + 1:])
    return _with_pole(joined, k, pole).subset(np.arange(clusters.freq_hz.size) != k + 1)


def _pair_key(clusters: PoleClusters, k: int) -> tuple:
    """The identity of the neighbouring modes k and k + 1 (their first member poles) across drops and
    merges of other modes."""
    return tuple(tuple(clusters.members[j][:1].tolist()) or (float(clusters.freq_hz[j]),) for j in (k, k + 1))


def _resolved(f: np.ndarray, H: np.ndarray, clusters: PoleClusters, k: int, constants: np.ndarray,
              fit: LsfdResult, quantity: str) -> float:
    """How many times the FRFs' own noise (:func:`_noise_rms`) the misfit is that the second pole of
    the pair k, k + 1 removes over the pair's lines (:func:`_near`): the rms of the difference of the
    squared misfits of the best single pole there (:func:`_merge`'s pole refined by
    :func:`_local_pole`) and of the pair, both in the LSFD of all modes.  With one output the MAC
    cannot tell a split resonance from two modes; the FRF can: a pair that explains what one pole
    leaves well above the noise is two resonances (ufffiles_analyser_frf: 461.8 and 470.8 Hz, 28-58
    times; the split 175.2/177.7 Hz, 1.5-1.7 times; docs/modal.md)."""
    pair = [k, k + 1]
    lines = np.flatnonzero(_near(f, clusters.freq_hz[pair], clusters.damping_ratio[pair]).any(axis=0))
    one = _merge(clusters, k, constants, f, H, fit, quantity)
    single = _local_pole(f, H, clusters, fit, quantity, pair, complex(one.pole[k]))
    fit_one = lsfd(f, H, _with_pole(one, k, single).pole, quantity=quantity)
    removed = (np.sum(np.abs(H - fit_one.synthesis)[..., lines] ** 2)
               - np.sum(np.abs(H - fit.synthesis)[..., lines] ** 2))
    noise = _noise_rms(H, lines)
    return float(np.sqrt(max(removed, 0.0) / lines.size) / noise) if noise > 0 else np.inf


def _protected(f: np.ndarray, clusters: PoleClusters, peaks_hz: np.ndarray) -> np.ndarray:
    """[n_modes] True for the candidate nearest each clear CMIF peak (within its half-power band or two
    lines): a mode the data show, which validation never drops."""
    out = np.zeros(clusters.freq_hz.size, bool)
    if clusters.freq_hz.size == 0 or peaks_hz.size == 0:
        return out
    k = np.argmin(np.abs(peaks_hz[:, None] - clusters.freq_hz[None, :]), axis=1)
    reach = np.maximum(2 * clusters.damping_ratio[k] * clusters.freq_hz[k], 2 * np.median(np.diff(f)))
    out[k[np.abs(peaks_hz - clusters.freq_hz[k]) <= reach]] = True
    return out


def _peak_within(f: np.ndarray, clusters: PoleClusters, peaks_hz: np.ndarray) -> np.ndarray:
    """[n_peaks, n_modes] True where the clear CMIF peak lies within the mode's half-power band or two
    lines of it."""
    gap = np.abs(peaks_hz[:, None] - clusters.freq_hz[None, :])
    reach = np.maximum(2 * clusters.damping_ratio * clusters.freq_hz, 2 * np.median(np.diff(f)))[None, :]
    return gap <= reach


def _explains(f: np.ndarray, clusters: PoleClusters, peaks_hz: np.ndarray) -> np.ndarray:
    """[n_peaks] True for each clear CMIF peak of ``peaks_hz`` a mode of ``clusters`` explains (lies
    within its half-power band or two lines of)."""
    return np.any(_peak_within(f, clusters, peaks_hz), axis=1)


def _candidates(f: np.ndarray, stab: Stabilisation, peaks_hz: np.ndarray, tie_above: int) -> PoleClusters:
    """The diagram's candidate modes (:func:`modal.lscf.stable_clusters`).  In a diagram reaching above
    order ``tie_above`` (the default cap, past which pLSCF's poles are set by rounding and the order
    search ends), a chain whose count of stable orders falls short of the line by less than the count's
    own uncertainty is kept when a clear CMIF peak ``peaks_hz`` that no kept chain explains lies within
    its half-power band (or two lines): what the data show decides, not rounding (pyfrf_impact_frf:
    the chain of the clear peak at 1518.2 Hz, stable since order 66, fell half an order short at order
    411 with its FRF moved by 1e-9).  Below that cap the search raises the order while a clear peak is
    unexplained, and the count decides at a higher order (a chain taken at its first orders stopped
    the search too soon, with poles 2e-4 off on a lightly damped impact test)."""
    def tie_break(clusters: PoleClusters, kept: np.ndarray) -> np.ndarray:
        within = _peak_within(f, clusters, peaks_hz)                  # [n_peaks, n_modes]
        return np.any(within[~np.any(within[:, kept], axis=1)], axis=0)

    late = stab.order.size and stab.order.max() > tie_above
    return stable_clusters(stab, top=TOP_ORDERS, tie_break=tie_break if late else None)


def _explained(f: np.ndarray, clusters: PoleClusters, peaks_hz: np.ndarray) -> int:
    """How many of the clear CMIF peaks ``peaks_hz`` a mode of ``clusters`` explains (:func:`_explains`)."""
    return int(_explains(f, clusters, peaks_hz).sum())


def _reach(f: np.ndarray, clusters: PoleClusters) -> np.ndarray:
    """[n_modes] Hz: half the half-power bandwidth of each mode, at least 1.5 lines."""
    return np.maximum(clusters.damping_ratio * clusters.freq_hz, 1.5 * np.median(np.diff(f)))


def _unseen(f: np.ndarray, clusters: PoleClusters, visible_hz: np.ndarray | None) -> np.ndarray:
    """[n_modes] True for a mode with no visible peak (:func:`modal.peaks.visible_peaks`) within its
    half-power bandwidth (or 1.5 lines) and no other mode within two of its half-power bandwidths: a
    resonance the FRFs do not show (a close neighbour may hide a mode's own peak; three bandwidths
    kept near-duplicates of real modes on the real-data impact entries).  A neighbour ``BROAD`` times
    narrower does not count: a light mode's narrow peak hides no broad resonance two broad bandwidths
    away (pyfrf_impact_frf in the ``exp(-i w dt)`` basis: a 1.9 % pole at 4718 Hz with no peak of its
    own was kept for the 0.03 % mode 248 Hz away)."""
    fn, zeta = clusters.freq_hz, clusters.damping_ratio
    if visible_hz is None or fn.size == 0:
        return np.zeros(fn.size, bool)
    seen = np.any(np.abs(visible_hz[None, :] - fn[:, None]) <= _reach(f, clusters)[:, None], axis=1)
    gap = np.abs(fn[:, None] - fn[None, :]) + np.diag(np.full(fn.size, np.inf))
    width = np.maximum(2 * zeta * fn, 1.5 * np.median(np.diff(f)))
    close = np.any((gap <= 2 * width[:, None]) & (width[:, None] < BROAD * width[None, :]), axis=1)
    return ~seen & ~close


def _late(f: np.ndarray, stab: Stabilisation, clusters: PoleClusters, base: int | None,
          peaks_hz: np.ndarray) -> tuple[np.ndarray, list[str]]:
    """[n_modes] True for the validated modes to report: not those first stable above the default cap
    of the model order ``base`` (None: no such cap, the user's ``--max-order``) that explain no clear
    CMIF peak (:func:`_protected`); and a line for each one left out.  The order is raised above the
    default cap only to explain clear peaks the modes below it missed
    (:func:`modal.lscf.adaptive_stabilisation`); a pole the extra order brings anywhere else is one
    the data did not ask for (on the real-data impact FRFs: weak noise poles first stable at 1.5-2
    times the default cap).  Such poles stay in the synthesis as background terms: taking them out
    of the fit changes the F statistics of the modes beside them (a pole of 2.5 % damping near 930 Hz
    carried the background under a one-line peak at 1518 Hz)."""
    if base is None or clusters.freq_hz.size == 0:
        return np.ones(clusters.freq_hz.size, bool), []
    first = np.array([stab.order[m[stab.stable[m]]].min() for m in clusters.members])
    late = (first > base) & ~_protected(f, clusters, peaks_hz)
    notes = [f"left out the pole at {clusters.freq_hz[k]:.5g} Hz (damping "
             f"{100 * clusters.damping_ratio[k]:.3g} %): first stable at order {first[k]}, above the default "
             f"cap {base}, at no clear CMIF peak (kept in the synthesis as a background pole)"
             for k in np.flatnonzero(late)]
    return ~late, notes


def _validate(f: np.ndarray, H: np.ndarray, clusters: PoleClusters, quantity: str, reference: int,
              limits: Thresholds, peaks_hz: np.ndarray | None = None, visible_hz: np.ndarray | None = None
              ) -> tuple[PoleClusters, LsfdResult, list[str], np.ndarray]:
    """LSFD of the candidate poles (:func:`_fit`); a pole pair that splits one mode (:func:`_split`)
    is merged into one pole (:func:`_merge`), unless the narrower one's half-power band does not reach
    the other and the other's is ``BROAD`` times wider: that broad pole is a background pole under
    the mode, kept in the fit, never a mode nor dropped.  Else the least needed failing mode is
    dropped, and the fit is redone until every mode passes (one change at a time, so of two duplicates
    one stays); a
    mode the FRFs do not show (:func:`_unseen`) fails too.  The mode nearest a clear CMIF peak
    (``peaks_hz``, :func:`_protected`) is never dropped.  A mode failing the F test is refitted once at
    its local pole (:func:`_local_pole`) before it is dropped.  Returns the clusters, their fit, the
    warnings and [n_modes] True for the background poles."""
    warnings, refined, apart = [], set(), set()
    background = np.zeros(clusters.freq_hz.size, bool)
    while True:   # a loop over merged, refined or dropped modes (a few)
        fit = _fit(f, H, clusters, quantity)
        if clusters.freq_hz.size == 0:
            return clusters, fit, warnings, background
        residues = fit.modal_constants(clusters.pole)
        constants = residues[:, reference]
        keys = [_pair_key(clusters, k) for k in range(clusters.freq_hz.size - 1)]
        split = _split(clusters, constants, misfit=rank_one_misfit(residues) if H.shape[1] > 1 else None,
                       background=background, apart=np.array([key in apart for key in keys], bool))
        if split is not None:
            k, why = split
            half = clusters.damping_ratio[[k, k + 1]] * clusters.freq_hz[[k, k + 1]]
            narrow = k + int(np.argmin(half))
            broad = 2 * k + 1 - narrow
            if np.diff(clusters.freq_hz[[k, k + 1]])[0] > 2 * half.min() and half.max() >= BROAD * half.min():
                background[broad] = True
                warnings.append(f"kept the pole at {clusters.freq_hz[broad]:.5g} Hz (damping "
                                f"{100 * clusters.damping_ratio[broad]:.3g} %) in the synthesis as a "
                                f"background pole, no mode: its half-power band covers the mode at "
                                f"{clusters.freq_hz[narrow]:.5g} Hz, {why}, whose band does not reach it")
                continue
            if constants.shape[0] == 1:
                times = _resolved(f, H, clusters, k, constants, fit, quantity)
                if times >= ZOOM_ABOVE_NOISE:
                    apart.add(keys[k])
                    fa, fb = clusters.freq_hz[[k, k + 1]]
                    warnings.append(f"kept the poles at {fa:.5g} and {fb:.5g} Hz as two modes (half-power "
                                    "bands overlapping, one output): one pole leaves a misfit the second "
                                    f"explains, {times:.3g} times the FRFs' noise there")
                    continue
            clusters, (fa, fb) = (_merge(clusters, k, constants, f, H, fit, quantity),
                                  clusters.freq_hz[[k, k + 1]])
            background = np.delete(background, k + 1)
            warnings.append(f"merged the poles at {fa:.5g} and {fb:.5g} Hz into one mode (listed at its "
                            f"refined frequency): half-power bands overlapping, {why}, one resonance the "
                            "model split in two")
            continue
        phase = mpc(constants) if H.shape[0] >= 2 else None
        fails = fit.need < limits.need_min
        if phase is not None:
            fails |= phase < limits.mpc_min
        shown = _protected(f, clusters, np.zeros(0) if peaks_hz is None else peaks_hz)
        fails = (fails | _unseen(f, clusters, visible_hz)) & ~shown & ~background
        if not fails.any():
            return clusters, fit, warnings, background
        r = int(np.flatnonzero(fails)[np.argmin(fit.need[fails])])
        if fit.need[r] < limits.need_min and clusters.members[r].size \
                and int(clusters.members[r][0]) not in refined:
            # a resonance the pole misses (e.g. five times too much damping at one line per half-power
            # band) fits it badly and is not needed for that: test it again at its own local pole
            refined.add(int(clusters.members[r][0]))
            pole = _local_pole(f, H, clusters, fit, quantity, (r,), complex(clusters.pole[r]))
            if pole != clusters.pole[r]:
                clusters = _with_pole(clusters, r, pole)
                continue
        why = (f"F = {fit.need[r]:.3g} < {limits.need_min:g}: the measured FRFs do not need it"
               if fit.need[r] < limits.need_min else
               f"MPC {phase[r]:.2f} < {limits.mpc_min:g}" if phase is not None and phase[r] < limits.mpc_min
               else f"no FRF or CMIF peak of {VISIBLE_DB:g} dB within {_reach(f, clusters)[r]:.3g} Hz and "
                    "no close mode: the FRFs show no resonance there")
        warnings.append(f"dropped the pole at {clusters.freq_hz[r]:.5g} Hz (damping "
                        f"{100 * clusters.damping_ratio[r]:.3g} %): {why}")
        keep = np.arange(clusters.freq_hz.size) != r
        clusters, background = clusters.subset(keep), background[keep]


def _lscf(f: np.ndarray, H: np.ndarray, *, quantity: str, reference: int, max_order: int | None,
          poles_hz: Sequence[float] | None, limits: Thresholds, stored: StoredDiagram | None = None,
          coherence: np.ndarray | None = None) -> dict:
    peaks_hz = f[clear_peaks(f, H)] if not poles_hz else np.zeros(0)   # picked poles: no floor
    visible_hz = visible_peaks(f, H, prominence_db=VISIBLE_DB)


    def search(common: bool):
        default_base = default_caps(1 if common else H.shape[1], peaks_hz.size)[0]
        base = None if max_order is not None else default_base

        def evaluate(stab: Stabilisation):
            if poles_hz:
                return stable_clusters(stab, top=TOP_ORDERS).freq_hz.size, 0, None
            candidates = _candidates(f, stab, peaks_hz, default_base)
            clusters, fit, warnings, background = _validate(f, H, candidates, quantity, reference, limits,
                                                            peaks_hz, visible_hz)
            report, late = _late(f, stab, clusters, base, peaks_hz)
            report &= ~background
            return (int(report.sum()), _explained(f, clusters.subset(report), peaks_hz),
                    (clusters, fit, warnings + late, report))

        return adaptive_stabilisation(f, H, max_order=max_order, evaluate=evaluate, floor=peaks_hz.size,
                                      common=common)

    if poles_hz and stored is not None:   # run the stabilisation once, pick many times (modal.diagrams)
        stab, note = stored.stabilisation, (stored.order_note.removesuffix(PICKED) + PICKED)
    elif poles_hz:
        stab, note, found = search(False)
    elif H.shape[1] > 1:
        stab, note, found = _common_or_poly(f, peaks_hz, search)
    else:
        stab, note, found = _one_reference_basis(f, H, peaks_hz, search)
    if poles_hz:
        clusters = _pick(pole_clusters(stab, TOP_ORDERS), poles_hz)
        fit, warnings = _fit(f, H, clusters, quantity), []
        report = np.ones(clusters.freq_hz.size, bool)
    else:
        clusters, fit, warnings, report = found
        if max_order is None:
            clusters, fit, warnings, report = _zoom(f, H, clusters, fit, warnings, report, quantity=quantity,
                                                    reference=reference, limits=limits, peaks_hz=peaks_hz,
                                                    visible_hz=visible_hz, coherence=coherence, stab=stab)
    if not report.any():
        raise ModalError(f"identify: no stable poles between {f.min():g} and {f.max():g} Hz ({note})")
    constants = fit.modal_constants(clusters.pole)[:, reference][:, report]
    need = fit.need[report]
    clusters = clusters.subset(report)
    flat_h, flat_s = H.reshape(-1, f.size), fit.synthesis.reshape(-1, f.size)
    local = np.array([frac(flat_h[:, w].ravel(), flat_s[:, w].ravel())
                      for w in _near(f, clusters.freq_hz, clusters.damping_ratio)])   # per mode
    selected = np.zeros(stab.freq_hz.size, bool)
    if clusters.members:
        chosen = np.concatenate(clusters.members)
        selected[chosen[stab.stable[chosen]]] = True
    return {"fn": clusters.freq_hz, "zeta": clusters.damping_ratio, "constants": constants,
            "mpc": mpc(constants), "mpd": mpd(constants), "synthesis_corr": local, "need": need,
            "frf_synthesis_corr": frac(H, fit.synthesis), "band_freq_hz": f, "synthesis": fit.synthesis,
            "stabilisation": stab, "selected": selected, "order_note": note, "warnings": warnings}


def misfit_spans(f: np.ndarray, H: np.ndarray, synthesis: np.ndarray, coherence: np.ndarray | None = None
                 ) -> list[tuple[float, float]]:
    """(lo, hi) [Hz] of the runs of windows of ZOOM_LINES lines (half overlapping) where ``synthesis``
    misfits the FRFs ``H`` [n_out, n_in, n_freq] on lines ``f`` [Hz]: relative misfit
    ||H - synthesis|| / ||H|| at least ZOOM_MISFIT times the band's median, at a response level
    ||H|| at least the band's median (a weak stretch between modes, or noise at a band edge, is no
    missed mode).  Where a mode the whole-band fit missed may lie (docs/modal.md).

    Examples
    --------
    >>> f = np.arange(1.0, 400.0)
    >>> mode = lambda fn: 1 / (fn ** 2 - f ** 2 + 2j * 0.01 * fn * f)
    >>> H = (mode(100.0) + mode(300.0) + 0.3 * mode(200.0))[None, None, :] * f ** 2
    >>> without_200 = (mode(100.0) + mode(300.0))[None, None, :] * f ** 2
    >>> misfit_spans(f, H, without_200)
    [(185.0, 224.0)]
    """
    n = f.size
    if n < 4 * ZOOM_LINES:
        return []
    starts = np.arange(0, n - ZOOM_LINES + 1, ZOOM_LINES // 2)
    idx = starts[:, None] + np.arange(ZOOM_LINES)
    h2 = np.sum(np.abs(H.reshape(-1, n)) ** 2, axis=0)
    e2 = np.sum(np.abs((H - synthesis).reshape(-1, n)) ** 2, axis=0)
    level = np.sqrt(h2[idx].sum(axis=1))
    err = np.sqrt(e2[idx].sum(axis=1)) / np.maximum(level, np.finfo(float).tiny)
    flagged = (err >= ZOOM_MISFIT * np.median(err)) & (level >= np.median(level))
    if coherence is not None:   # noise, e.g. where an impact's force spectrum has a zero
        flagged &= np.mean(np.reshape(coherence, (-1, n)), axis=0)[idx].mean(axis=1) >= ZOOM_COHERENCE
    spans: list[list[int]] = []
    for s in starts[flagged]:   # a loop over flagged windows (a few)
        if spans and s <= spans[-1][1] + 1:
            spans[-1][1] = s + ZOOM_LINES - 1
        else:
            spans.append([int(s), int(s + ZOOM_LINES - 1)])
    return [(float(f[a]), float(f[b])) for a, b in spans]


def _above_noise(H: np.ndarray, synthesis: np.ndarray, lines: np.ndarray) -> bool:
    """True when the misfit of ``synthesis`` on ``lines`` stands ZOOM_ABOVE_NOISE times above the
    FRFs' own noise there, estimated from their second differences (white noise of variance s^2
    gives 6 s^2; the smooth curve of modes a few lines wide adds little): a misfit no larger is
    noise, e.g. where an impact's force spectrum has a zero, not a missed mode."""
    noise_rms = _noise_rms(H, lines)
    if np.isnan(noise_rms):
        return False
    misfit_rms = np.linalg.norm((H - synthesis)[..., lines]) / np.sqrt(lines.size)
    return bool(misfit_rms >= ZOOM_ABOVE_NOISE * noise_rms)


def _noise_rms(H: np.ndarray, lines: np.ndarray) -> float:
    """The rms noise of the FRFs ``H`` on ``lines`` (ascending indices) from their second differences
    (white noise of variance s^2 gives 6 s^2; the smooth curve of modes a few lines wide adds
    little); NaN when no line has its two predecessors among ``lines``."""
    run = lines[2:][lines[2:] - lines[:-2] == 2]   # lines whose two predecessors are lines too
    if run.size == 0:
        return float("nan")
    d2 = H[..., run] - 2 * H[..., run - 1] + H[..., run - 2]
    return float(np.linalg.norm(d2) / np.sqrt(6 * run.size))


def _refused_chain(stab: Stabilisation, clusters: PoleClusters, lo: float, hi: float, reach: np.ndarray
                   ) -> list[complex]:
    """[the pole] of the chain of the diagram ``stab`` in [lo, hi] Hz that is stable at the most orders,
    at least min_orders 5, but was refused by :func:`modal.lscf.stable_clusters` (stable at fewer than
    half the orders from its first), more than one half-power bandwidth (two ``reach``) from every
    mode of ``clusters``; [] when there is none."""
    chains = pole_clusters(stab, TOP_ORDERS)
    kept = stable_clusters(stab, top=TOP_ORDERS).freq_hz
    apart = np.abs(chains.freq_hz[:, None] - clusters.freq_hz[None, :]) > 2 * reach[None, :]
    ok = (chains.freq_hz >= lo) & (chains.freq_hz <= hi) & (chains.n_stable >= 5) & apart.all(axis=1) \
        & ~np.isin(chains.freq_hz, kept)
    if not ok.any():
        return []
    return [complex(chains.pole[np.flatnonzero(ok)[np.argmax(chains.n_stable[ok])]])]


def _zoom(f: np.ndarray, H: np.ndarray, clusters: PoleClusters, fit: LsfdResult, warnings: list[str],
          report: np.ndarray, *, quantity: str, reference: int, limits: Thresholds, peaks_hz: np.ndarray,
          visible_hz: np.ndarray, coherence: np.ndarray | None, stab: Stabilisation | None = None
          ) -> tuple[PoleClusters, LsfdResult, list[str], np.ndarray]:
    """Modes the whole-band fit missed where its synthesis misfits the FRFs (:func:`misfit_spans`).
    In each such span above SUSPENSION times the lowest mode (below, rigid-body motion on the
    suspension: Ewins 2000 §3.3) whose misfit away from the modes (three half-power bandwidths, their
    own leakage) stands above the FRFs' noise (:func:`_above_noise`), one pole is fitted to the
    residual (:func:`modal.lsfd.refine_pole`, started at ZOOM_ZETA at its largest residual there);
    it joins the candidates when it stays in the span and away from the modes.  A span wholly inside
    the modes' leakage has no residual of its own to fit: where its misfit stands above the noise,
    the candidate is the diagram's own chain there that :func:`modal.lscf.stable_clusters` refused
    (:func:`_refused_chain`; ``stab`` the stabilisation diagram, None: none).  All are validated
    again on the whole band (:func:`_validate`).
    The arguments and the result are those of the whole-band selection (clusters, fit, warnings, [n]
    True for the modes to report), returned as they were unless a new mode passes."""
    spans = misfit_spans(f, H, fit.synthesis, coherence)
    if not spans:
        return clusters, fit, warnings, report
    new: list[complex] = []
    rest = H - synthesis_of(f, clusters.pole, fit.residues, quantity)
    size = np.sqrt(np.sum(np.abs(rest.reshape(-1, f.size)) ** 2, axis=0))
    reach = _reach(f, clusters)
    lowest = clusters.freq_hz[report].min() if report.any() else 0.0
    taken = _near(f, clusters.freq_hz, clusters.damping_ratio).any(axis=0)   # the modes' own leakage
    for lo, hi in spans:   # a loop over misfit spans (a few)
        if hi < SUSPENSION * lowest:   # rigid-body or suspension modes, Ewins 2000 §3.3
            continue
        inside = np.flatnonzero((f >= lo) & (f <= hi) & ~taken)
        if inside.size < 3:   # the span lies in the modes' leakage: no residual of its own to fit
            span = np.flatnonzero((f >= lo) & (f <= hi))
            if stab is not None and span.size >= 3 and _above_noise(H, fit.synthesis, span):
                new += _refused_chain(stab, clusters, lo, hi, reach)
            continue
        if not _above_noise(H, fit.synthesis, inside):
            continue
        k = inside[np.argmax(size[inside])]
        wn = 2 * np.pi * f[k]
        start = complex(-ZOOM_ZETA * wn, wn * np.sqrt(1 - ZOOM_ZETA ** 2))
        pole = refine_pole(f, rest, start, quantity=quantity)
        fn = abs(pole) / (2 * np.pi)
        if pole != start and lo <= fn <= hi and not np.any(np.abs(clusters.freq_hz - fn) <= 6 * reach):
            new.append(pole)
    if not new:
        return clusters, fit, warnings, report
    poles = np.r_[clusters.pole, new]
    late = {int(m[0]) for m, r in zip(clusters.members, report, strict=True) if not r and m.size}
    joined = PoleClusters(np.abs(poles) / (2 * np.pi), -poles.real / np.abs(poles), poles,
                          np.r_[clusters.n_stable, np.zeros(len(new), int)],
                          clusters.members + tuple(np.zeros(0, int) for _ in new))   # no diagram poles
    joined = joined.subset(np.argsort(joined.freq_hz, kind="stable"))
    c2, fit2, w2, background = _validate(f, H, joined, quantity, reference, limits, peaks_hz, visible_hz)
    added = [f"{x:.5g}" for x, m in zip(c2.freq_hz, c2.members, strict=True) if not m.size]
    if not added:   # the whole-band result stands as it was
        return clusters, fit, warnings, report
    report2 = ~background & np.array([not (m.size and int(m[0]) in late) for m in c2.members], bool)
    note = (f"found {counted(len(added), 'mode')} at {', '.join(added)} Hz where the whole-band synthesis "
            "misfits the FRFs (one pole fitted to the residual there, or in a mode's leakage the diagram's "
            "chain stable at too few orders)")
    return c2, fit2, warnings + [w for w in w2 if w not in warnings] + [note], report2


def _common_or_poly(f: np.ndarray, peaks_hz: np.ndarray, search) -> tuple:
    """Two or more references: the modes of one common denominator (``search(True)``,
    :class:`modal.lscf.PoleEstimator`) or of the poly-reference fit (``search(False)``), whichever
    explains more clear CMIF peaks ``peaks_hz``, then reports more validated modes (a tie: the common
    denominator).  The common denominator finds heavily damped modes the poly-reference diagram's
    noise poles hide (beam_ring_mimo_frf: 9 modes against 7); the poly-reference fit separates two
    modes closer than their bandwidths by their participation, where a common denominator may have one
    pole for both (the close pair 0.5 % apart of tests/test_modal_identify_acceptance.py, one seed in
    two).  The order note says which fit was used."""
    def score(result) -> tuple[int, int]:
        found = result[2]
        if found is None:
            return -1, -1
        clusters, _, _, report = found
        return _explained(f, clusters.subset(report), peaks_hz), int(report.sum())

    common, poly = search(True), search(False)
    (a_shown, a_n), (b_shown, b_n) = score(common), score(poly)
    if (b_shown, b_n) > (a_shown, a_n):
        return poly[0], (f"{poly[1]}; poly-reference fit: {b_n} modes explaining {b_shown} clear CMIF peaks, "
                         f"one common denominator {a_n} explaining {a_shown}"), poly[2]
    note = (f"{common[1]}; one denominator common to the references: {a_n} modes explaining {a_shown} "
            f"clear CMIF peaks, the poly-reference fit {b_n} explaining {b_shown}")
    return common[0], note, common[2]


def _one_reference_basis(f: np.ndarray, H: np.ndarray, peaks_hz: np.ndarray, search) -> tuple:
    """One reference: the modes of the pLSCF in the basis ``z = exp(+i w dt)`` (``search(False)``),
    unless the basis ``z = exp(-i w dt)`` (``search(True)``, :mod:`modal.lscf`), where noise poles
    come out at negative damping, explains every clear CMIF peak ``peaks_hz`` the first explains and
    more, and its synthesis fits the FRFs about as well: its misfit share (1 - mean FRF correlation,
    :func:`modal.indicators.frac`) at most BASIS_MISFIT times the first's; "every peak and more" is
    also met by BASIS_PEAKS more clear peaks, whichever they are.  Which single peak each basis explains
    is no firmer than a chain's count of stable orders (:func:`_candidates`): pyfrf_impact_frf with its
    FRF moved by 6e-8 had exp(+i w dt) explain the clear peak at 824 Hz, which exp(-i w dt) did not,
    and "every peak" kept exp(+i w dt) although exp(-i w dt) explained 17 clear peaks against 15 at a
    misfit share of 0.027 against 0.065.  A better fit alone does not decide: on ufffiles_analyser_frf
    exp(-i w dt) explains as many (8), at a correlation of 0.989 against 0.660, with 6 extra modes
    instead of 1.
    The selection rules were tuned on the first basis; the second finds modes its noise poles hide
    (pyfrf_impact_frf: 1518.2 Hz, one line in its half-power band) but does not replace it blindly:
    on beam_ring_chirp it explains two more clear peaks, both in the charge amplifier's roll-off above
    100 Hz, and fits the FRFs worse (correlation 0.975 against 0.984), the 7.4 % mode 0.7 % off; on
    pyfrf_impact_single_hit it loses the clear peak at 4128 Hz (its pole is stable at fewer than half
    the orders) and fits worse (0.50 against 0.93).  A misfit share a few % apart is no evidence
    either way (pyfrf_impact_5hits: 0.069 in exp(-i w dt) against 0.066): there the peaks decide;
    chirp's 1.6 times and the single hit's 7 times do not pass.
    The order note says which basis was used."""
    def explained(result) -> tuple[np.ndarray, float]:
        if result[2] is None:
            return np.zeros(peaks_hz.size, bool), -np.inf
        clusters, fit, _, report = result[2]
        return _explains(f, clusters.subset(report), peaks_hz), float(np.mean(frac(H, fit.synthesis)))

    plus, minus = search(False), search(True)
    (a, a_corr), (b, b_corr) = explained(plus), explained(minus)
    gain = int(b.sum()) - int(a.sum())
    used = bool((gain >= BASIS_PEAKS or gain > 0 and not np.any(a & ~b))
                and 1 - b_corr <= BASIS_MISFIT * (1 - a_corr))
    (n_used, corr_used), (n_other, corr_other) = ((b, b_corr), (a, a_corr))[::1 if used else -1]
    words = (f"of the two pLSCF fits, {BASIS_WORDS[used]} is used: it explains "
             f"{counted(int(n_used.sum()), 'clear CMIF peak')} at an FRF correlation of {corr_used:.3f}; "
             f"{BASIS_WORDS[not used]} explains {int(n_other.sum())} at {corr_other:.3f}")
    found = minus if used else plus
    return found[0], f"{found[1]}; {words}", found[2]


ADVICE = {   # what to change when modes have few lines in their half-power band, by how the FRFs were made
    "random": "the Hann window's leakage biases damping high at so few lines: use a longer nfft "
              "(frf --nfft)",
    "impact": "damping is unbiased if each hit's response died away within its record; if not, "
              "record longer hits or use an exponential window (its damping is removed); nfft is not "
              "the knob for impact runs",
    "sweep": "the FRFs are the whole sweep's: finer resolution needs a longer record (a slower sweep)",
    None: "damping may be biased high if these FRFs were Welch-averaged (leakage); finer resolution "
          "(longer records) resolves it",
}


def _resolution(f: np.ndarray, fn: np.ndarray, zeta: np.ndarray, excitation: str | None,
                decay_rate_per_s: float = 0.0) -> tuple[list[str], tuple[str, ...]]:
    """One summary warning for the modes ``fn`` [Hz], ``zeta`` [-] with fewer than
    MIN_LINES_PER_BANDWIDTH lines (``f`` [Hz]) in their half-power band in the FRFs (widened by an
    exponential window of ``decay_rate_per_s`` [1/s]: sigma / pi Hz), with the advice right for
    ``excitation`` (``random`` for Welch-averaged FRFs of random or sweep runs, ``impact``, None
    unknown), and the per-mode lines."""
    lines = (2 * zeta * fn + decay_rate_per_s / np.pi) / float(np.median(np.diff(f)))
    few = np.flatnonzero(lines < MIN_LINES_PER_BANDWIDTH)
    details = tuple(f"mode at {fn[k]:.4g} Hz: {lines[k]:.1f} lines in its half-power band "
                    f"(< {MIN_LINES_PER_BANDWIDTH})" for k in few)
    if few.size == 0:
        return [], details
    at = ", ".join(f"{fn[k]:.4g}" for k in few[:4]) + (", ..." if few.size > 4 else "")
    span = (f"{lines[few].min():.1f}" if few.size == 1 else f"{lines[few].min():.1f}-{lines[few].max():.1f}")
    verb, whose = ("has", "its") if few.size == 1 else ("have", "their")
    advice = ADVICE[excitation if excitation in ADVICE else None]
    return [f"{few.size} of {counted(fn.size, 'mode')} ({at} Hz) {verb} {span} lines in {whose} "
            f"half-power band (< {MIN_LINES_PER_BANDWIDTH}): {advice}"], details


@dataclass(frozen=True)
class FrfInputs:
    """What an FRF identification method (modal.registry.METHODS, input ``frf``) is given: ``freq_hz``
    [Hz] and ``H`` [n_out, n_in, n_band] in the band, ``coherence`` [n_out, n_band] or None, the FRFs'
    ``quantity``, the ``reference`` input column, ``max_order``, the ``poles_hz`` [Hz] to pick, the
    validation ``thresholds`` and the ``stored`` diagram of these inputs, if any (modal.diagrams)."""

    freq_hz: np.ndarray
    H: np.ndarray
    coherence: np.ndarray | None
    quantity: str
    reference: int
    max_order: int | None
    poles_hz: Sequence[float] | None
    thresholds: Thresholds
    stored: StoredDiagram | None = None   # a stored diagram of these inputs to pick ``poles_hz`` from


@dataclass(frozen=True)
class Poles:
    """What an FRF identification method returns: ``freq_hz`` [Hz] and ``damping_ratio`` [n], the modal
    ``constants`` [n_out, n] of the reference column, its ``warnings``, whether the constants are
    ``scaled`` residues (mass-normalised shapes with a driving point) and the ``extra`` fields of
    :class:`Modes` it sets (validation indicators, stabilisation diagram, ...)."""

    freq_hz: np.ndarray
    damping_ratio: np.ndarray
    constants: np.ndarray
    warnings: tuple[str, ...]
    scaled: bool
    extra: Mapping[str, object]


def lscf_poles(inp: FrfInputs) -> Poles:
    """pLSCF over an adaptive stabilisation diagram, automatic selection (or the poles nearest
    ``poles_hz``), LSFD shapes and validation (the ``lscf`` method)."""
    with one_blas_thread():
        extra = _lscf(inp.freq_hz, inp.H, quantity=inp.quantity, reference=inp.reference,
                      max_order=inp.max_order, poles_hz=inp.poles_hz, limits=inp.thresholds,
                      stored=inp.stored, coherence=inp.coherence)
    fn, zeta, constants = extra.pop("fn"), extra.pop("zeta"), extra.pop("constants")
    warnings = extra.pop("warnings")
    return Poles(fn, zeta, constants, tuple(warnings), True, extra)


def peak_poles(inp: FrfInputs) -> Poles:
    """CMIF peaks, half-power damping and quadrature shapes (the ``peak`` method)."""
    f, Hb, coh = inp.freq_hz, inp.H, inp.coherence
    warnings: list[str] = []
    lines = pick_peaks(f, Hb, coherence=coh)
    if lines.size == 0:
        raise ModalError(f"identify: no resonance peak between {f.min():g} and {f.max():g} Hz")
    rec = convert(Hb, f, inp.quantity, "receptance")
    indicator = cmif(rec)[0]
    fits = []
    for k in lines:   # a loop over peaks (modes)
        try:
            fits.append(half_power(f, indicator, int(k)))
        except ModalError as exc:
            warnings.append(str(exc))
    if not fits:
        raise ModalError("identify: no peak had two half-power points (" + "; ".join(warnings) + ")")
    warnings += [w for h in fits for w in h.warnings]
    fn = np.array([h.fn_hz for h in fits])
    zeta = np.array([h.damping_ratio for h in fits])
    used = np.array([int(np.argmin(np.abs(f - h.fn_hz))) for h in fits])
    constants = quadrature_shapes(rec, used, inp.reference).astype(complex)
    return Poles(fn, zeta, constants, tuple(warnings), False, {})


def identify(freq_hz: np.ndarray, H: np.ndarray, *, method: str = "lscf", fmin: float | None = None,
             fmax: float | None = None, coherence: np.ndarray | None = None,
             quantity: str = "accelerance", decay_rate_per_s: float = 0.0, reference: int = 0,
             driving_point: int | None = None, max_order: int | None = None,
             poles_hz: Sequence[float] | None = None, thresholds: Thresholds | None = None,
             excitation: str | None = None, diagrams: DiagramStore | None = None) -> Modes:
    """Identify the modes of FRFs ``H`` [n_out, n_in, n_freq] in [fmin, fmax] Hz.

    ``quantity`` of H (accelerance, mobility, receptance); ``decay_rate_per_s`` [1/s] of an exponential
    window to remove; ``reference`` the input column whose shapes are reported; ``driving_point`` the
    output row measured at that input (mass-normalised shapes).  pLSCF: the highest model order grows
    until the stable poles stop growing, capped by ``max_order``
    (:func:`modal.lscf.adaptive_stabilisation`); ``poles_hz`` picks the stable poles nearest these
    frequencies (and keeps exactly them); otherwise the automatically selected poles are validated by
    the synthesis against ``thresholds`` (:class:`Thresholds`).  ``excitation`` (``random``:
    Welch-averaged FRFs, ``impact``, None unknown) chooses the advice given when modes have few lines in
    their half-power band (one warning; the per-mode lines in ``Modes.details``).  ``diagrams``: stored
    stabilisation diagrams (modal.diagrams); ``poles_hz`` are picked from the one whose key matches
    these FRFs and options instead of running the stabilisation again.
    """
    if method not in METHODS or output_only(method):
        frf_methods = [m for m in METHODS if not output_only(m)]
        raise ModalError(f"method {method!r}: use one of {', '.join(frf_methods)}")
    H = np.asarray(H)
    if H.ndim != 3 or H.shape[-1] != len(freq_hz):
        raise ModalError(f"identify: FRFs of shape {H.shape} do not match {len(freq_hz)} lines")
    if not np.all(np.isfinite(H[..., np.asarray(freq_hz) > 0])):
        raise ModalError("identify: the FRFs contain NaN or infinite values")
    fault = range_fault(H[..., np.asarray(freq_hz) > 0])
    if fault:
        raise ModalError(f"identify: H{list(fault[0]) or ''} {fault[1]}")   # H[output, input, line]
    if decay_rate_per_s < 0 or not np.isfinite(decay_rate_per_s):
        raise ModalError(f"identify: exponential window decay {decay_rate_per_s:g} 1/s must be >= 0")
    band = _band(freq_hz, fmin, fmax)
    edge = coherent_top(np.asarray(freq_hz, float)[band], coherence[:, band]) \
        if fmax is None and coherence is not None else None
    if edge is not None and np.count_nonzero(band & (np.asarray(freq_hz, float) <= edge)) >= 8:
        band &= np.asarray(freq_hz, float) <= edge
    else:
        edge = None
    f, Hb = np.asarray(freq_hz, float)[band], H[..., band]
    warnings: list[str] = [nyquist_note(fmax, float(np.max(freq_hz)))] if fmax is not None \
        and fmax > np.max(freq_hz) else []
    coh = coherence[:, band] if coherence is not None else None
    limits = thresholds or Thresholds()
    key = inputs_key(f, Hb, method=method, quantity=quantity, reference=reference, max_order=max_order,
                     thresholds=limits)
    stored = diagrams.find(key) if diagrams is not None and poles_hz else None
    found = METHODS.entry(method).runner()(FrfInputs(f, Hb, coh, quantity, reference, max_order, poles_hz,
                                                     limits, stored))
    fn, zeta, constants, extra = found.freq_hz, found.damping_ratio, found.constants, dict(found.extra)
    warnings += found.warnings
    keep = np.ones(fn.size, bool)
    if decay_rate_per_s:
        fn, zeta = remove_added_damping(fn, zeta, decay_rate_per_s)
        keep = zeta > 0   # less damping than the window itself added: not a structural mode
        warnings += [f"dropped a pole at {fr:.4g} Hz: its damping is below the exponential window's "
                     f"(a spurious or aliased pole)" for fr in fn[~keep]]
        if not keep.any():
            raise ModalError("identify: every pole had less damping than the exponential window added")
    shapes, massn = _shapes(constants[:, keep], driving_point if found.scaled else None)
    order = np.flatnonzero(keep)[np.argsort(fn[keep])]
    per_mode = {k: extra[k][order] for k in ("mpc", "mpd", "synthesis_corr", "need") if k in extra}
    coarse, details = _resolution(f, fn[order], zeta[order], excitation, decay_rate_per_s)
    warnings += coarse
    return Modes(fn[order], zeta[order], shapes[:, np.argsort(fn[keep])], constants[:, order], method, massn,
                 tuple(warnings), **per_mode, **{k: v for k, v in extra.items() if k not in per_mode},
                 details=details, diagram_key=key,
                 band_note=band_note(f, fmin, fmax, float(np.max(freq_hz)), edge), excitation=excitation)


def restated(before: Modes, after: Modes, freq_hz: np.ndarray, decay_rate_per_s: float = 0.0) -> Modes:
    """``after`` (``before`` with its poles refined, :mod:`modal.uncertainty`) with the warning on lines
    per half-power band and its per-mode details said at its own poles, the frequencies the modal
    table lists (FRF lines ``freq_hz`` [Hz], exponential window ``decay_rate_per_s`` [1/s])."""
    old, _ = _resolution(freq_hz, before.freq_hz, before.damping_ratio, before.excitation, decay_rate_per_s)
    new, details = _resolution(freq_hz, after.freq_hz, after.damping_ratio, after.excitation,
                               decay_rate_per_s)
    return dataclasses.replace(after, warnings=tuple(w for w in after.warnings if w not in old) + tuple(new),
                               details=details)


def modes_table(modes: Modes, outputs: Sequence[str], *, config: str = "run",
                pose: Mapping[str, float] | None = None, source: str = "experiment") -> ModalTable:
    """The modal table of one configuration: config, mode, freq_hz, damping_ratio, source, the
    validation indicators ``mpc``, ``mpd_deg`` and ``synthesis_corr`` (pLSCF), pose.*,
    shape.<output>."""
    records = []
    for r in range(modes.freq_hz.size):
        row: dict[str, object] = {"config": config, "mode": r + 1, "freq_hz": float(modes.freq_hz[r]),
                                  "damping_ratio": float(modes.damping_ratio[r]), "source": source}
        row.update({col: float(getattr(modes, k)[r]) for k, col in INDICATORS.items()
                    if getattr(modes, k) is not None})
        row.update({k: float(getattr(modes, k)[r]) for k in ("freq_std_hz", "damping_std")
                    if getattr(modes, k) is not None})
        row.update({f"pose.{k}": v for k, v in (pose or {}).items()})
        row.update({f"shape.{name}": float(modes.shapes[j, r]) for j, name in enumerate(outputs)})
        records.append(row)
    return ModalTable.from_records(records, source=f"identified ({modes.method})")


def synthesis_path(out: str | Path) -> Path:
    """Where :func:`write_synthesis_csv` writes for the modal table ``out``: MODES.synthesis.csv."""
    p = Path(out)
    return p.with_name(p.stem + ".synthesis.csv")


def write_synthesis_csv(out: str | Path, modes_by_config: Mapping[str, tuple[Modes, Sequence[str]]]
                        ) -> Path:
    """Write the FRAC of every measured and synthesised FRF (columns config, output, input = the
    1-based reference number, synthesis_corr) next to the modal table ``out``; configurations
    identified without a synthesis (peak picking) are left out."""
    rows = []
    for config, (modes, outputs) in modes_by_config.items():   # a loop over configurations
        corr = modes.frf_synthesis_corr
        if corr is not None:
            rows += [{"config": config, "output": outputs[o], "input": i + 1,
                      "synthesis_corr": float(corr[o, i])} for o, i in np.ndindex(*corr.shape)]
    path = synthesis_path(out)
    with atomic_path(path) as tmp:
        pd.DataFrame(rows, columns=["config", "output", "input", "synthesis_corr"]).to_csv(
            tmp, index=False, float_format="%.9g")
    return path


def identify_modes(freq_hz: np.ndarray, H: np.ndarray, *, outputs: Sequence[str] | None = None,
                   config: str = "run", pose: Mapping[str, float] | None = None, **options) -> ModalTable:
    """:func:`identify` then :func:`modes_table` (outputs default to ``o1``, ``o2``, ...)."""
    modes = identify(freq_hz, H, **options)
    names = list(outputs) if outputs is not None else [f"o{j + 1}" for j in range(np.shape(H)[0])]
    return modes_table(modes, names, config=config, pose=pose)
