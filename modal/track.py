"""Modes of an arm while it moves: output-only identification in sliding windows, each tagged with the
pose its encoders measured, modes followed from window to window, motor/gear harmonics set apart.

Windows.  The record is cut into windows of ``window_s`` (default: ``periods`` periods of the slowest
mode, found by a frequency-domain decomposition of the whole record when ``fmin`` is not given) every
``hop_s`` (default: the time the pose needs to move a quarter of a pose bin at the 90th percentile of
its rate, between an eighth and a half of the window).  A window's pose is the mean of each encoder
channel over it, its spread their standard deviation; a window whose spread exceeds ``max_spread_deg``
is skipped and counted.  Each pose variable's rate (deg/s) is the least-squares slope over the window.

Identification.  SSI-cov (:func:`flexmodal.modal.ssi.ssi_cov`, its stabilisation diagram and automatic
selection) on each window, with at most ``MAX_REFS`` reference channels.

Harmonics (:mod:`flexmodal.modal.harmonics`).  A pole whose frequency is an order of a joint's speed
(``f = order x |rate| / 360``, orders given or found from the data) or whose band-passed signal has
the amplitude statistics of a sinusoid (kurtosis near 1.5, where a mode's random response has 3) is a
harmonic: it is reported with its order, never as a mode, and never joins a mode's track.  The orders
are found first and taken out of the record before identification
(:func:`flexmodal.modal.harmonics.remove_orders`: each harmonic's phase is its order times the encoder
angle), so a harmonic dwelling on a mode pulls the mode's estimate much less.

Tracking.  Modes are followed window by window by a Hungarian assignment between the open tracks and
the window's poles with the cost ``|f - f_pred| / (gate_rel f) + (1 - MAC) / (1 - mac_min)`` (the
predicted frequency extrapolates the track's last two estimates, so modes whose frequencies cross are
told apart by their shapes and slopes; MAC is the smaller of the MACs with the track's last shape and
with its shape ``MAC_LAG_S`` earlier, so a pole whose shape turns gradually from one mode's to
another's, two crossing modes merged, is not followed across); a pair outside either gate is no
match.  A track with no match
for more than ``max_gap`` windows is ended (a mode that disappears ends, it is not swapped for another);
a pole with no track starts one.  Tracks shorter than ``min_windows`` are dropped; the rest are numbered
by their median frequency.

The modal map.  Windows are binned by pose (``bin_deg`` per pose variable); each (bin, mode) row holds
the mean frequency and damping ratio of the windows in it, their standard errors, the number of windows
and the mean shape: a modal table (contract/table.py) whose configurations are pose bins, so that compare,
predict --poses and diagnose read it unchanged.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field

import numpy as np
from scipy.optimize import linear_sum_assignment

from flexmodal.checked_io.plural import counted
from flexmodal.contract.mac import mac
from flexmodal.contract.table import POSE_PREFIX, SHAPE_PREFIX, ModalTable
from flexmodal.modal.errors import ModalError
from flexmodal.modal.harmonics import find_orders, is_order, remove_orders, sinusoid_kurtosis
from flexmodal.modal.ssi import default_block_rows, ssi_cov

MIN_WINDOW_SAMPLES = 64    # a tracking window shorter than this holds no covariance to fit
MIN_HOP_FRACTION = 1 / 64  # windows stepping by less overlap by > 98 %: no new data, only more work
MAX_REFS = 4               # SSI reference channels per window (the ones with the largest RMS)
LOOK_S = 4.0              # the slowest mode is looked for in stretches this long ...
LOOK_STRETCHES = 6        # ... this many, spread over the record, by SSI whose time lags reach half a
LOOK_PERIODS = 40.0       # period of a mode holding this many periods in a stretch (10 Hz in 4 s)
STITCH_GAP = 40           # windows: a later track may continue an earlier one after this many
STITCH_FIRST = 5          # ... when its prediction agrees with one of the later one's first this many
MAC_LAG_S = 3.0           # a pole joins a track only if its shape matches the track's last one and the
#                           one this many seconds before (two crossing modes merged into one pole whose
#                           shape turns from one to the other are not followed from one to the other)
SMOOTH_WINDOWS = 5        # the refinement's frequency track: a running median over this many estimates,
SMOOTH_SPAN = 15          # then a quadratic Savitzky-Golay fit over this many
REFINE_PERIODS = 150.0    # the refinement's window holds this many periods (at least the first pass's)
REFINE_BAND = 0.4         # the refinement looks within +-40 % of the track's frequency ...
REFINE_RATE = 4.0         # ... decimated to this many times the band's top,
REFINE_ORDER = 30         # ... with SSI model orders up to this, and block rows spanning lags of
REFINE_LAG_PERIODS = 4.0  # this many periods (as many as the window holds, 40 samples per row)
ZETA_FLOOR = 0.002        # the damping ratio the refinement's window is sized for is at least this
DAMPING_PER_SPAN = 8.0    # long-span damping estimates per span (linear in time between them)
KURTOSIS_SINE = 2.0        # band-passed kurtosis below this: a sinusoid (1.5) rather than a mode (3)


@dataclass(frozen=True)
class TrackOptions:
    """The tracking's settings (module docstring); None picks the default from the record."""

    window_s: float | None = None
    hop_s: float | None = None
    periods: float = 80.0
    fmin: float | None = None
    fmax: float | None = None
    max_order: int = 40
    max_spread_deg: float = 5.0
    bin_deg: float = 5.0
    gate_rel: float = 0.05
    mac_min: float = 0.7
    max_gap: int = 3
    min_windows: int = 5
    orders: tuple[float, ...] = ()        # known harmonic orders per joint revolution; () finds them
    order_tol: float = 0.02
    kurtosis_max: float = KURTOSIS_SINE
    refine: int = 2               # passes of the warped-time refinement (0: none)
    damping_rel_std: float = 0.12  # the refinement's window is long enough for this relative standard
    #                                deviation of the damping ratio (closed-form bound, damping_bound)


