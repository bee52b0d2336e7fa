"""Validation indicators of identified modes (Pappa, Elliott & Schenk 1993; Reynders, Houbrechts &
De Roeck 2012; Heylen, Lammens & Sas 1997 §A.4): how real a complex mode shape is (MPC, MPD), and how
well a synthesised FRF reproduces the measured one (FRAC).  Shapes are columns: ``phi`` [n_points,
n_modes]."""

from __future__ import annotations

import numpy as np


def _covariance(phi: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Sums Sxx, Syy, Sxy [n_modes] of the real (x) and imaginary (y) parts of each shape."""
    p = np.atleast_2d(np.asarray(phi, complex))
    x, y = p.real, p.imag
    return np.sum(x * x, axis=0), np.sum(y * y, axis=0), np.sum(x * y, axis=0)


def mpc(phi: np.ndarray) -> np.ndarray:
    """Modal phase collinearity [n_modes] in [0, 1]: ``((l1 - l2) / (l1 + l2))^2`` with l1, l2 the
    eigenvalues of the 2 x 2 covariance of the shape's real and imaginary parts.  1 for a real
    (monophase) shape, whatever its rotation in the complex plane; 0 for points spread evenly in
    phase.  1 - MPC is the modal complexity factor (MCF)."""
    sxx, syy, sxy = _covariance(phi)
    total = sxx + syy
    gap_sq = (sxx - syy) ** 2 + 4 * sxy ** 2             # (l1 - l2)^2
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where(total > 0, gap_sq / np.where(total > 0, total, 1.0) ** 2, 1.0)


def mpd(phi: np.ndarray) -> np.ndarray:
    """Mean phase deviation [n_modes] in degrees (0..90): the magnitude-weighted mean angle between
    each shape entry and the straight line through the origin that best fits the shape in the complex
    plane (the principal axis of the real and imaginary parts, angle ``0.5 arg(sum phi^2)``)."""
    p = np.atleast_2d(np.asarray(phi, complex))
    theta = 0.5 * np.angle(np.sum(p ** 2, axis=0))
    dev = np.abs(np.angle(p * np.exp(-1j * theta)[None, :]))   # 0..pi
    dev = np.minimum(dev, np.pi - dev)                           # the line has two directions
    w = np.abs(p)
    with np.errstate(divide="ignore", invalid="ignore"):
        out = np.sum(w * dev, axis=0) / np.sum(w, axis=0)
    return np.degrees(np.nan_to_num(out))


def frac(a: np.ndarray, b: np.ndarray, axis: int = -1) -> np.ndarray:
    """Frequency response assurance criterion ``|a^H b|^2 / ((a^H a)(b^H b))`` along ``axis`` (1 for
    FRFs of identical shape over frequency, whatever their scale)."""
    a, b = np.asarray(a), np.asarray(b)
    num = np.abs(np.sum(a.conj() * b, axis=axis)) ** 2
    den = np.sum(np.abs(a) ** 2, axis=axis) * np.sum(np.abs(b) ** 2, axis=axis)
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where(den > 0, num / np.where(den > 0, den, 1.0), 0.0)
