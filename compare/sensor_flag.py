"""One sensor whose measured mode shapes disagree with the model's, judged against the shape noise.

A sensor mounted elsewhere (or on another direction) than the rig says, or a local effect no library
entry has, shows as one sensor whose measured shape components the model cannot follow while the other
sensors agree to within their noise.  The check is a leave-one-sensor-out F test on unit-normalised
shapes: for each sensor ``j`` and each measured mode, the model shape is scaled to the *other* sensors
(least squares), the misfit at ``j`` is predicted-minus-measured, and the other sensors' residuals give
the shape noise of that comparison.  Under independent per-sensor noise of one level the ratio of the two
mean squares is Fisher F with ``N`` and ``N (s - 2)`` degrees of freedom (``N`` modes x configurations,
``s`` sensors).  Unlike 1 - COMAC, the ratio does not grow where a sensor merely has a small amplitude
(near a node of every mode, 1 - COMAC is noise over a small signal).

The same test is also made mode by mode (``N`` = configurations, the others' noise of that mode alone):
a mode that the model does not follow at any sensor (a wrong or missing effect) inflates the pooled
noise and can hide a sensor that disagrees in every mode the model does follow (blind 1159 #10: a
moved sensor at pooled ratio 8, at 153x the noise of mode 1; docs/diagnosis.md's block ``sensor_modes``).
One mode alone does not flag: a model whose form is wrong at one sensor in one mode (a node a few
per cent off, the end of a real beam) looks the same there, while a sensor mounted elsewhere misreads
every mode whose shape differs between the two points (docs/diagnosis.md's block ``sensor_beam``).

A moved sensor also misleads the pairing of model and measured modes by MAC, so that the true effect
fits badly and a wrong verdict absorbs the sensor's misfit (blind 1788 #10); compare/diagnosis.py's
``_unpaired_flag`` then makes the same check against the single candidate that fits the frequencies
best with that sensor left out of the pairing (the MAC sums over the other sensors only, numerator and
both norms: compare/fit.py's ``Target.pairing_sensors``; ``flag_text`` names that model).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

SENSOR_FACTOR = 15.0
"""A sensor flags the verdict when its misfit mean square is at least 15x the shape noise the other
sensors show (an RMS misfit ~4x the noise).  On the 720 blind cases of the used draws 106-110, 211-215,
316-320 and 421-425, every moved sensor gave >= 20 and no in-library case more than 9.7 (model form and
wrong candidates included)."""
SENSOR_P = 1e-3
"""... and the F test rejects "same noise as the others" at 0.1 %, Bonferroni-corrected over sensors."""
SENSOR_MODE_FACTOR = 50.0
"""Or, in one mode, the misfit mean square is at least 50x that mode's shape noise at the other sensors
(and the F test rejects at ``SENSOR_P``, Bonferroni-corrected over sensors and modes), and the same
sensor stands out in ``SENSOR_MODES`` modes in all.  Chosen in-sample (27 Nov), after blind 1159 #10 (a
moved sensor the pooled test missed) and on the stored verdicts of the used draws 946-950, 1051-1055 and
1156-1160, by scripts outside the repository, measured once; the ratios of the current method on
1156-1160 are docs/diagnosis.md's block ``sensor_modes``, on the draws 1681-1685 no case of which chose
it the block ``sensor_modes_fresh`` (benchmarks/sensor_mode_ratios.py, re-run by
tests/test_diagnosis_sensor_flag.py under ``-m slow``)."""
SENSOR_MODES = 2
"""... in at least two modes: at ``SENSOR_MODE_FACTOR`` in one and at ``SENSOR_FACTOR`` in another (each
with ``SENSOR_P``), so that one mode alone cannot carry the flag.  Added after a review (28 Nov) measured
the one-mode rule on a real free beam with nothing moved (modelab_free_beam against the textbook beam):
it about doubled the pooled test's flags.  Two modes (chosen on that beam: in-sample) cut those added
flags to the few at the beam's accelerometer, a real local mass (docs/diagnosis.md's block ``sensor_beam``,
benchmarks/sensor_flag_beam.py, re-run by tests/test_diagnosis_sensor_flag.py); blind 1159 #10 stands
out in two modes (its slow test checks the flag)."""
SHAPE_NOISE_MIN = 1e-3
"""No sensor measures a unit-normalised shape better than 0.1 % (the floor of the noise estimate)."""


@dataclass(frozen=True)
class SensorCheck:
    """The worst sensor of a leave-one-sensor-out shape check: its index, the ratio of its misfit mean
    square to the other sensors' noise mean square [-], the Bonferroni-corrected p-value of that ratio,
    and whether it flags the verdict (``ratio >= SENSOR_FACTOR`` and ``p_value <= SENSOR_P``, pooled over
    modes; or mode by mode, ``SENSOR_MODE_FACTOR`` in one and ``SENSOR_FACTOR`` in ``SENSOR_MODES`` in
    all).  ``mode`` is the sensor's worst mode when only the mode-by-mode test flags (the ratio and
    p-value are then that mode's), else None."""

    sensor: int
    ratio: float
    p_value: float
    flagged: bool
    mode: int | None = None