@dataclass(frozen=True)
class WindowPoles:
    """One window: its centre ``t_s``, pose and spread (deg), joint rates (deg/s), and the poles SSI
    kept (``freq_hz``, ``damping_ratio``, real ``shapes`` [n_out, n]), each pole's band-passed
    ``kurtosis`` and its ``harmonic`` order (0: not a harmonic)."""

    t_s: float
    pose: Mapping[str, float]
    spread: Mapping[str, float]
    rate_deg_per_s: Mapping[str, float]
    freq_hz: np.ndarray
    damping_ratio: np.ndarray
    shapes: np.ndarray
    kurtosis: np.ndarray
    harmonic: np.ndarray


@dataclass(frozen=True)
class Harmonic:
    """A harmonic pole: window centre ``t_s`` [s], ``freq_hz``, the pose variable whose speed it
    follows (``joint``, '' when found by its sinusoid statistics alone) and its ``order``."""

    t_s: float
    freq_hz: float
    joint: str
    order: float


@dataclass(frozen=True)
class Track:
    """One mode followed along the record: window indices, frequencies, damping ratios, shapes, the
    band-passed kurtosis and, once refined, the seconds of record behind each estimate ``span_s``."""

    windows: np.ndarray
    freq_hz: np.ndarray
    damping_ratio: np.ndarray
    shapes: np.ndarray   # [n_out, n_windows]
    kurtosis: np.ndarray
    span_s: np.ndarray = field(default_factory=lambda: np.zeros(0))   # seconds of record per estimate


@dataclass(frozen=True)
class TrackResult:
    """What tracking found: the window length and hop [s], the analysed ``windows``, the number
    ``skipped`` for their pose spread (``gapped``: for lost samples), the mode ``tracks`` (numbered by
    median frequency), the ``harmonics`` (every harmonic pole) and their ``orders`` per joint, the
    modal ``table`` (the map) and the output channel names."""

    window_s: float
    hop_s: float
    windows: tuple[WindowPoles, ...]
    skipped: int
    tracks: tuple[Track, ...]
    harmonics: tuple[Harmonic, ...]
    orders: Mapping[str, tuple[float, ...]]
    table: ModalTable
    outputs: tuple[str, ...]
    warnings: tuple[str, ...] = field(default=())
    gapped: int = 0      # windows skipped because they hold lost samples


def window_plan(n_samples: int, sample_rate_hz: float, pose: np.ndarray, lowest_hz: float,
                options: TrackOptions, min_samples: int = 0) -> tuple[int, int]:
    """Window length and hop in samples (module docstring) for a record whose pose channels are
    ``pose`` [n, n_vars] (degrees) and slowest mode ``lowest_hz``; a default window holds at least
    ``min_samples``."""
    fs = sample_rate_hz
    win = options.window_s or max(options.periods / lowest_hz, min_samples / fs)
    if options.hop_s:
        hop = options.hop_s
    else:
        step = max(int(fs * 0.1), 1)
        rate = np.abs(np.diff(pose[::step], axis=0)).max(axis=1) * fs / step if pose.shape[1] else np.zeros(1)
        fast = float(np.nanpercentile(rate, 90)) if np.isfinite(rate).any() else 0.0
        hop = 0.25 * options.bin_deg / fast if fast > 0 else 0.5 * win
        hop = float(np.clip(hop, win / 8, win / 2))
    if win * fs >= n_samples + 0.5:   # rounded below; compared first: 1e308 s has no sample count
        raise ModalError(f"tracking window of {win:.3g} s is longer than the record "
                         f"({n_samples / fs:.3g} s); give a shorter window")
    n_win = int(round(win * fs))
    if n_win < MIN_WINDOW_SAMPLES:
        raise ModalError(f"tracking window of {win:.3g} s holds {n_win} samples at {fs:g} Hz; give at least "
                         f"{MIN_WINDOW_SAMPLES / fs:.3g} s ({MIN_WINDOW_SAMPLES} samples)")
    if hop < MIN_HOP_FRACTION * win:   # also at least one sample, as the window holds 64 or more
        raise ModalError(f"tracking hop (--hop) of {hop:.3g} s is shorter than 1/{1 / MIN_HOP_FRACTION:g} of "
                         f"the {win:.3g} s window: windows overlapping by more than 98 % add work, no data; "
                         f"give at least {MIN_HOP_FRACTION * win:.3g} s")
    if hop > win:   # was "no mode was followed over enough windows": few windows, data between them unused
        raise ModalError(f"tracking hop (--hop) of {hop:.3g} s is longer than the {win:.3g} s window "
                         f"(--window{'' if options.window_s else ', its default'}): the samples between "
                         "windows would never be identified; give a hop of at most the window")
    return n_win, max(1, int(round(min(hop * fs, n_samples))))   # a hop past the end: one window


def _references(y: np.ndarray) -> list[int]:
    """Up to MAX_REFS reference channels: the strongest, evenly spread over the channel order."""
    if y.shape[1] <= MAX_REFS:
        return list(range(y.shape[1]))
    return sorted(np.linspace(0, y.shape[1] - 1, MAX_REFS).round().astype(int).tolist())


def _slope(x: np.ndarray, fs: float) -> np.ndarray:
    """Least-squares slope of each column of ``x`` [n, k] per second."""
    t = (np.arange(x.shape[0]) - (x.shape[0] - 1) / 2) / fs
    return t @ (x - x.mean(axis=0)) / (t @ t)


