"""The measured data of a diagnosis, the baseline sim-to-real gap and where it lies.

Errors are relative, ``f_model / f_measured - 1`` (0.05 = 5 %).  Shape correlation: MAC (Allemang &
Brown 1982) per paired mode and COMAC per sensor (Lieven & Ewins 1988) over all paired modes.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from flexmodal.checked_io.plural import counted
from flexmodal.compare.errors import CompareError
from flexmodal.contract.table import ModalTable
from flexmodal.models.rig import Rig


@dataclass(frozen=True)
class Measured:
    """Validated measured modes: configurations, poses, frequencies [C, n] and shapes [C, n_s, n]."""

    configs: tuple[str, ...]
    poses: tuple[dict[str, float], ...]
    freq_hz: np.ndarray
    shapes: np.ndarray | None
    sensors: tuple[str, ...]        # rig sensors with measured shapes (order of ``shapes``)
    # configurations whose measured shapes cannot pair modes by MAC (the fit pairs them by frequency
    # order), each with the key of compare.pairing.WHY_NOT_MAC (:func:`unused_shapes`)
    shapes_unused: tuple[tuple[str, str], ...] = ()


def prepare(rig: Rig, table: ModalTable, min_configs: int = 3) -> Measured:
    """Check ``table`` against ``rig`` (pose columns, modes, configurations); CompareError on a problem."""
    src = table.source
    have = sorted(c[len("pose."):] for c in table.pose_columns)
    need = sorted(rig.pose_variables)
    if have != need:
        missing = [v for v in need if v not in have]
        extra = [v for v in have if v not in need]
        what = f"lacks pose.{missing[0]}" if missing else f"has pose.{extra[0]}, which is not a pose variable"
        raise CompareError(f"{src}: pose columns do not match the rig's joints: the table {what} "
                           f"(rig {rig.source} needs {', '.join('pose.' + v for v in need) or 'none'})")
    configs = table.configs
    if len(configs) < min_configs:
        raise CompareError(f"{src}: {counted(len(configs), 'configuration')}; held-out scoring needs at "
                           f"least {min_configs}")
    n = int(table.frame["mode"].max())
    poses = []
    for c in configs:
        modes = sorted(table.rows(c)["mode"].tolist())
        if modes != list(range(1, n + 1)):
            lack = sorted(set(range(1, n + 1)) - set(modes))
            fullest = next(k for k in configs if int(table.rows(k)["mode"].max()) == n)
            raise CompareError(f"{src}: config {c!r} is missing mode {lack[0] if lack else modes} "
                               f"(every configuration needs modes 1..{n}, as {fullest!r} has: identify "
                               "over a band every run resolves, --fmin/--fmax, or keep the common modes)")
        pose = table.pose(c)
        if sorted(pose) != need:
            lacking = sorted(set(need) - set(pose))[0]
            raise CompareError(f"{src}: config {c!r} has no value for pose.{lacking}")
        poses.append({k: float(v) for k, v in pose.items()})
    freq = np.array([table.freq_hz(c) for c in configs])
    rig_sensors = [s.name for s in rig.sensors]
    sensors = tuple(s for s in table.sensors if s in rig_sensors)
    shapes, unused = None, ()
    if sensors:
        shapes = np.array([table.shapes(c, sensors) for c in configs])
        why = [unused_shapes(phi) for phi in shapes]
        unused = tuple((c, w) for c, w in zip(configs, why, strict=True) if w)
        still = ~np.any(np.nan_to_num(shapes) != 0, axis=1)   # [C, n]: a mode zero wherever it is given
        shapes = np.where(still[:, None, :], np.nan, shapes)   # no shape (MAC 0/0), not one unlike every mode
        if len(sensors) < 2 or np.isnan(shapes).all():   # one sensor: every MAC is 1, it pairs nothing
            shapes, sensors = None, ()
    elif table.sensors:   # shape columns, none at a sensor of the rig (renamed?): compare's "apart"
        unused = tuple((c, "apart") for c in configs)
    return Measured(tuple(configs), tuple(poses), freq, shapes, sensors, unused)


def unused_shapes(phi: np.ndarray) -> str | None:
    """Why the fit (compare.fit) pairs a configuration's modes by frequency order rather than by MAC,
    from its measured shapes ``phi`` [n_sensors, n_modes] at the rig's sensors: the key of
    compare.pairing.WHY_NOT_MAC ("zero measured": every value given is 0, the MAC 0/0 is undefined;
    "empty": fewer than two sensors hold a value for every mode, one sensor alone included (its MAC is
    1 for any pair); "zero mode": one mode is 0 at every sensor that gives it; "incomplete": a value is
    missing at some other sensor), or None when every value is given and every mode moves the sensors.

    Examples
    --------
    >>> phi = np.array([[0.5, 1.0], [1.0, -0.5]])
    >>> unused_shapes(phi), unused_shapes(0 * phi), unused_shapes(np.full((2, 2), np.nan))
    (None, 'zero measured', 'empty')
    >>> unused_shapes(np.vstack([phi, [[np.nan, 0.2]]])), unused_shapes(np.array([[0.0, np.nan]] * 3))
    ('incomplete', 'zero measured')
    >>> unused_shapes(phi[:1]), unused_shapes(phi * [1.0, 0.0])
    ('empty', 'zero mode')
    """
    given = np.isfinite(phi)
    if given.any() and not np.any(phi[given]):
        return "zero measured"
    complete = int(np.sum(given.all(axis=1)))
    if complete < 2:
        return "empty"
    if not np.all(np.any(np.nan_to_num(phi) != 0, axis=0)):
        return "zero mode"
    return "incomplete" if complete < len(phi) else None


def rms(x: np.ndarray) -> float:
    return float(np.sqrt(np.mean(np.square(x)))) if np.size(x) else 0.0


def gap_summary(err: np.ndarray, configs: tuple[str, ...]) -> dict:
    """The ``baseline`` block of diagnosis.json (docs/formats.md) from relative errors [C, n]."""
    return {
        "rms_rel_error": rms(err),
        "max_rel_error": float(np.max(np.abs(err))),
        "per_mode": {str(m + 1): rms(err[:, m]) for m in range(err.shape[1])},
        "per_config": {c: rms(err[i]) for i, c in enumerate(configs)},
    }


def carriers(per_item: dict[str, float], scatter: float) -> list[str]:
    """Items (modes or configs) whose RMS error is above twice the scatter and at least half the largest."""
    top = max(per_item.values(), default=0.0)
    return [k for k, v in per_item.items() if v > max(2 * scatter, 0.5 * top)]


def comac(measured: np.ndarray, model: np.ndarray) -> np.ndarray:
    """COMAC per sensor over paired modes; shapes [k, s, n] stacked over configs, unit-scaled per mode."""
    def unit(x: np.ndarray) -> np.ndarray:
        return x / np.maximum(np.linalg.norm(x, axis=-2, keepdims=True), 1e-300)

    a, b = unit(measured), unit(model)
    sign = np.sign(np.sum((a.conj() * b).real, axis=-2, keepdims=True))
    b = b * np.where(sign == 0, 1.0, sign)
    num = np.abs(np.sum(a.conj() * b, axis=(0, 2))) ** 2
    den = np.sum(np.abs(a) ** 2, axis=(0, 2)) * np.sum(np.abs(b) ** 2, axis=(0, 2))
    return num / np.maximum(den, 1e-300)


def region_scores(err: np.ndarray, sens: np.ndarray, groups: dict[str, list[int]],
                  weight: np.ndarray) -> dict[str, float]:
    """Fraction of the (weighted) error pattern [C, n] explained linearly by each location's sensitivities.

    ``sens`` [C, n, H]: d(f/f_meas)/dh at the nominal model; ``groups`` maps a region label to handle
    indices.  The score is R^2 of the least-squares fit of the error by that region's columns.
    """
    e = (err * weight).ravel()
    total = float(e @ e)
    out = {}
    for label, idx in groups.items():
        A = (sens[..., idx] * weight[..., None]).reshape(-1, len(idx))
        scale = np.linalg.norm(A, axis=0)
        ok = scale > 0
        if not ok.any() or total == 0:
            out[label] = 0.0
            continue
        A = A[:, ok] / scale[ok]
        coef, *_ = np.linalg.lstsq(A, e, rcond=None)
        fit = A @ coef
        out[label] = float(fit @ fit / total)
    return out


def damped_frequency_shift(zeta: float | np.ndarray) -> float | np.ndarray:
    """Relative drop of the damped natural frequency, ``1 - sqrt(1 - zeta^2)`` (viscous, Ewins 2000 §2.2).

    Seed 000's largest ratio zeta = 0.13 moves a frequency by 0.85 % at most, far below Table 2's
    6.7-15 % shifts: damping alone cannot explain them.
    """
    return 1.0 - np.sqrt(1.0 - np.square(zeta))


def joint_angles_rad(rig: Rig, poses: tuple[dict[str, float], ...]) -> dict[str, np.ndarray]:
    """Each joint's angle [rad] at every configuration (its fixed angle when it has no pose variable)."""
    return {j.name: np.array([math.radians(p[j.angle] if j.angle else j.angle_deg) for p in poses])
            for j in rig.joints}