def _unit(x: np.ndarray) -> np.ndarray:
    return x / np.maximum(np.linalg.norm(x, axis=1, keepdims=True), 1e-300)


def sensor_check(measured: np.ndarray, model: np.ndarray) -> SensorCheck | None:
    """The sensor whose measured shapes disagree most with ``model`` against the shape noise.

    Parameters
    ----------
    measured, model : ndarray [C, s, n]
        Real mode shapes (any scale, any sign) of ``n`` paired modes at ``s`` sensors in ``C``
        configurations; configurations with a missing value in either are skipped.

    Returns
    -------
    SensorCheck or None
        None with fewer than three sensors or no complete configuration.

    Examples
    --------
    Two modes at four sensors, 1 % noise; sensor 2 reads another point of the arm:

    >>> rng = np.random.default_rng(0)
    >>> true = np.array([[0.2, 0.5, 0.8, 1.0], [0.9, 0.6, -0.4, -1.0]]).T[None].repeat(6, axis=0)
    >>> meas = true + 0.01 * rng.standard_normal(true.shape)
    >>> sensor_check(meas, true).flagged
    False
    >>> meas[:, 2] = [0.3, 0.9]
    >>> check = sensor_check(meas, true)
    >>> check.sensor, check.flagged, check.ratio > 1000
    (2, True, True)
    """
    from scipy.special import fdtrc  # F survival function (lighter than scipy.stats)

    full = ~(np.isnan(measured).any(axis=(1, 2)) | np.isnan(model).any(axis=(1, 2)))
    C, s, n = measured[full].shape
    if s < 3 or C == 0:
        return None
    m, a = _unit(np.real(measured[full])), _unit(np.real(model[full]))
    miss, noise = np.empty((s, n)), np.empty((s, n))        # per sensor left out and mode, summed over C
    for j in range(s):
        others = np.arange(s) != j
        ao, mo = a[:, others], m[:, others]
        norm = np.maximum(np.sum(ao * ao, axis=1), 1e-300)                         # [C, n]
        alpha = np.sum(mo * ao, axis=1) / norm
        miss[j] = np.sum((m[:, j] - alpha * a[:, j]) ** 2 / (1.0 + a[:, j] ** 2 / norm), axis=0)
        noise[j] = np.sum((mo - alpha[:, None] * ao) ** 2, axis=(0, 1))
    floor = SHAPE_NOISE_MIN**2
    ratios = (miss.sum(axis=1) / (C * n)) / np.maximum(noise.sum(axis=1) / (C * n * (s - 2)), floor)
    worst = int(np.argmax(ratios))
    p = min(1.0, s * float(fdtrc(C * n, C * n * (s - 2), ratios[worst])))
    pooled = SensorCheck(worst, float(ratios[worst]), p,
                         bool(ratios[worst] >= SENSOR_FACTOR and p <= SENSOR_P))
    per_mode = (miss / C) / np.maximum(noise / (C * (s - 2)), floor)                      # [s, n]
    p_mode = np.minimum(1.0, s * n * fdtrc(C, C * (s - 2), per_mode))
    stands_out = (per_mode >= SENSOR_FACTOR) & (p_mode <= SENSOR_P)
    sensors = np.flatnonzero(np.any(stands_out & (per_mode >= SENSOR_MODE_FACTOR), axis=1)
                             & (stands_out.sum(axis=1) >= SENSOR_MODES))
    if pooled.flagged or sensors.size == 0:
        return pooled
    j = int(sensors[np.argmax(per_mode[sensors].max(axis=1))])
    k = int(np.argmax(per_mode[j]))
    return SensorCheck(j, float(per_mode[j, k]), float(p_mode[j, k]), True, k)


def sensor_flag(measured: np.ndarray, model: np.ndarray, names: Sequence[str]) -> tuple[str, str]:
    """The name of one disagreeing sensor (``sensor_check``) and the flag text (``flag_text``); empty
    strings when no sensor disagrees."""
    check = sensor_check(measured, model)
    if check is None or not check.flagged:
        return "", ""
    return names[check.sensor], flag_text(measured, model, names, check)


def flag_text(measured: np.ndarray, model: np.ndarray, names: Sequence[str], check: SensorCheck,
              against: str = "") -> str:
    """The flag of ``check`` (a flagged ``sensor_check`` of ``measured`` against ``model`` [C, s, n]),
    with the COMAC of every sensor (Lieven & Ewins 1988); ``against`` names the model when it is not
    the verdict's."""
    from flexmodal.compare.gap import comac

    full = ~(np.isnan(measured).any(axis=(1, 2)) | np.isnan(model).any(axis=(1, 2)))
    values = comac(measured[full], model[full])
    others = np.delete(values, check.sensor)
    where = "" if check.mode is None else f" in mode {check.mode + 1}"
    return (f"the measured shapes disagree at sensor {names[check.sensor]}{against} (COMAC "
            f"{values[check.sensor]:.2f}, the other sensors {others.min():.2f}-{others.max():.2f}; its "
            f"misfit{where} is {check.ratio:.0f}x the shape noise of the others)")
