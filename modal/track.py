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
harmonic: it is reported with its order, never as a mode, and never joins a mode's track.

Tracking.  Modes are followed window by window by a Hungarian assignment between the open tracks and
the window's poles with the cost ``|f - f_pred| / (gate_rel f) + (1 - MAC) / (1 - mac_min)`` (the
predicted frequency extrapolates the track's last two estimates, so modes whose frequencies cross are
told apart by their shapes and slopes); a pair outside either gate is no match.  A track with no match
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

from flexmodal.contract.mac import mac
from flexmodal.contract.table import POSE_PREFIX, SHAPE_PREFIX, ModalTable
from flexmodal.modal.errors import ModalError
from flexmodal.modal.harmonics import find_orders, is_order, sinusoid_kurtosis
from flexmodal.modal.ssi import ssi_cov

MIN_WINDOW_SAMPLES = 64    # a tracking window shorter than this holds no covariance to fit
MAX_REFS = 4               # SSI reference channels per window (the ones with the largest RMS)
LOOK_S = 4.0              # the slowest mode is looked for in stretches this long ...
LOOK_STRETCHES = 6        # ... this many, spread over the record
STITCH_GAP = 40           # windows: a later track may continue an earlier one after this many
SMOOTH_WINDOWS = 5        # the refinement's frequency track: a running median over this many estimates,
SMOOTH_SPAN = 15          # then a quadratic Savitzky-Golay fit over this many
REFINE_PERIODS = 150.0    # the refinement's window holds this many periods (at least the first pass's)
REFINE_BAND = 0.4         # the refinement looks within +-40 % of the track's frequency ...
REFINE_ORDER = 30         # ... with SSI model orders up to this, and block rows spanning lags of
REFINE_LAG_PERIODS = 4.0  # this many periods (as many as the window holds, 40 samples per row)
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
    """One mode followed along the record: window indices, frequencies, damping ratios, shapes."""

    windows: np.ndarray
    freq_hz: np.ndarray
    damping_ratio: np.ndarray
    shapes: np.ndarray   # [n_out, n_windows]
    kurtosis: np.ndarray


@dataclass(frozen=True)
class TrackResult:
    """What tracking found: the window length and hop [s], the analysed ``windows``, the number
    ``skipped`` for their pose spread, the mode ``tracks`` (numbered by median frequency), the
    ``harmonics`` (every harmonic pole) and their ``orders`` per joint, the modal ``table`` (the map)
    and the output channel names."""

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


def window_plan(n_samples: int, sample_rate_hz: float, pose: np.ndarray, lowest_hz: float,
                options: TrackOptions) -> tuple[int, int]:
    """Window length and hop in samples (module docstring) for a record whose pose channels are
    ``pose`` [n, n_vars] (degrees) and slowest mode ``lowest_hz``."""
    fs = sample_rate_hz
    win = options.window_s or options.periods / lowest_hz
    if options.hop_s:
        hop = options.hop_s
    else:
        step = max(int(fs * 0.1), 1)
        rate = np.abs(np.diff(pose[::step], axis=0)).max(axis=1) * fs / step if pose.shape[1] else np.zeros(1)
        fast = float(np.percentile(rate, 90)) if rate.size else 0.0
        hop = 0.25 * options.bin_deg / fast if fast > 0 else 0.5 * win
        hop = float(np.clip(hop, win / 8, win / 2))
    n_win, n_hop = int(round(win * fs)), max(1, int(round(hop * fs)))
    if n_win > n_samples:
        raise ModalError(f"tracking window of {win:.3g} s is longer than the record "
                         f"({n_samples / fs:.3g} s); give a shorter window")
    if n_win < MIN_WINDOW_SAMPLES:
        raise ModalError(f"tracking window of {win:.3g} s holds {n_win} samples at {fs:g} Hz; give at least "
                         f"{MIN_WINDOW_SAMPLES / fs:.3g} s ({MIN_WINDOW_SAMPLES} samples)")
    return n_win, n_hop


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