@dataclass(frozen=True)
class Scatter:
    """Relative measurement scatter of the frequencies (0.005 = 0.5 %) and where it came from."""

    value: float
    source: str        # "repeated configurations", "freq_std_hz column" or "--scatter (fallback)"
    detail: str


FALLBACK_SOURCE = "--scatter (fallback)"
"""``Scatter.source`` when the data carry no scatter of their own and the assumed fallback stands in."""

MIN_SCATTER_REL = 1e-6
"""No relative frequency scatter below 1 ppm is taken (far below any modal test's repeatability; a
smaller one, or a subnormal ``freq_std_hz``, squares to 0 in the chi-square of the diagnosis)."""


def _raised(value: float) -> str:
    """What a scatter's detail adds when the data's ``value`` (fraction) is below ``MIN_SCATTER_REL``.

    Examples
    --------
    >>> _raised(0.0), _raised(0.002)
    ('; raised to the 1e-06 floor', '')
    """
    return f"; raised to the {MIN_SCATTER_REL:g} floor" if value < MIN_SCATTER_REL else ""


def estimate_scatter(table: ModalTable, meas: Measured, fallback: float) -> Scatter:
    """Scatter from the data when it carries any, else ``fallback``; at least ``MIN_SCATTER_REL``.

    In order: (1) configurations measured more than once at the same pose: the pooled standard deviation
    of ``ln f`` within each group of repeats, per mode, ``sqrt(sum (ln f - mean)^2 / (N - G))`` (needs at
    least two degrees of freedom); (2) a ``freq_std_hz`` column (e.g. identification uncertainty): the
    RMS of ``freq_std_hz / freq_hz`` over its rows; (3) ``fallback``.
    """
    keys = [tuple(sorted(p.items())) for p in meas.poses]
    groups: dict[tuple, list[int]] = {}
    for i, k in enumerate(keys):
        groups.setdefault(k, []).append(i)
    reps = [g for g in groups.values() if len(g) > 1]
    if reps:
        logf = np.log(meas.freq_hz)
        dev = np.concatenate([(logf[g] - logf[g].mean(axis=0)).ravel() for g in reps])
        dof = sum((len(g) - 1) * meas.freq_hz.shape[1] for g in reps)
        if dof >= 2:
            value = float(np.sqrt(np.sum(dev**2) / dof))
            return Scatter(max(value, MIN_SCATTER_REL), "repeated configurations",
                           f"{counted(len(reps), 'pose')} measured more than once, "
                           f"{dof} degrees of freedom{_raised(value)}")
    if "freq_std_hz" in table.frame.columns:
        rel = (table.frame["freq_std_hz"] / table.frame["freq_hz"]).to_numpy(float)
        rel = rel[np.isfinite(rel) & (rel > 0)]
        if rel.size:
            value = float(np.sqrt(np.mean(rel**2)))
            return Scatter(max(value, MIN_SCATTER_REL), "freq_std_hz column",
                           f"RMS of freq_std_hz / freq_hz over {rel.size} rows{_raised(value)}")
    return Scatter(fallback, FALLBACK_SOURCE, "the data carry no repeats and no freq_std_hz column")
