"""The modal map: modes tracked across poses (MAC and frequency continuity, veering handled).

A *branch* is one physical mode followed from pose to pose.  Ordering modes by frequency at each pose
mislabels them where two modes approach: at a *veering* the frequencies repel and the shapes exchange,
at a *crossing* (modes that do not couple) the frequencies pass through each other.  Tracking follows
the shape when shapes are measured and the frequency trend otherwise (Allemang 2003 for MAC; mode
tracking by MAC/frequency assignment as in continuation studies of parameter-dependent modes, e.g.
Vidoli & Vestroni 2005, Kerschen et al. 2009).

Functions (signatures are stable; ``track`` of issue 27 reuses them):

``track_modes(pose, freq_hz, shapes=None, freq_std_hz=None, max_cost=MAX_COST) -> ModalMap``
    Low level.  ``pose`` [P] the pose value of each observation (any order; repeats allowed);
    ``freq_hz`` a sequence of P arrays of the modes at each observation (any count, ascending or not);
    ``shapes`` a sequence of P arrays [n_sensors, n_modes] (complex or real; None: no shapes);
    ``freq_std_hz`` a sequence of P arrays of 1-sigma frequency uncertainties [Hz] (None: unknown).
    Observations at the same pose value are repeats: their modes are merged by order (mean frequency,
    standard error from the repeats' spread when there are >= 2, else the given ``freq_std_hz``).
    Consecutive poses are linked by an optimal assignment (Hungarian, scipy ``linear_sum_assignment``)
    on the cost ``(1 - MAC) + |ln(f / f_pred)| / FREQ_LOG_WIDTH`` where ``f_pred`` extrapolates the
    branch linearly from its last two poses; a pair whose cost exceeds ``max_cost`` is not linked and
    the mode starts a new branch.

``modal_map(table, pose_var=None) -> ModalMap``
    The same from a ModalTable (docs/formats.md): one observation per configuration, ``pose.<pose_var>``
    (default: the table's only pose column), shapes from its ``shape.*`` columns, ``freq_std_hz`` when
    the column is present.

``ModalMap``: ``pose`` [Q] distinct pose values ascending, ``freq_hz``/``freq_std_hz`` [Q, B] per branch
(NaN where the branch was not seen), ``mode_number`` [Q, B] the branch's rank by frequency at that pose
(1-based, 0 where not seen), ``mac_link`` [Q, B] MAC with the branch's previous pose (NaN at its first
pose, without shapes, or where either shape is all zero: its MAC is undefined, contract.mac; the link
cost counts it as unlike), ``n_repeats`` [Q], ``events`` the order swaps ``(q_index, branch_a, branch_b)``:
branches a and b exchange frequency order between ``pose[q_index - 1]`` and ``pose[q_index]`` (with
shapes a veering or crossing resolved by the shape; without shapes a crossing extrapolated from the
trend).  ``to_frame()`` is the long table (pose, branch, mode_number, freq_hz, freq_std_hz, mac_link).

``PredictionBand``: a model's frequencies at poses [Q] (``freq_hz`` [Q, n]) with a 95 % interval
``lower_hz``/``upper_hz`` (the diagnosis' ``prediction_band`` fills it; the figure
reports/modal_map_plot.py draws it under the tracked points).

Examples
--------
>>> import numpy as np
>>> q = np.array([0.0, 1.0, 2.0, 3.0])
>>> up, down = 10 + 2 * q, 16 - 2 * q        # two modes crossing between q = 1 and q = 2
>>> m = track_modes(q, [np.sort([a, b]) for a, b in zip(up, down)])
>>> m.freq_hz[:, 0].round(1).tolist()
[10.0, 12.0, 14.0, 16.0]
>>> m.events
((2, 0, 1),)
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from scipy.optimize import linear_sum_assignment

from flexmodal.compare.errors import CompareError
from flexmodal.contract.mac import mac
from flexmodal.contract.table import ModalTable

FREQ_LOG_WIDTH = 0.25
"""A 25 % (log) jump from the extrapolated frequency costs as much as a shape that does not correlate."""
MAX_COST = 2.0
"""Links costlier than this start a new branch (e.g. MAC 0.2 and a 30 % jump, or a 65 % jump alone)."""
REPEAT_TOL = 1e-9
"""Pose values closer than this are the same pose (repeats)."""


@dataclass(frozen=True)
class ModalMap:
    """Modes tracked across poses (module docstring)."""

    pose: np.ndarray             # [Q] distinct pose values, ascending
    freq_hz: np.ndarray          # [Q, B]
    freq_std_hz: np.ndarray      # [Q, B] 1-sigma uncertainty of freq_hz (NaN: unknown)
    mode_number: np.ndarray      # [Q, B] int, rank by frequency at that pose (0: not seen)
    mac_link: np.ndarray         # [Q, B]
    n_repeats: np.ndarray        # [Q] int
    events: tuple[tuple[int, int, int], ...]

    @property
    def n_branches(self) -> int:
        return int(self.freq_hz.shape[1])

    def to_frame(self):
        """Long table: one row per (pose, branch) seen, columns pose, branch (from 1), mode_number,
        freq_hz, freq_std_hz, mac_link, n_repeats."""
        import pandas as pd

        q, b = np.nonzero(self.mode_number > 0)
        return pd.DataFrame({"pose": self.pose[q], "branch": b + 1, "mode_number": self.mode_number[q, b],
                             "freq_hz": self.freq_hz[q, b], "freq_std_hz": self.freq_std_hz[q, b],
                             "mac_link": self.mac_link[q, b], "n_repeats": self.n_repeats[q]})


@dataclass(frozen=True)
class PredictionBand:
    """A model's frequencies [Hz] at poses ``pose`` [Q] with a 95 % interval, modes ``1..n`` by order."""

    pose: np.ndarray             # [Q]
    freq_hz: np.ndarray          # [Q, n]
    lower_hz: np.ndarray         # [Q, n]
    upper_hz: np.ndarray         # [Q, n]
    label: str = "model"


