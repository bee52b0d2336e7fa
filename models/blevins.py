"""Closed-form natural frequencies of uniform Euler-Bernoulli beams (Blevins 1979, table 8-1).

``f_i = lambda_i^2 / (2 pi L^2) * sqrt(EI / mu)`` with the tabulated roots ``lambda_i = beta_i L`` of each
boundary condition; beyond the tabulated modes the asymptotic forms of the same table are used (exact to
better than 1e-7 from the fifth mode on).  A cantilever with a tip mass uses Blevins' table 8-8 Rayleigh
formula for the fundamental, ``f = (1/2 pi) sqrt(3 EI / (L^3 (M + 0.24 mu L)))``.
"""

from __future__ import annotations

import math

import numpy as np

from flexmodal.models.errors import ModelError

# lambda_i for i = 1..4 (Blevins 1979, table 8-1) and the asymptote for i >= 5 (i 1-based)
_TABLE: dict[str, tuple[tuple[float, ...], float]] = {
    "clamped-free": ((1.87510407, 4.69409113, 7.85475744, 10.99554073), -0.5),
    "free-free": ((4.73004074, 7.85320462, 10.99560784, 14.13716549), 0.5),
    "clamped-clamped": ((4.73004074, 7.85320462, 10.99560784, 14.13716549), 0.5),
    "clamped-pinned": ((3.92660231, 7.06858275, 10.21017612, 13.35176878), 0.25),
    "pinned-free": ((3.92660231, 7.06858275, 10.21017612, 13.35176878), 0.25),
    "clamped-sliding": ((2.36502037, 5.49780392, 8.63937983, 11.78097245), -0.25),
    "pinned-pinned": ((math.pi, 2 * math.pi, 3 * math.pi, 4 * math.pi), 0.0),
}
CONDITIONS = tuple(_TABLE)


def lambdas(condition: str, n_modes: int = 4) -> np.ndarray:
    """Roots beta_i L of the first ``n_modes`` flexible modes (rigid-body modes are not listed)."""
    if condition not in _TABLE:
        raise ModelError(f"Blevins: unknown boundary condition {condition!r} (expected one of "
                         f"{', '.join(CONDITIONS)})")
    table, offset = _TABLE[condition]
    return np.array([table[i - 1] if i <= len(table) else (i + offset) * math.pi
                     for i in range(1, n_modes + 1)])


def beam_frequencies_hz(condition: str, length_m: float, EI_Nm2: float, mass_per_m_kg: float,
                        n_modes: int = 4) -> np.ndarray:
    """Natural frequencies [Hz] of a uniform beam, ``f = lambda^2 / (2 pi L^2) sqrt(EI / mu)``."""
    lam = lambdas(condition, n_modes)
    return lam**2 / (2 * math.pi * length_m**2) * math.sqrt(EI_Nm2 / mass_per_m_kg)


def cantilever_tip_mass_hz(length_m: float, EI_Nm2: float, mass_per_m_kg: float,
                           tip_mass_kg: float) -> float:
    """Fundamental [Hz] of a cantilever with a tip mass (Blevins table 8-8, Rayleigh; within ~1 %)."""
    effective_mass = tip_mass_kg + 0.24 * mass_per_m_kg * length_m
    return math.sqrt(3 * EI_Nm2 / (length_m**3 * effective_mass)) / (2 * math.pi)