def _merge_doublets(f: np.ndarray, z: np.ndarray, sh: np.ndarray, options: TrackOptions
                    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """One pole for each mode of a window: neighbours (ascending frequency) closer than half the
    tracking gate with MAC >= ``mac_min`` (a mode whose frequency moved within the window, fitted
    by two poles) are replaced by their mean."""
    if f.size < 2:
        return f, z, sh
    close = (np.diff(f) < 0.5 * options.gate_rel * f[:-1]) & \
        (np.diag(mac(sh[:, :-1], sh[:, 1:])) >= options.mac_min)
    group = np.concatenate([[0], np.cumsum(~close)])
    n = group[-1] + 1
    count = np.bincount(group, minlength=n)
    signs = np.where(np.sum(sh * sh[:, np.searchsorted(group, group)], axis=0) < 0, -1.0, 1.0)
    shapes = np.zeros((sh.shape[0], n))
    np.add.at(shapes.T, group, (sh * signs).T)
    return (np.bincount(group, f, n) / count, np.bincount(group, z, n) / count,
            shapes / np.abs(shapes).max(axis=0))


def window_starts(y: np.ndarray, pose: np.ndarray, sample_rate_hz: float, options: TrackOptions,
                  lowest_hz: float) -> tuple[list[int], int, int, int, int, list[int]]:
    """The windows of the outputs ``y`` [n, n_out] to identify: their first samples (those whose pose
    spread is small enough and which hold no lost sample, a NaN row of ``y`` or ``pose``: a gap of the
    acquisition), the numbers skipped for their spread and for a gap, the window length and hop
    (samples) and the SSI reference channels."""
    fs = sample_rate_hz
    refs = _references(y)
    q = max(1, int(fs // (4 * options.fmax))) if options.fmax else 1   # SSI's decimation (docs/oma.md)
    rows = max(default_block_rows(options.max_order, len(refs), fs / q, lowest_hz),
               -(-options.max_order // y.shape[1]) + 1)
    n_win, n_hop = window_plan(y.shape[0], fs, pose, lowest_hz, options, 40 * rows * q)   # SSI's minimum
    lost = np.concatenate([[0], np.cumsum(~np.isfinite(np.hstack([y, pose])).all(axis=1))])
    starts, skipped, gapped = [], 0, 0
    for a in range(0, y.shape[0] - n_win + 1, n_hop):   # a loop over windows
        if lost[a + n_win] > lost[a]:
            gapped += 1
        elif np.any(pose[a:a + n_win].std(axis=0) > options.max_spread_deg):
            skipped += 1
        else:
            starts.append(a)
    return starts, skipped, gapped, n_win, n_hop, refs


def identify_windows(y: np.ndarray, pose: np.ndarray, pose_names: Sequence[str], sample_rate_hz: float,
                     options: TrackOptions, lowest_hz: float, starts: Sequence[int], n_win: int,
                     refs: list[int]) -> list[WindowPoles]:
    """SSI-cov in the windows of ``n_win`` samples from ``starts`` (:func:`window_starts`)."""
    fs = sample_rate_hz
    out = []
    for a in starts:   # a loop over windows
        p = pose[a:a + n_win]
        seg = y[a:a + n_win]
        try:
            res = ssi_cov(seg, fs, references=refs, fmin=options.fmin, fmax=options.fmax,
                          max_order=options.max_order, lowest_hz=lowest_hz)
            m = res.modes
            f, z, sh = m.freq_hz, m.damping_ratio, m.shapes
        except ModalError:
            f, z, sh = np.zeros(0), np.zeros(0), np.zeros((y.shape[1], 0))
        f, z, sh = _merge_doublets(f, z, sh, options)
        kurt = sinusoid_kurtosis(seg, fs, f, z, n_win / fs, sh)
        out.append(WindowPoles((a + n_win / 2) / fs,
                               dict(zip(pose_names, p.mean(axis=0).tolist(), strict=True)),
                               dict(zip(pose_names, p.std(axis=0).tolist(), strict=True)),
                               dict(zip(pose_names, _slope(p, fs).tolist(), strict=True)),
                               f, z, sh, kurt, np.zeros(f.size)))
    return out


def joint_orders(y: np.ndarray, pose: np.ndarray, pose_names: Sequence[str], sample_rate_hz: float,
                 starts: Sequence[int], n_win: int, options: TrackOptions) -> dict[str, tuple[float, ...]]:
    """The harmonic orders of each pose variable's joint (per revolution): ``options.orders`` when
    given, else found in the windows from ``starts`` (:func:`flexmodal.modal.harmonics.find_orders`)."""
    orders: dict[str, tuple[float, ...]] = {}
    band = (options.fmin or 0.0, options.fmax or sample_rate_hz / 2)
    for j, v in enumerate(pose_names):   # a loop over pose variables
        if options.orders:
            orders[v] = tuple(options.orders)
            continue
        pieces = [(y[a:a + n_win], pose[a:a + n_win, j]) for a in starts]
        speed = np.array([abs(float(_slope(pose[a:a + n_win, j:j + 1], sample_rate_hz)[0])) / 360.0
                          for a in starts])
        orders[v] = find_orders(pieces, sample_rate_hz, speed, band, options.order_tol) if starts else ()
    return orders


def mark_harmonics(windows: list[WindowPoles], orders: Mapping[str, tuple[float, ...]], options: TrackOptions
                   ) -> tuple[list[WindowPoles], list[Harmonic]]:
    """Flag each window's poles on a harmonic ``orders`` of a joint's speed (module docstring) and list
    them."""
    marked, found = [], []
    for w in windows:   # a loop over windows
        harm = np.zeros(w.freq_hz.size)
        joint = [""] * w.freq_hz.size
        for v, ords in orders.items():
            o = is_order(w.freq_hz, abs(w.rate_deg_per_s[v]) / 360.0, ords, options.order_tol)
            new = (o > 0) & (harm == 0)
            harm[new] = o[new]
            for i in np.flatnonzero(new):
                joint[i] = v
        for i in np.flatnonzero(harm):
            found.append(Harmonic(w.t_s, float(w.freq_hz[i]), joint[i], float(harm[i])))
        marked.append(WindowPoles(w.t_s, w.pose, w.spread, w.rate_deg_per_s, w.freq_hz, w.damping_ratio,
                                  w.shapes, w.kurtosis, harm))
    return marked, found


def follow(windows: Sequence[WindowPoles], options: TrackOptions) -> list[Track]:
    """Follow the non-harmonic poles from window to window (module docstring).  Over a stretch of skipped
    windows (a gap, a spread) the frequency gate widens in proportion to the time elapsed beyond
    ``max_gap + 1`` hops (the longest a track waits for a match when no window is skipped)."""
    open_: list[dict] = []
    done: list[dict] = []
    hop = float(np.median(np.diff([w.t_s for w in windows]))) if len(windows) > 1 else 1.0
    for k, w in enumerate(windows):   # a loop over windows
        idx = np.flatnonzero(w.harmonic == 0)
        f, sh = w.freq_hz[idx], w.shapes[:, idx]
        if open_ and idx.size:
            reach = (options.max_gap + 1) * hop   # the longest wait for a match when no window is skipped
            pred = np.array([_predict(t, w.t_s, reach) for t in open_])
            widen = np.array([max(1.0, (w.t_s - t["t"][-1]) / reach) for t in open_])
            last = np.column_stack([t["shapes"][-1] for t in open_])
            lag = np.column_stack([t["shapes"][int(np.searchsorted(t["t"], t["t"][-1] - MAC_LAG_S))]
                                   for t in open_])
            mac_ = np.nan_to_num(np.minimum(mac(last, sh), mac(lag, sh)), nan=0.0)  # undefined: unlike
            df = np.abs(f[None, :] - pred[:, None]) / (options.gate_rel * (pred * widen)[:, None])
            dm = (1 - mac_) / (1 - options.mac_min)
            cost = df + dm
            bad = (df > 1) | (dm > 1)
            rows, cols = linear_sum_assignment(np.where(bad, 1e6, cost))
            pairs = [(r, c) for r, c in zip(rows, cols, strict=True) if not bad[r, c]]
        else:
            pairs = []
        used = set()
        for r, c in pairs:
            t = open_[r]
            j = idx[c]
            t["windows"].append(k)
            t["t"].append(w.t_s)
            t["freq"].append(w.freq_hz[j])
            t["zeta"].append(w.damping_ratio[j])
            t["shapes"].append(w.shapes[:, j])
            t["kurt"].append(w.kurtosis[j])
            used.add(c)
        matched = {r for r, _ in pairs}
        still = []
        for r, t in enumerate(open_):
            (still if r in matched or k - t["windows"][-1] <= options.max_gap else done).append(t)
        open_ = still
        for c in range(idx.size):
            if c not in used:
                j = idx[c]
                open_.append({"windows": [k], "t": [w.t_s], "freq": [w.freq_hz[j]],
                              "zeta": [w.damping_ratio[j]], "shapes": [w.shapes[:, j]],
                              "kurt": [w.kurtosis[j]]})
    done += open_
    tracks = [Track(np.array(t["windows"]), np.array(t["freq"]), np.array(t["zeta"]),
                    np.column_stack(t["shapes"]), np.array(t["kurt"]))
              for t in sorted(done, key=lambda t: t["windows"][0])]
    tracks = _stitch(tracks, options, np.array([w.t_s for w in windows]))
    return sorted([t for t in tracks if t.windows.size >= options.min_windows],
                  key=lambda t: float(np.median(t.freq_hz)))


def _stitch(tracks: list[Track], options: TrackOptions, times: np.ndarray) -> list[Track]:
    """Join a track to an earlier one that ended at most ``STITCH_GAP`` windows before it began when the
    earlier one's last estimates, extrapolated linearly in time over the gap (``times``: the windows'
    centres, so windows skipped between count), and one of the later one's first ``STITCH_FIRST`` agree
    within the gates (frequency, widened in proportion to the gap beyond ``max_gap``, and MAC): one mode
    whose poles were missed for a while, or set aside as a harmonic where one crossed it, or merged with
    a crossing mode (the later track's first poles then have mixed shapes)."""
    out: list[Track] = []
    for t in tracks:   # a loop over tracks, in order of their first window
        best, best_cost = -1, 1.0
        for i, u in enumerate(out):
            if u.windows[-1] >= t.windows[0] or t.windows[0] - u.windows[-1] > STITCH_GAP:
                continue
            n = min(5, u.freq_hz.size)
            slope = np.polyfit(times[u.windows[-n:]], u.freq_hz[-n:], 1)[0] if n >= 2 else 0.0
            first = slice(0, min(STITCH_FIRST, t.windows.size))   # any of the later track's first few
            gap = t.windows[first] - u.windows[-1]
            pred = u.freq_hz[-1] + slope * (times[t.windows[first]] - times[u.windows[-1]])
            df = np.abs(t.freq_hz[first] - pred) / (options.gate_rel * np.maximum(1.0, gap / options.max_gap)
                                                   * pred)
            dm = (1 - mac(u.shapes[:, -1:], t.shapes[:, first])[0]) / (1 - options.mac_min)
            cost = np.where((df <= 1) & (dm <= 1), df + dm, np.inf)
            if cost.min() < best_cost:
                best, best_cost = i, float(cost.min())
        if best < 0:
            out.append(t)
            continue
        u = out[best]
        out[best] = Track(np.concatenate([u.windows, t.windows]), np.concatenate([u.freq_hz, t.freq_hz]),
                          np.concatenate([u.damping_ratio, t.damping_ratio]), np.hstack([u.shapes, t.shapes]),
                          np.concatenate([u.kurtosis, t.kurtosis]))
    return out


def _predict(track: dict, t_s: float, reach_s: float) -> float:
    """The track's frequency extrapolated to time ``t_s`` from its last two estimates, or, beyond
    ``reach_s`` after its last one (windows skipped between), along the least-squares line in time
    through its last five (a two-point slope carried that far amplifies their scatter)."""
    f, t = track["freq"], track["t"]
    if len(f) < 2:
        return float(f[-1])
    if t_s - t[-1] > reach_s:
        slope = np.polyfit(t[-5:], f[-5:], 1)[0]
    else:
        slope = (f[-1] - f[-2]) / (t[-1] - t[-2])
    return float(f[-1] + slope * (t_s - t[-1]))


def refine(y: np.ndarray, sample_rate_hz: float, windows: Sequence[WindowPoles], tracks: Sequence[Track],
           n_win: int, orders: Mapping[str, tuple[float, ...]], options: TrackOptions,
           damping: bool = True) -> list[Track]:
    """Second pass: each mode re-identified at every window centre of its span, over the first pass's
    window or ``REFINE_PERIODS`` periods if longer (warping keeps the drift out), in its own warped time
    (:func:`flexmodal.modal.warp.warp` along the track's frequencies, median-smoothed over
    ``SMOOTH_WINDOWS`` and interpolated in time), decimated to at least four times ``f_c (1 +
    REFINE_BAND)``, by SSI-cov in ``f_c (1 +- REFINE_BAND)`` with block rows over ``REFINE_LAG_PERIODS``;
    the selected mode nearest ``f_c`` within the gates (frequency, and MAC with the track's nearest
    first-pass shape and with its shape ``MAC_LAG_S`` away: at a crossing the nearest may be a mixed
    one) replaces the first pass's estimate, and fills the windows the first pass missed.  A pole on a
    harmonic order (within ``order_tol``) is left out.  With ``damping``, the damping
    ratio then comes from the same identification over the longer span that holds its relative standard
    deviation to ``options.damping_rel_std`` (:func:`damping_span_s` at the track's median damping ratio;
    the drift is warped out, so a long span adds no bandwidth), the frequency and shape staying those of
    the shorter one; ``span_s`` records the seconds behind each damping ratio.  Spans a few windows apart
    share most of their data, so the long-span damping ratio is identified every ``1 / DAMPING_PER_SPAN``
    of its span and taken linear in time between.  Tracks keep their order."""
    import scipy.ndimage
    import scipy.signal

    fs = sample_rate_hz
    centres = np.array([w.t_s for w in windows])
    refs = _references(y)
    out = []
    for tr in tracks:   # a loop over modes
        f_s = scipy.ndimage.median_filter(tr.freq_hz, min(SMOOTH_WINDOWS, tr.freq_hz.size), mode="nearest")
        if f_s.size > SMOOTH_SPAN:
            f_s = scipy.signal.savgol_filter(f_s, SMOOTH_SPAN, 2)
        keep: list[tuple[int, float, float, np.ndarray, float]] = []
        zeta = max(ZETA_FLOOR, float(np.median(tr.damping_ratio)))
        long: dict[int, tuple[float, float]] = {}   # window -> damping ratio over the long span, span [s]
        for k in range(int(tr.windows[0]), int(tr.windows[-1]) + 1):   # a loop over windows
            f_c = float(np.interp(centres[k], centres[tr.windows], f_s))
            at = centres[tr.windows]   # the nearest first-pass shape and the one MAC_LAG_S before (after)
            near_k = int(np.argmin(np.abs(tr.windows - k)))
            lag_k = int(np.argmin(np.abs(at - (centres[k] - MAC_LAG_S))))
            lag_k = int(np.argmin(np.abs(at - (centres[k] + MAC_LAG_S)))) if lag_k == near_k else lag_k
            shape = tr.shapes[:, [near_k, lag_k]]
            rates = {v: abs(windows[k].rate_deg_per_s[v]) / 360.0 for v in orders}
            n = min(y.shape[0], max(n_win, int(REFINE_PERIODS / f_c * fs)))
            pole = _warped_pole(y, fs, centres, k, tr, f_s, n, refs, shape, rates, orders, options)
            if pole is None:
                continue
            f, z, sh = pole
            keep.append((k, f, z, sh, n / fs))
            n_z = min(y.shape[0], int(damping_span_s(f_c, zeta, options.damping_rel_std) * fs))
            step = n_z / fs / DAMPING_PER_SPAN   # long-span estimates this far apart [s] (module docstring)
            last = max(long, default=None)
            if damping and n_z > n and (last is None or centres[k] - centres[last] >= step):
                pole_z = _warped_pole(y, fs, centres, k, tr, f_s, n_z, refs, sh[:, None], rates, orders,
                                      options)
                if pole_z is not None:
                    long[k] = (pole_z[1], n_z / fs)
        if len(keep) < options.min_windows:
            out.append(tr)
            continue
        if long:   # the long-span damping ratios, linear in time between the windows they were found at
            at = np.array(sorted(long))
            z_long = np.interp(centres[[k[0] for k in keep]], centres[at], [long[a][0] for a in at])
            span = np.interp(centres[[k[0] for k in keep]], centres[at], [long[a][1] for a in at])
            keep = [(k, f, float(z), sh, float(t)) for (k, f, _, sh, _), z, t in zip(keep, z_long, span,
                                                                                       strict=True)]
        idx = np.array([k[0] for k in keep])
        kurt = np.interp(idx, tr.windows, tr.kurtosis)
        out.append(Track(idx, np.array([k[1] for k in keep]), np.array([k[2] for k in keep]),
                         np.column_stack([k[3] for k in keep]), kurt, np.array([k[4] for k in keep])))
    return out


def drop_duplicates(tracks: Sequence[Track], options: TrackOptions) -> list[Track]:
    """Tracks without the ones that follow another, longer track's mode: a track at least half of whose
    windows hold the other's estimate within half the frequency gate and with MAC >= ``mac_min`` (a
    first-pass track that followed a harmonic across a mode, re-identified onto that mode) is dropped;
    a track that overlaps another only at an end and agrees with it (so) over at least half of the
    windows they share is joined to it (one mode whose first-pass track broke where it drifted fast,
    its pieces re-identified onto the same mode), the longer track's estimates kept where both have one."""
    kept: list[Track] = []
    for t in sorted(tracks, key=lambda t: -t.windows.size):   # a loop over tracks, longest first
        same, join = 0, -1
        for m, u in enumerate(kept):
            common, i, j = np.intersect1d(t.windows, u.windows, return_indices=True)
            if common.size:
                close = np.abs(t.freq_hz[i] / u.freq_hz[j] - 1) < 0.5 * options.gate_rel
                alike = np.diag(mac(t.shapes[:, i], u.shapes[:, j])) >= options.mac_min
                agree = int(np.sum(close & alike))
                same = max(same, agree)
                if join < 0 and agree >= 0.5 * common.size and t.span_s.size > 0 and u.span_s.size > 0:
                    join = m
        if same >= 0.5 * t.windows.size:
            continue
        if join < 0:
            kept.append(t)
            continue
        u = kept[join]
        own = ~np.isin(t.windows, u.windows)
        order = np.argsort(np.concatenate([u.windows, t.windows[own]]), kind="stable")
        kept[join] = Track(*(np.concatenate([a, b[..., own]], axis=-1)[..., order] for a, b in (
            (u.windows, t.windows), (u.freq_hz, t.freq_hz), (u.damping_ratio, t.damping_ratio),
            (u.shapes, t.shapes), (u.kurtosis, t.kurtosis), (u.span_s, t.span_s))))
    return sorted(kept, key=lambda t: float(np.median(t.freq_hz)))


def _warped_pole(y: np.ndarray, fs: float, centres: np.ndarray, k: int, tr: Track, f_s: np.ndarray, n: int,
                 refs: list[int], shape: np.ndarray, rates: Mapping[str, float],
                 orders: Mapping[str, tuple[float, ...]], options: TrackOptions
                 ) -> tuple[float, float, np.ndarray] | None:
    """The mode of track ``tr`` at window ``k`` from ``n`` samples around its centre in the track's warped
    time (:func:`refine`): frequency, damping ratio and shape of the selected SSI mode nearest the
    smoothed track ``f_s`` within the gates (frequency, and the smallest MAC with the columns of
    ``shape`` [n_out, r]), or None (none there, or one on a harmonic order of the joint speeds ``rates``
    [rev/s])."""
    mid = int(round(centres[k] * fs))
    f_c = float(np.interp(centres[k], centres[tr.windows], f_s))
    a = int(np.clip(mid - n // 2, 0, y.shape[0] - n))
    g = np.interp(np.arange(a, a + n) / fs, centres[tr.windows], f_s)
    q = max(1, int(fs // (REFINE_RATE * (1 + REFINE_BAND) * f_c)))   # decimated (REFINE_RATE)
    seg = _warped(y[a:a + n], fs, g, mid - a, q)
    rows = min(seg.shape[0] // 40, max(-(-REFINE_ORDER // len(refs)) + 2,
                                       int(np.ceil(REFINE_LAG_PERIODS * fs / q / f_c))))
    try:
        m = ssi_cov(seg, fs / q, references=refs, fmin=(1 - REFINE_BAND) * f_c, fmax=(1 + REFINE_BAND) * f_c,
                    max_order=REFINE_ORDER, block_rows=rows).modes
    except ModalError:
        return None
    unlike = 1 - np.nan_to_num(mac(shape, m.shapes), nan=0.0).min(axis=0)   # undefined MAC: unlike
    near = np.abs(m.freq_hz / f_c - 1) / options.gate_rel + unlike / (
        1 - options.mac_min)
    j = int(np.argmin(near))
    on_order = any(is_order(m.freq_hz[j:j + 1], rates[v], o, options.order_tol)[0] for v, o in orders.items())
    if near[j] > 1 or on_order:
        return None
    return float(m.freq_hz[j]), float(m.damping_ratio[j]), m.shapes[:, j]


def _warped(y: np.ndarray, sample_rate_hz: float, freq_hz: np.ndarray, centre: int, q: int) -> np.ndarray:
    """``y`` warped along ``freq_hz`` (:func:`flexmodal.modal.warp.warp`) and decimated by ``q``; the rows
    that lost samples (NaN: a gap) reach, with the spline's and the decimation filter's support around
    them, are NaN in the result (SSI leaves NaN rows out of its covariances)."""
    import scipy.ndimage
    import scipy.signal

    from flexmodal.modal.warp import warp

    lost = ~np.isfinite(y).all(axis=1)
    x = warp(np.where(lost[:, None], 0.0, y), sample_rate_hz, freq_hz, centre)
    x = scipy.signal.resample_poly(x, 1, q, axis=0) if q > 1 else x
    if lost.any():
        reach = np.abs(warp(lost[:, None].astype(float), sample_rate_hz, freq_hz, centre)[:, 0]) > 1e-3
        reach = scipy.ndimage.binary_dilation(reach, iterations=10 * q + 4)   # resample_poly: 10 q taps
        x[reach[::q][:x.shape[0]]] = np.nan
    return x


def damping_bound(freq_hz: np.ndarray, damping_ratio: np.ndarray, span_s: np.ndarray) -> np.ndarray:
    """Relative standard deviation of a damping ratio estimated from ``span_s`` seconds of a mode's
    response to broadband excitation: ``1 / sqrt(2 pi zeta f T)``.

    The large-sample variance of the AR(2) coefficient ``a2 = -r^2`` is ``(1 - a2^2) / N`` (Box, Jenkins &
    Reinsel, *Time Series Analysis*, 4th ed., 2008, §7.2.2), with ``r = exp(-zeta w dt)`` and ``N = T /
    dt`` that is ``var(zeta w) = zeta w / T`` (Gersch 1974, J. Sound Vib. 34(1) 63-79, finds the same
    order for the Cramer-Rao bound of structural damping): no estimator does much better from ``T``
    seconds, whatever the method — the decay time ``1 / (zeta w)`` has to be seen about ``1 / std^2``
    times.  SSI on a few channels with noise and neighbouring modes comes out above it.

    Examples
    --------
    >>> round(float(damping_bound(np.array(40.0), np.array(0.01), np.array(10.0))), 3)   # 25 decays
    0.199
    """
    return 1.0 / np.sqrt(2 * np.pi * np.asarray(damping_ratio) * np.asarray(freq_hz) * np.asarray(span_s))


def damping_span_s(freq_hz: float, damping_ratio: float, rel_std: float) -> float:
    """Seconds of record for which :func:`damping_bound` equals ``rel_std``.

    Examples
    --------
    >>> round(damping_span_s(40.0, 0.01, 0.2), 2)
    9.95
    """
    return 1.0 / (rel_std**2 * 2 * np.pi * damping_ratio * freq_hz)


def modal_map(windows: Sequence[WindowPoles], tracks: Sequence[Track], outputs: Sequence[str],
              bin_deg: float, source: str = "track") -> ModalTable:
    """The modal map (module docstring) as a modal table whose configurations are pose bins."""
    names = list(windows[0].pose) if windows else []
    rows = []
    bins: dict[tuple[int, ...], list[tuple[int, int]]] = {}
    for m, t in enumerate(tracks):
        for i, k in enumerate(t.windows):
            index = [windows[k].pose[v] / bin_deg + 0.5 for v in names]
            if not np.isfinite(index).all():
                raise ModalError(f"pose bin (--bin) of {bin_deg:g} deg is too narrow to count poses up to "
                                 f"{max(abs(windows[k].pose[v]) for v in names):g} deg")
            bins.setdefault(tuple(int(np.floor(x)) for x in index), []).append((m, i))
    names_of = {key: ",".join(f"{v}={b * bin_deg:g}" for v, b in zip(names, key, strict=True))
                for key in bins}
    if len(set(names_of.values())) < len(names_of):
        raise ModalError(f"pose bin (--bin) of {bin_deg:g} deg is too narrow: bins of the modal map would "
                         "share their names (6 significant digits); give a wider bin")
    for key in sorted(bins):
        members = bins[key]
        config = names_of[key]
        for m in sorted({m for m, _ in members}):
            t = tracks[m]
            sel = np.array([i for mm, i in members if mm == m])
            f, z = t.freq_hz[sel], t.damping_ratio[sel]
            n = sel.size
            shape = t.shapes[:, sel]
            ref = shape[:, int(np.argmax(np.abs(shape).max(axis=0)))]
            signs = np.where(ref @ shape < 0, -1.0, 1.0)
            mean_shape = (shape * signs).mean(axis=1)
            mean_shape = mean_shape / np.max(np.abs(mean_shape))
            pose = {POSE_PREFIX + v: float(np.mean([windows[t.windows[i]].pose[v] for i in sel]))
                    for v in names}
            z_std = float(z.std(ddof=1) / np.sqrt(n)) if n > 1 else np.nan
            span = {}
            if t.span_s.size:   # refined: the closed-form bound of the data behind the estimates
                z_std = max(np.nan_to_num(z_std), float(np.mean(z * damping_bound(f, z, t.span_s[sel]))))
                span = {"damping_span_s": float(t.span_s[sel].mean())}
            rows.append({"config": config, "mode": m + 1, "freq_hz": float(f.mean()),
                         "damping_ratio": float(z.mean()), "source": source,
                         "freq_std_hz": float(f.std(ddof=1) / np.sqrt(n)) if n > 1 else np.nan,
                         "damping_std": z_std, "n_windows": n, **span, **pose,
                         **{SHAPE_PREFIX + o: float(v) for o, v in zip(outputs, mean_shape, strict=True)}})
    if not rows:
        raise ModalError("tracking: no mode was followed over enough windows to map")
    return ModalTable.from_records(rows, "track")


def _lowest_mode_hz(y: np.ndarray, sample_rate_hz: float, options: TrackOptions) -> float | None:
    """The median over ``LOOK_STRETCHES`` stretches of ``LOOK_S`` seconds spread over the record of the
    lowest SSI mode of each (a mode whose frequency moves is sharp over a short stretch, smeared over
    the whole record), or None when SSI finds none.  SSI's time lags are sized for the lowest mode a
    stretch can hold ``LOOK_PERIODS`` periods of (``lowest_hz`` of
    :func:`flexmodal.modal.ssi.default_block_rows`): sized for the model order alone they span a few
    milliseconds, and a weak mode whose period is longer (the wrist arm's 18-25 Hz first mode beside
    its 67-83 Hz second) is not found.  A stretch where those lags find nothing (lost samples leave too
    few lag products) is looked at again with the model order's lags."""
    n = min(y.shape[0], int(LOOK_S * sample_rate_hz))
    found = []
    for a in np.unique(np.linspace(0, y.shape[0] - n, LOOK_STRETCHES).astype(int)):   # a loop over stretches
        for low in (LOOK_PERIODS * sample_rate_hz / n, None):   # long lags, else (gaps) the order's
            try:   # SSI leaves lost samples (NaN rows) out of its covariances, up to half of the stretch
                modes = ssi_cov(y[a:a + n], sample_rate_hz, references=_references(y), fmax=options.fmax,
                                max_order=options.max_order, lowest_hz=low).modes
            except ModalError:
                continue
            if modes.freq_hz.size:
                found.append(float(modes.freq_hz.min()))
                break
    return float(np.median(found)) if found else None


def track_modes(samples: np.ndarray, sample_rate_hz: float, names: Sequence[str], kinds: Sequence[str],
                pose_from: Mapping[str, str], options: TrackOptions = TrackOptions(),
                where: str = "record") -> TrackResult:
    """Track the modes of a record of a moving arm [n_samples, n_channels] (module docstring).

    ``pose_from``: pose variable -> encoder channel name (degrees).  Returns a :class:`TrackResult`.
    """
    from flexmodal.modal.oma import output_channels

    samples = np.asarray(samples, float)
    missing = [c for c in pose_from.values() if c not in names]
    if missing:
        raise ModalError(f"{where}: pose channel {missing[0]!r} is not a channel of the record")
    if not pose_from:
        raise ModalError(f"{where}: no encoder channel gives the pose (name one: pose variable = channel)")
    outputs = output_channels(kinds)
    if not outputs:
        raise ModalError(f"{where}: no response channel to track")
    y = samples[:, outputs]
    pose = samples[:, [list(names).index(c) for c in pose_from.values()]]
    if np.isinf(y).any() or np.isinf(pose).any():
        raise ModalError(f"{where}: the record holds infinite samples")
    lowest = options.fmin or _lowest_mode_hz(y, sample_rate_hz, options)
    if lowest is None:
        raise ModalError(f"{where}: no mode found to size the windows; give --fmin or a window length")
    names_pose = list(pose_from)
    starts, skipped, gapped, n_win, n_hop, refs = window_starts(y, pose, sample_rate_hz, options, lowest)
    if not starts:
        raise ModalError(f"{where}: no window to analyse: {skipped} with a pose spread above "
                         f"{options.max_spread_deg:g} deg, {gapped} holding lost samples; use a shorter "
                         "window or a larger spread")
    orders = joint_orders(y, pose, names_pose, sample_rate_hz, starts, n_win, options)
    y = remove_orders(y, sample_rate_hz, pose, [orders[v] for v in names_pose])
    windows = identify_windows(y, pose, names_pose, sample_rate_hz, options, lowest, starts, n_win, refs)
    windows, harmonics = mark_harmonics(windows, orders, options)
    tracks = follow(windows, options)
    sines = [t for t in tracks if np.median(t.kurtosis) < options.kurtosis_max]
    tracks = [t for t in tracks if np.median(t.kurtosis) >= options.kurtosis_max]
    harmonics += [Harmonic(windows[k].t_s, float(f), "", 0.0) for t in sines
                  for k, f in zip(t.windows, t.freq_hz, strict=True)]
    for p in range(options.refine):   # each pass warps along the previous pass's frequencies
        tracks = refine(y, sample_rate_hz, windows, tracks, n_win, orders, options, p == options.refine - 1)
        tracks = drop_duplicates(tracks, options)
    out_names = tuple(names[j] for j in outputs)
    table = modal_map(windows, tracks, out_names, options.bin_deg)
    hold = "it holds" if gapped == 1 else "they hold"
    warnings = ((f"{counted(skipped, 'window')} skipped: pose spread above {options.max_spread_deg:g} deg",)
                if skipped else ()) + ((f"{counted(gapped, 'window')} skipped: {hold} lost samples (gaps)",)
                                       if gapped else ())
    return TrackResult(n_win / sample_rate_hz, n_hop / sample_rate_hz, tuple(windows), skipped, tuple(tracks),
                       tuple(harmonics), orders, table, out_names, warnings, gapped)


def default_pose_from(names: Sequence[str], kinds: Sequence[str], pose: Mapping[str, float],
                      where: str) -> dict[str, str]:
    """The pose channels of a record when none are named: its one encoder channel for its one pose
    variable (``pose`` as the run stores it; ``theta_deg`` when it stores none)."""
    encoders = [n for n, k in zip(names, kinds, strict=True) if k == "encoder"]
    variables = list(pose) or ["theta_deg"]
    if len(encoders) == 1 and len(variables) == 1:
        return {variables[0]: encoders[0]}
    what = "pose variable" if len(variables) == 1 else "pose variables"
    raise ModalError(f"{where}: {counted(len(encoders), 'encoder channel')} for {what} "
                     f"{', '.join(variables)}: name them with --pose-from VAR=CHANNEL,...")


def track_input(path: str, *, pose_from: Mapping[str, str] | None = None, run_id: str | None = None,
                options: TrackOptions = TrackOptions()) -> TrackResult:
    """Track the modes of an HDF5 run (the file's only run, or ``run_id``) or of UFF dataset 58 time
    histories; ``pose_from`` maps pose variables to encoder channels (degrees; default
    :func:`default_pose_from`).  Channels named there are the pose, never outputs."""
    from pathlib import Path

    import h5py

    p = Path(path)
    if not p.is_file():
        raise ModalError(f"{p}: input not found")
    if h5py.is_hdf5(p):
        from flexmodal.modal.sources import hdf5_runs

        runs = list(hdf5_runs(p, run_id))
        if len(runs) > 1:
            raise ModalError(f"{p}: holds {len(runs)} runs; choose one with --run "
                             f"({', '.join(r.run_id for r in runs)})")
        run = runs[0]
        samples, fs, channels = run.samples, run.sample_rate_hz, run.channels
        names, kinds = [c.name for c in run.channels], [c.kind for c in run.channels]
        where, pose = f"{p}:{run.run_id}", dict(run.pose)
    else:
        from flexmodal.modal.sources import uff_without_run
        from flexmodal.modal.uff import UffFrfs, read_uff

        uff_without_run(p, run_id)
        data = read_uff(p)
        if isinstance(data, UffFrfs):
            raise ModalError(f"{p}: holds FRFs; tracking needs time histories (dataset 58, type 1)")
        samples, fs, names, kinds = data.samples, data.sample_rate_hz, list(data.names), list(data.kinds)
        where, pose, channels = str(p), {}, None
    if pose_from is None:
        pose_from = default_pose_from(names, kinds, pose, where)
    unknown = [v for v in pose_from if pose and v not in pose]
    if unknown:   # the map's pose column would name a variable the run (and the rig's poses) lack
        raise ModalError(f"{where}: --pose-from {unknown[0]}: not a pose variable of the run (its pose "
                         f"variables: {', '.join(pose)})")
    kinds = ["encoder" if n in pose_from.values() else k for n, k in zip(names, kinds, strict=True)]
    if channels is not None:   # responses stored in different units: in m/s^2, as identify takes them
        from flexmodal.modal.oma import output_channels
        from flexmodal.modal.sources import si_samples

        samples = si_samples(samples, channels, output_channels(kinds), where)
    return track_modes(samples, fs, names, kinds, pose_from, options, where)


def write_harmonics_csv(path: str, harmonics: Sequence[Harmonic]) -> None:
    """The harmonic poles, one row each: ``t_s``, ``freq_hz``, ``joint`` (pose variable, empty when found
    by its sinusoid statistics), ``order`` (per joint revolution, 0 when not an order)."""
    import pandas as pd

    from flexmodal.checked_io.output import atomic_path

    frame = pd.DataFrame([{"t_s": h.t_s, "freq_hz": h.freq_hz, "joint": h.joint, "order": h.order}
                          for h in harmonics], columns=["t_s", "freq_hz", "joint", "order"])
    with atomic_path(path) as tmp:
        frame.to_csv(tmp, index=False, float_format="%.9g")