def _merge_repeats(freqs: list[np.ndarray], shapes: list[np.ndarray] | None, stds: list[np.ndarray] | None
                   ) -> tuple[np.ndarray, np.ndarray | None, np.ndarray]:
    """Repeats of one pose merged by mode order: mean frequency, mean shape (signs aligned with the
    first repeat), standard error (repeats' spread / sqrt(k) when k >= 2, else the given std)."""
    n = min(len(f) for f in freqs)
    F = np.array([np.sort(f)[:n] if shapes is None else f[:n] for f in freqs])
    mean = F.mean(axis=0)
    if len(freqs) >= 2:
        std = F.std(axis=0, ddof=1) / math.sqrt(len(freqs))
    elif stds is not None:
        std = np.asarray(stds[0], float)[:n]
    else:
        std = np.full(n, np.nan)
    if shapes is None:
        return mean, None, std
    ref = np.asarray(shapes[0])[:, :n]
    acc = np.zeros_like(ref, dtype=complex if np.iscomplexobj(ref) else float)
    for s in shapes:
        s = np.asarray(s)[:, :n]
        sign = np.sign(np.real(np.sum(np.conj(ref) * s, axis=0)))
        acc = acc + s * np.where(sign == 0, 1.0, sign)
    return mean, acc / len(shapes), std


