"""Pairing of measured and predicted modes, configuration by configuration.

Where both tables hold mode shapes at two or more common sensors, modes are paired by an optimal
assignment (Hungarian method, ``scipy.optimize.linear_sum_assignment``) on the cost ``1 - MAC`` plus a
small frequency term ``freq_weight * |ln(f_pred / f_meas)|`` that breaks ties between shapes the sensors
cannot tell apart; a pair whose MAC is below ``min_mac`` is rejected and both modes are listed as
unpaired.  Without usable shapes the modes are paired in ascending frequency order (1st with 1st, ...);
where both tables give shape columns, the pairing records why they could not be used (names apart, no
values, or every mode shape of one side zero: MAC undefined), and the comparison says so in its notes and
in one warning per predicted table.
The Modal Assurance Criterion (Allemang & Brown 1982) is ``contract.mac.mac``.

Configurations are matched by name; a measured configuration with no namesake is matched to the one
predicted configuration with the same pose (every ``pose.<name>`` equal within 1e-9), so modes identified
from runs named ``theta0-impact`` and ``theta0-random`` both meet the prediction for ``theta0``; the
predicted modes are then reported under the measured configuration's name.

Every mode ends up either in a pair or in one of the unpaired lists; nothing is dropped silently.
Relative errors are fractions: (f_pred - f_meas) / f_meas.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property

import numpy as np
from scipy.optimize import linear_sum_assignment

from flexmodal.contract.mac import mac
from flexmodal.contract.table import ModalTable

MIN_MAC = 0.5
FREQ_WEIGHT = 1e-3
POSE_TOL = 1e-9  # pose values equal within this match a measured configuration to a predicted one
#: why a configuration whose tables both give shape columns is paired by frequency order, not by MAC
WHY_NOT_MAC = {
    "apart": "both tables give mode shapes, but at fewer than two sensors of the same name",
    "empty": "fewer than two common sensors hold a shape value (not empty, not NaN) for every mode",
    "zero measured": "every measured mode shape is zero at the common sensors (MAC undefined)",
    "zero predicted": "every predicted mode shape is zero at the common sensors (MAC undefined)",
    # the diagnosis' only (compare leaves such a sensor out, and pairs a zero mode by frequency alone):
    # its fit pairs complete shapes by MAC
    "zero mode": "a measured mode shape is zero at every sensor that gives it (MAC undefined)",
    "incomplete": "a measured mode shape is empty or NaN at one or more sensors (the diagnosis pairs "
                  "by MAC only shapes given at every sensor)",
}


@dataclass(frozen=True)
class ModeRef:
    """One mode of one table: configuration, 1-based mode number, frequency [Hz]."""

    config: str
    mode: int
    freq_hz: float


@dataclass(frozen=True)
class Pair:
    """A measured mode and the predicted mode paired with it; ``mac`` is NaN when paired by frequency."""

    measured: ModeRef
    predicted: ModeRef
    mac: float
    method: str  # "mac" | "frequency"

    @property
    def rel_error(self) -> float:
        """(f_pred - f_meas) / f_meas, a fraction (NaN for a 0 Hz measured mode)."""
        f = self.measured.freq_hz
        return (self.predicted.freq_hz - f) / f if f > 0 else float("nan")


@dataclass(frozen=True)
class Pairing:
    """The pairing of one predicted source against the measured table."""

    source: str
    pairs: tuple[Pair, ...]
    unpaired_measured: tuple[ModeRef, ...]  # measured modes the source has no partner for
    unpaired_predicted: tuple[ModeRef, ...]  # predicted modes matching no measured one (spurious/extra)
    # configurations where both tables give shape columns but no MAC can pair them, each with the reason
    # (:data:`WHY_NOT_MAC`): paired by frequency order instead, and the notes and warnings say so
    shapes_unused: tuple[tuple[str, str], ...] = ()

    def pair_of(self, config: str, measured_mode: int) -> Pair | None:
        return self._by_measured.get((config, measured_mode))

    @cached_property
    def _by_measured(self) -> dict[tuple[str, int], Pair]:
        return {(p.measured.config, p.measured.mode): p for p in self.pairs}


def common_sensors(measured: ModalTable, predicted: ModalTable, config: str,
                   pred_config: str | None = None) -> list[str]:
    """Sensors where both tables give a finite shape for every mode of ``config`` (``pred_config``)."""
    predicted_sensors = set(predicted.sensors)
    both = [s for s in measured.sensors if s in predicted_sensors]
    if not both:
        return []
    a = np.isfinite(measured.shapes(config, both)).all(axis=1)
    b = np.isfinite(predicted.shapes(pred_config or config, both)).all(axis=1)
    return [s for s, ok in zip(both, a & b, strict=True) if ok]


def partner_config(measured: ModalTable, predicted: ModalTable, config: str,
                   poses: PoseIndex | None = None) -> str | None:
    """The predicted configuration for measured ``config``: same name, else the only one with the same
    non-empty pose (values equal within 1e-9), else None.  ``poses``: ``PoseIndex(predicted)``, built
    once when many configurations are matched."""
    if predicted.has_config(config):
        _same_pose(measured, predicted, config)
        return config
    pose = measured.pose(config)
    if not pose:
        return None
    same = (poses or PoseIndex(predicted)).find(pose)
    return same[0] if len(same) == 1 else None


def _same_pose(measured: ModalTable, predicted: ModalTable, config: str) -> None:
    """CompareError when ``config`` is predicted at another pose than it was measured at: other pose
    variables (each table naming one the other lacks; a prediction may fix more variables, such as
    a payload the measured table does not give), or a pose variable both tables give whose predicted values
    leave the measured ones' range (one value in a modal table; the windows' means of a modal map's
    pose bin).  Modes of two poses would otherwise be paired under one name, and their differences
    reported as the model's error."""
    from flexmodal.compare.errors import CompareError

    given = [sorted(t.pose(config)) for t in (measured, predicted)]
    a, b = map(set, given)
    if a and b and not (a <= b or b <= a):   # theta_deg against phi_deg was paired without a word
        raise CompareError(f"config {config!r}: measured at pose {', '.join(given[0])} ({measured.source}) "
                           f"but predicted at pose {', '.join(given[1])} ({predicted.source}): the pose "
                           "variables differ, so the poses cannot be compared (predict --poses MEASURED.csv)")
    for col in [c for c in measured.pose_columns if c in predicted.pose_columns]:
        m = measured.column(config, col).astype(float)
        p = predicted.column(config, col).astype(float)
        m, p = m[np.isfinite(m)], p[np.isfinite(p)]
        if m.size and p.size:
            tol = 1e-6 * max(1.0, float(np.abs(m).max()))   # poses written with 9 digits compare equal
            if p.min() < m.min() - tol or p.max() > m.max() + tol:
                raise CompareError(f"config {config!r}: measured at {col} = {m[0]:g} ({measured.source}) but "
                                   f"predicted at {p[0]:g} ({predicted.source}): a configuration is one pose "
                                   "(predict at the measured poses: predict --poses MEASURED.csv)")