def identify_windows(y: np.ndarray, pose: np.ndarray, pose_names: Sequence[str], sample_rate_hz: float,
                     options: TrackOptions, lowest_hz: float) -> tuple[list[WindowPoles], int, int, int]:
    """SSI-cov in every window of the outputs ``y`` [n, n_out] whose pose spread is small enough;
    returns the windows, the number skipped, the window length and hop (samples)."""
    fs = sample_rate_hz
    n_win, n_hop = window_plan(y.shape[0], fs, pose, lowest_hz, options)
    refs = _references(y)
    out, skipped = [], 0
    for a in range(0, y.shape[0] - n_win + 1, n_hop):   # a loop over windows
        p = pose[a:a + n_win]
        spread = p.std(axis=0)
        if np.any(spread > options.max_spread_deg):
            skipped += 1
            continue
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
                               dict(zip(pose_names, spread.tolist(), strict=True)),
                               dict(zip(pose_names, _slope(p, fs).tolist(), strict=True)),
                               f, z, sh, kurt, np.zeros(f.size)))
    return out, skipped, n_win, n_hop


def mark_harmonics(windows: list[WindowPoles], y: np.ndarray, pose: np.ndarray, sample_rate_hz: float,
                   n_win: int, options: TrackOptions
                   ) -> tuple[list[WindowPoles], list[Harmonic], dict[str, tuple[float, ...]]]:
    """Flag each window's harmonic poles (module docstring) and list them; the orders per joint."""
    orders: dict[str, tuple[float, ...]] = {}
    joints = list(windows[0].rate_deg_per_s) if windows else []
    band = (options.fmin or 0.0, options.fmax or sample_rate_hz / 2)
    for j, v in enumerate(joints):   # a loop over pose variables
        if options.orders:
            orders[v] = tuple(options.orders)
            continue
        starts = [int(round(w.t_s * sample_rate_hz)) - n_win // 2 for w in windows]
        pieces = [(y[a:a + n_win], pose[a:a + n_win, j]) for a in starts]
        speed = np.array([abs(w.rate_deg_per_s[v]) / 360.0 for w in windows])
        orders[v] = find_orders(pieces, sample_rate_hz, speed, band, options.order_tol)
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
    return marked, found, orders


def follow(windows: Sequence[WindowPoles], options: TrackOptions) -> list[Track]:
    """Follow the non-harmonic poles from window to window (module docstring)."""
    open_: list[dict] = []
    done: list[dict] = []
    for k, w in enumerate(windows):   # a loop over windows
        idx = np.flatnonzero(w.harmonic == 0)
        f, sh = w.freq_hz[idx], w.shapes[:, idx]
        if open_ and idx.size:
            pred = np.array([_predict(t, k) for t in open_])
            last = np.column_stack([t["shapes"][-1] for t in open_])
            mac_ = mac(last, sh)
            df = np.abs(f[None, :] - pred[:, None]) / (options.gate_rel * pred[:, None])
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
                open_.append({"windows": [k], "freq": [w.freq_hz[j]], "zeta": [w.damping_ratio[j]],
                              "shapes": [w.shapes[:, j]], "kurt": [w.kurtosis[j]]})
    done += open_
    tracks = [Track(np.array(t["windows"]), np.array(t["freq"]), np.array(t["zeta"]),
                    np.column_stack(t["shapes"]), np.array(t["kurt"]))
              for t in sorted(done, key=lambda t: t["windows"][0])]
    tracks = _stitch(tracks, options)
    return sorted([t for t in tracks if t.windows.size >= options.min_windows],
                  key=lambda t: float(np.median(t.freq_hz)))


def _stitch(tracks: list[Track], options: TrackOptions) -> list[Track]:
    """Join a track to an earlier one that ended at most ``STITCH_GAP`` windows before it began when the
    earlier one's last estimates, extrapolated linearly over the gap, and the later one's first agree
    within the gates (frequency, widened in proportion to the gap beyond ``max_gap``, and MAC): one mode
    whose poles were missed for a while, or set aside as a harmonic where one crossed it."""
    out: list[Track] = []
    for t in tracks:   # a loop over tracks, in order of their first window
        best, best_cost = -1, 1.0
        for i, u in enumerate(out):
            if u.windows[-1] >= t.windows[0] or t.windows[0] - u.windows[-1] > STITCH_GAP:
                continue
            gap = int(t.windows[0] - u.windows[-1])
            n = min(5, u.freq_hz.size)
            slope = np.polyfit(u.windows[-n:], u.freq_hz[-n:], 1)[0] if n >= 2 else 0.0
            pred = u.freq_hz[-1] + slope * gap
            df = abs(t.freq_hz[0] - pred) / (options.gate_rel * max(1.0, gap / options.max_gap) * pred)
            dm = (1 - float(mac(u.shapes[:, -1:], t.shapes[:, :1])[0, 0])) / (1 - options.mac_min)
            if df <= 1 and dm <= 1 and df + dm < best_cost:
                best, best_cost = i, df + dm
        if best < 0:
            out.append(t)
            continue
        u = out[best]
        out[best] = Track(np.concatenate([u.windows, t.windows]), np.concatenate([u.freq_hz, t.freq_hz]),
                          np.concatenate([u.damping_ratio, t.damping_ratio]), np.hstack([u.shapes, t.shapes]),
                          np.concatenate([u.kurtosis, t.kurtosis]))
    return out


def _predict(track: dict, k: int) -> float:
    """The track's frequency extrapolated to window ``k`` from its last two estimates."""
    f, w = track["freq"], track["windows"]
    if len(f) < 2:
        return float(f[-1])
    slope = (f[-1] - f[-2]) / (w[-1] - w[-2])
    return float(f[-1] + slope * (k - w[-1]))


def refine(y: np.ndarray, sample_rate_hz: float, windows: Sequence[WindowPoles], tracks: Sequence[Track],
           n_win: int, orders: Mapping[str, tuple[float, ...]], options: TrackOptions) -> list[Track]:
    """Second pass: each mode re-identified at every window centre of its span, over the first pass's
    window or ``REFINE_PERIODS`` periods if longer (warping keeps the drift out), in its own warped time
    (:func:`flexmodal.modal.warp.warp` along the track's frequencies, median-smoothed over
    ``SMOOTH_WINDOWS`` and interpolated in time), decimated to at least four times ``f_c (1 +
    REFINE_BAND)``, by SSI-cov in ``f_c (1 +- REFINE_BAND)`` with block rows over ``REFINE_LAG_PERIODS``;
    the selected mode nearest ``f_c`` within the gates (frequency and MAC with the track's nearest
    first-pass shape) replaces the first pass's estimate, and fills the windows the first pass
    missed.  A pole on a harmonic order (within ``order_tol``) is left out.  Tracks keep their order."""
    import scipy.ndimage
    import scipy.signal

    from flexmodal.modal.warp import warp

    fs = sample_rate_hz
    centres = np.array([w.t_s for w in windows])
    refs = _references(y)
    out = []
    for tr in tracks:   # a loop over modes
        f_s = scipy.ndimage.median_filter(tr.freq_hz, min(SMOOTH_WINDOWS, tr.freq_hz.size), mode="nearest")
        if f_s.size > SMOOTH_SPAN:
            f_s = scipy.signal.savgol_filter(f_s, SMOOTH_SPAN, 2)
        keep: list[tuple[int, float, float, np.ndarray]] = []
        for k in range(int(tr.windows[0]), int(tr.windows[-1]) + 1):   # a loop over windows
            mid = int(round(centres[k] * fs))
            f_c = float(np.interp(centres[k], centres[tr.windows], f_s))
            n = min(y.shape[0], max(n_win, int(REFINE_PERIODS / f_c * fs)))
            a = int(np.clip(mid - n // 2, 0, y.shape[0] - n))
            g = np.interp(np.arange(a, a + n) / fs, centres[tr.windows], f_s)
            q = max(1, int(fs // (4 * (1 + REFINE_BAND) * f_c)))   # decimated to >= 4 x the band's top
            seg = warp(y[a:a + n], fs, g, mid - a)
            seg = scipy.signal.resample_poly(seg, 1, q, axis=0) if q > 1 else seg
            rows = min(seg.shape[0] // 40, max(-(-REFINE_ORDER // len(refs)) + 2,
                                               int(np.ceil(REFINE_LAG_PERIODS * fs / q / f_c))))
            try:
                m = ssi_cov(seg, fs / q, references=refs, fmin=(1 - REFINE_BAND) * f_c,
                            fmax=(1 + REFINE_BAND) * f_c, max_order=REFINE_ORDER, block_rows=rows).modes
            except ModalError:
                continue
            shape = tr.shapes[:, int(np.argmin(np.abs(tr.windows - k)))]   # the nearest first-pass shape
            near = np.abs(m.freq_hz / f_c - 1) / options.gate_rel + (1 - mac(shape[:, None], m.shapes)[0]) / (
                1 - options.mac_min)
            j = int(np.argmin(near))
            on_order = any(is_order(m.freq_hz[j:j + 1], abs(windows[k].rate_deg_per_s[v]) / 360.0, o,
                                    options.order_tol)[0] for v, o in orders.items())
            if near[j] <= 1 and not on_order:
                keep.append((k, float(m.freq_hz[j]), float(m.damping_ratio[j]), m.shapes[:, j]))
        if len(keep) < options.min_windows:
            out.append(tr)
            continue
        idx = np.array([k for k, _, _, _ in keep])
        kurt = np.interp(idx, tr.windows, tr.kurtosis)
        out.append(Track(idx, np.array([f for _, f, _, _ in keep]), np.array([z for _, _, z, _ in keep]),
                         np.column_stack([sh for _, _, _, sh in keep]), kurt))
    return out


def modal_map(windows: Sequence[WindowPoles], tracks: Sequence[Track], outputs: Sequence[str],
              bin_deg: float, source: str = "track") -> ModalTable:
    """The modal map (module docstring) as a modal table whose configurations are pose bins."""
    names = list(windows[0].pose) if windows else []
    rows = []
    bins: dict[tuple[int, ...], list[tuple[int, int]]] = {}
    for m, t in enumerate(tracks):
        for i, k in enumerate(t.windows):
            key = tuple(int(np.floor(windows[k].pose[v] / bin_deg + 0.5)) for v in names)
            bins.setdefault(key, []).append((m, i))
    for key in sorted(bins):
        members = bins[key]
        config = ",".join(f"{v}={b * bin_deg:g}" for v, b in zip(names, key, strict=True))
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
            rows.append({"config": config, "mode": m + 1, "freq_hz": float(f.mean()),
                         "damping_ratio": float(z.mean()), "source": source,
                         "freq_std_hz": float(f.std(ddof=1) / np.sqrt(n)) if n > 1 else np.nan,
                         "damping_std": float(z.std(ddof=1) / np.sqrt(n)) if n > 1 else np.nan,
                         "n_windows": n, **pose,
                         **{SHAPE_PREFIX + o: float(v) for o, v in zip(outputs, mean_shape, strict=True)}})
    if not rows:
        raise ModalError("tracking: no mode was followed over enough windows to map")
    return ModalTable.from_records(rows, "track")


def _lowest_mode_hz(y: np.ndarray, sample_rate_hz: float, options: TrackOptions) -> float | None:
    """The median over ``LOOK_STRETCHES`` stretches of ``LOOK_S`` seconds spread over the record of the
    lowest SSI mode of each (a mode whose frequency moves is sharp over a short stretch, smeared over
    the whole record), or None when SSI finds none."""
    n = min(y.shape[0], int(LOOK_S * sample_rate_hz))
    found = []
    for a in np.unique(np.linspace(0, y.shape[0] - n, LOOK_STRETCHES).astype(int)):   # a loop over stretches
        try:
            modes = ssi_cov(y[a:a + n], sample_rate_hz, references=_references(y), fmax=options.fmax,
                            max_order=options.max_order).modes
        except ModalError:
            continue
        found.append(float(modes.freq_hz.min()))
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
    if not np.isfinite(y).all() or not np.isfinite(pose).all():
        raise ModalError(f"{where}: the record holds NaN or infinite samples (gaps); tracking needs a "
                         "record without gaps")
    lowest = options.fmin or _lowest_mode_hz(y, sample_rate_hz, options)
    if lowest is None:
        raise ModalError(f"{where}: no mode found to size the windows; give --fmin or a window length")
    windows, skipped, n_win, n_hop = identify_windows(y, pose, list(pose_from), sample_rate_hz, options,
                                                      lowest)
    if not windows:
        raise ModalError(f"{where}: every window's pose spread exceeds {options.max_spread_deg:g} deg "
                         f"({skipped} skipped); use a shorter window or a larger spread")
    windows, harmonics, orders = mark_harmonics(windows, y, pose, sample_rate_hz, n_win, options)
    tracks = follow(windows, options)
    sines = [t for t in tracks if np.median(t.kurtosis) < options.kurtosis_max]
    tracks = [t for t in tracks if np.median(t.kurtosis) >= options.kurtosis_max]
    harmonics += [Harmonic(windows[k].t_s, float(f), "", 0.0) for t in sines
                  for k, f in zip(t.windows, t.freq_hz, strict=True)]
    for _ in range(options.refine):   # each pass warps along the previous pass's frequencies
        tracks = refine(y, sample_rate_hz, windows, tracks, n_win, orders, options)
    out_names = tuple(names[j] for j in outputs)
    table = modal_map(windows, tracks, out_names, options.bin_deg)
    warnings = ((f"{skipped} window(s) skipped: pose spread above {options.max_spread_deg:g} deg",)
                if skipped else ())
    return TrackResult(n_win / sample_rate_hz, n_hop / sample_rate_hz, tuple(windows), skipped, tuple(tracks),
                       tuple(harmonics), orders, table, out_names, warnings)


def default_pose_from(names: Sequence[str], kinds: Sequence[str], pose: Mapping[str, float],
                      where: str) -> dict[str, str]:
    """The pose channels of a record when none are named: its one encoder channel for its one pose
    variable (``pose`` as the run stores it; ``theta_deg`` when it stores none)."""
    encoders = [n for n, k in zip(names, kinds, strict=True) if k == "encoder"]
    variables = list(pose) or ["theta_deg"]
    if len(encoders) == 1 and len(variables) == 1:
        return {variables[0]: encoders[0]}
    raise ModalError(f"{where}: {len(encoders)} encoder channel(s) for pose variable(s) "
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
        samples, fs = run.samples, run.sample_rate_hz
        names, kinds = [c.name for c in run.channels], [c.kind for c in run.channels]
        where, pose = f"{p}:{run.run_id}", dict(run.pose)
    else:
        from flexmodal.modal.uff import UffFrfs, read_uff

        data = read_uff(p)
        if isinstance(data, UffFrfs):
            raise ModalError(f"{p}: holds FRFs; tracking needs time histories (dataset 58, type 1)")
        samples, fs, names, kinds = data.samples, data.sample_rate_hz, list(data.names), list(data.kinds)
        where, pose = str(p), {}
    if pose_from is None:
        pose_from = default_pose_from(names, kinds, pose, where)
    kinds = ["encoder" if n in pose_from.values() else k for n, k in zip(names, kinds, strict=True)]
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