def track_modes(pose: Sequence[float], freq_hz: Sequence[np.ndarray],
                shapes: Sequence[np.ndarray] | None = None,
                freq_std_hz: Sequence[np.ndarray] | None = None, max_cost: float = MAX_COST) -> ModalMap:
    """Track modes across poses (module docstring); CompareError on empty or inconsistent input."""
    pose = np.asarray(pose, float)
    if pose.ndim != 1 or len(pose) == 0 or len(freq_hz) != len(pose):
        raise CompareError(f"track_modes: {len(freq_hz)} frequency sets for {pose.size} pose values")
    if shapes is not None and len(shapes) != len(pose):
        raise CompareError(f"track_modes: {len(shapes)} shape sets for {len(pose)} pose values")
    order = np.argsort(pose, kind="stable")
    groups: list[list[int]] = []
    for i in order:
        if groups and abs(pose[i] - pose[groups[-1][0]]) <= REPEAT_TOL * max(1.0, abs(pose[i])):
            groups[-1].append(int(i))
        else:
            groups.append([int(i)])
    merged = [_merge_repeats([np.asarray(freq_hz[i], float) for i in g],
                             None if shapes is None else [np.asarray(shapes[i]) for i in g],
                             None if freq_std_hz is None else [np.asarray(freq_std_hz[i], float) for i in g])
              for g in groups]
    Q = len(groups)
    branches: list[dict[int, tuple[float, float, float, int]]] = []   # per branch: q -> (f, std, mac, k)
    last_shape: list[np.ndarray | None] = []
    for q, (f, phi, std) in enumerate(merged):
        rank = np.argsort(np.argsort(f)) + 1
        live = [b for b, br in enumerate(branches) if q - 1 in br]
        assigned: dict[int, int] = {}
        if live and len(f):
            cost = np.empty((len(live), len(f)))
            for r, b in enumerate(live):
                br = branches[b]
                f1 = br[q - 1][0]
                pred = f1
                if q - 2 in br:                           # linear extrapolation in the pose
                    p0, p1, p2 = (float(pose[groups[k][0]]) for k in (q - 2, q - 1, q))
                    pred = f1 + (f1 - br[q - 2][0]) * (p2 - p1) / max(p1 - p0, 1e-300)
                pred = max(pred, 1e-3 * f1)
                cost[r] = np.abs(np.log(f / pred)) / FREQ_LOG_WIDTH
                if phi is not None and last_shape[b] is not None:
                    cost[r] += np.nan_to_num(1.0 - mac(last_shape[b][:, None], phi)[0], nan=1.0)
            rows, cols = linear_sum_assignment(cost)
            assigned = {int(c): live[r] for r, c in zip(rows, cols, strict=True) if cost[r, c] <= max_cost}
        for k in range(len(f)):
            b = assigned.get(k)
            link = math.nan
            if b is None:
                branches.append({})
                last_shape.append(None)
                b = len(branches) - 1
            elif phi is not None and last_shape[b] is not None:
                link = float(mac(last_shape[b][:, None], phi[:, k:k + 1])[0, 0])
            branches[b][q] = (float(f[k]), float(std[k]), link, int(rank[k]))
            if phi is not None:
                last_shape[b] = phi[:, k]
    B = len(branches)
    F = np.full((Q, B), np.nan)
    S, L = F.copy(), F.copy()
    N = np.zeros((Q, B), int)
    for b, br in enumerate(branches):
        for q, (f, s, link, k) in br.items():
            F[q, b], S[q, b], L[q, b], N[q, b] = f, s, link, k
    start = sorted(range(B), key=lambda b: (min(branches[b]), F[min(branches[b]), b]))
    F, S, L, N = F[:, start], S[:, start], L[:, start], N[:, start]
    events = []
    for q in range(1, Q):
        both = (N[q - 1] > 0) & (N[q] > 0)
        idx = np.flatnonzero(both)
        for i, a in enumerate(idx):
            for b in idx[i + 1:]:
                if (F[q - 1, a] - F[q - 1, b]) * (F[q, a] - F[q, b]) < 0:
                    events.append((q, int(a), int(b)))
    return ModalMap(np.array([pose[g[0]] for g in groups]), F, S, N, L,
                    np.array([len(g) for g in groups]), tuple(events))


def modal_map(table: ModalTable, pose_var: str | None = None) -> ModalMap:
    """``track_modes`` over the configurations of a modal table (module docstring)."""
    columns = [c[len("pose."):] for c in table.pose_columns]
    if pose_var is None:
        if len(columns) != 1:
            raise CompareError(f"{table.source}: give the pose variable to map over "
                               f"(the table has {', '.join(columns) or 'no pose column'})")
        pose_var = columns[0]
    if pose_var not in columns:
        raise CompareError(f"{table.source}: no column 'pose.{pose_var}' to map over")
    configs = table.configs
    pose = [float(table.pose(c)[pose_var]) for c in configs]
    freqs = [table.freq_hz(c) for c in configs]
    shapes = None
    if table.sensors:
        shapes = [table.shapes(c) for c in configs]
        if any(np.isnan(s).any() for s in shapes):
            shapes = None
    stds = None
    if "freq_std_hz" in table.frame:
        stds = [table.rows(c)["freq_std_hz"].to_numpy(float) for c in configs]
    return track_modes(pose, freqs, shapes, stds)