class PoseIndex:
    """The configurations of a table by pose: those whose every pose variable equals a given pose's
    within :data:`POSE_TOL` are found by a binary search on the first variable (not a scan)."""

    def __init__(self, table: ModalTable) -> None:
        groups: dict[tuple[str, ...], list[tuple[str, list[float]]]] = {}
        for c in table.configs:
            pose = table.pose(c)
            if pose:
                names = tuple(sorted(pose))
                groups.setdefault(names, []).append((c, [float(pose[k]) for k in names]))
        self._groups: dict[tuple[str, ...], tuple[list[str], np.ndarray]] = {}
        for names, members in groups.items():
            values = np.array([v for _, v in members], float)
            order = np.argsort(values[:, 0], kind="stable")
            self._groups[names] = ([members[i][0] for i in order], values[order])

    def find(self, pose: dict) -> list[str]:
        """Configurations with the same pose variables as ``pose``, each equal within POSE_TOL."""
        names = tuple(sorted(pose))
        if names not in self._groups:
            return []
        configs, values = self._groups[names]
        want = np.array([float(pose[k]) for k in names])
        lo = int(np.searchsorted(values[:, 0], want[0] - POSE_TOL, side="left"))
        hi = int(np.searchsorted(values[:, 0], want[0] + POSE_TOL, side="right"))
        near = np.abs(values[lo:hi] - want[None, :]) <= POSE_TOL
        return [configs[lo + i] for i in np.flatnonzero(near.all(axis=1))]


def _refs(table: ModalTable, config: str, label: str | None = None) -> list[ModeRef]:
    return [ModeRef(label or config, int(m), float(f))
            for m, f in zip(table.column(config, "mode"), table.column(config, "freq_hz"), strict=True)]


def _pair_by_mac(meas: list[ModeRef], pred: list[ModeRef], macs: np.ndarray, min_mac: float,
                 freq_weight: float) -> list[Pair]:
    fm = np.array([r.freq_hz for r in meas])
    fp = np.array([r.freq_hz for r in pred])
    with np.errstate(divide="ignore", invalid="ignore"):
        spread = np.abs(np.log(np.maximum(fp[None, :], 1e-300) / np.maximum(fm[:, None], 1e-300)))
    unlike = 1.0 - np.nan_to_num(macs, nan=0.0)    # a zero shape (MAC undefined) counts as unlike
    cost = unlike + freq_weight * np.nan_to_num(spread, nan=1e3, posinf=1e3)
    rows, cols = linear_sum_assignment(cost)
    return [Pair(meas[i], pred[j], float(macs[i, j]), "mac")
            for i, j in zip(rows, cols, strict=True) if macs[i, j] >= min_mac]


def _why_not_mac(named: int, sensors: list[str], shapes: tuple[np.ndarray, np.ndarray]) -> str | None:
    """None when a configuration's modes can be paired by MAC: ``shapes`` (measured, predicted)
    [n_sensors, n_modes] finite at two or more common ``sensors``, each side with a mode that moves them
    (a zero shape has no direction; one such mode alone is left unpaired by the MAC pairing).  Else
    the key of :data:`WHY_NOT_MAC`, or "" when a table gives no shapes at all (nothing to say).
    ``named``: how many sensors both tables name, -1 when one names none."""
    if named < 0:
        return ""
    if len(sensors) < 2:
        return "apart" if named < 2 else "empty"
    for side, phi in zip(("measured", "predicted"), shapes, strict=True):
        if not np.any(phi):
            return f"zero {side}"
    return None


def _pair_by_frequency(meas: list[ModeRef], pred: list[ModeRef]) -> list[Pair]:
    ms = sorted(meas, key=lambda r: r.freq_hz)
    ps = sorted(pred, key=lambda r: r.freq_hz)
    return [Pair(a, b, float("nan"), "frequency") for a, b in zip(ms, ps, strict=False)]


def pair_modes(measured: ModalTable, predicted: ModalTable, source: str = "prediction", *,
               min_mac: float = MIN_MAC, freq_weight: float = FREQ_WEIGHT) -> Pairing:
    """Pair the modes of ``predicted`` with those of ``measured`` in every configuration.

    By MAC (optimal assignment on 1 - MAC, frequency tie-break) where both have shapes at two or more
    common sensors, otherwise by ascending frequency.  Configurations are matched by name, else by pose
    (``partner_config``); configurations present on one side only leave all their modes unpaired.
    """
    pairs: list[Pair] = []
    lone_meas: list[ModeRef] = []
    lone_pred: list[ModeRef] = []
    used_configs: set[str] = set()
    poses = PoseIndex(predicted)
    unused: list[tuple[str, str]] = []
    both_named = measured.sensors and predicted.sensors
    named = len(set(measured.sensors) & set(predicted.sensors)) if both_named else -1
    for config in measured.configs:
        meas = _refs(measured, config)
        pconfig = partner_config(measured, predicted, config, poses)
        if pconfig is None:
            lone_meas += meas
            continue
        used_configs.add(pconfig)
        pred = _refs(predicted, pconfig, label=config)
        sensors = common_sensors(measured, predicted, config, pconfig)
        shapes = (measured.shapes(config, sensors), predicted.shapes(pconfig, sensors))
        why = _why_not_mac(named, sensors, shapes)
        if why is None:
            found = _pair_by_mac(meas, pred, mac(*shapes), min_mac, freq_weight)
        else:
            found = _pair_by_frequency(meas, pred)
            if why:
                unused.append((config, why))
        pairs += found
        used_m = {p.measured.mode for p in found}
        used_p = {p.predicted.mode for p in found}
        lone_meas += [r for r in meas if r.mode not in used_m]
        lone_pred += [r for r in pred if r.mode not in used_p]
    for config in predicted.configs:
        if config not in used_configs:
            lone_pred += _refs(predicted, config)
    position = {c: i for i, c in enumerate(measured.configs)}
    pairs.sort(key=lambda p: (position[p.measured.config], p.measured.mode))
    return Pairing(source, tuple(pairs), tuple(lone_meas), tuple(lone_pred), tuple(unused))
