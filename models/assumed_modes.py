"""Euler-Bernoulli beam eigenfunctions with general end conditions, and the seed-002 two-link model.

A uniform beam (length L, bending stiffness EI, mass per length mu) has mode shapes
``W(x) = A S(bx) + B T(bx)/b + C U(bx)/b^2 + D V(bx)/b^3`` in the Krylov-Duncan functions
S, T, U, V (Blevins 1979, table 8-1; Gorman 1975), written in the non-dimensional coordinate x/L with
``b = lambda = beta L`` and ``omega = lambda^2 sqrt(EI / (mu L^4))``.  ``(A, B, C, D)`` are then directly
W, W', W'', W''' at the left end.  Each end carries a translational spring ``k_t``, a rotational spring
``k_r`` (either may be ``inf``: fixed), a lumped mass and a rotary inertia; with the signs of
``EI w'''' + mu w_tt = 0`` the end conditions are

    left  (x=0):  EI W''  = (k_r - omega^2 J) W',    EI W''' = (omega^2 m - k_t) W
    right (x=L):  EI W''  = (omega^2 J - k_r) W',    EI W''' = (k_t - omega^2 m) W

Each condition is scaled by ``1/(1 + k)`` (k non-dimensional: k_r L/EI, k_t L^3/EI) so a spring tending
to rigid tends smoothly to the fixed condition.  The characteristic determinant of the 4x4 system is
scanned for sign changes and each root refined with Brent's method; rigid-body modes (lambda = 0) come
from the null space of the lambda = 0 system.  Shapes are normalised with the end masses included:
``int mu phi^2 dx + sum(m phi^2 + J phi'^2) = 1`` (kg^-1/2), the orthonormality of seeds 002 and 004.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from scipy.linalg import eigh
from scipy.optimize import brentq

from flexmodal.models.errors import ModelError

INF = math.inf
_GAUSS_X, _GAUSS_W = np.polynomial.legendre.leggauss(80)
_GAUSS_X, _GAUSS_W = 0.5 * (_GAUSS_X + 1.0), 0.5 * _GAUSS_W  # on [0, 1]


@dataclass(frozen=True)
class End:
    """Support at one beam end: springs (N/m, N m/rad; ``inf`` = fixed), mass (kg), inertia (kg m^2)."""

    k_t_N_per_m: float = 0.0
    k_r_Nm_per_rad: float = 0.0
    mass_kg: float = 0.0
    inertia_kgm2: float = 0.0


CLAMPED, PINNED, FREE, SLIDING = End(INF, INF), End(INF, 0.0), End(), End(0.0, INF)
BOUNDARY_CONDITIONS: dict[str, tuple[End, End]] = {
    "clamped-free": (CLAMPED, FREE), "free-free": (FREE, FREE), "pinned-pinned": (PINNED, PINNED),
    "clamped-pinned": (CLAMPED, PINNED), "clamped-clamped": (CLAMPED, CLAMPED), "pinned-free": (PINNED, FREE),
    "clamped-sliding": (CLAMPED, SLIDING),
}


@dataclass(frozen=True)
class Beam:
    """A uniform Euler-Bernoulli beam: length [m], EI [N m^2], mass per length [kg/m]."""

    length_m: float
    EI_Nm2: float
    mass_per_m_kg: float

    @property
    def omega_scale(self) -> float:
        """omega / lambda^2 [rad/s]."""
        return math.sqrt(self.EI_Nm2 / (self.mass_per_m_kg * self.length_m**4))


def krylov(z: np.ndarray) -> np.ndarray:
    """Krylov-Duncan functions [4, ...]: S=(ch+c)/2, T=(sh+s)/2, U=(ch-c)/2, V=(sh-s)/2 (series below 1)."""
    z = np.asarray(z, float)
    small = np.abs(z) < 1.0
    out = np.stack([(np.cosh(z) + np.cos(z)) / 2, (np.sinh(z) + np.sin(z)) / 2,
                    (np.cosh(z) - np.cos(z)) / 2, (np.sinh(z) - np.sin(z)) / 2])
    if np.any(small):
        zs = z[small]
        series = np.zeros((4, zs.size))
        term = np.ones_like(zs)
        for n in range(24):  # z^n / n! summed by n mod 4: positive terms, no cancellation
            series[n % 4] += term
            term = term * zs / (n + 1)
        out[:, small] = series
    return out


def _values_at(lam: float, x: np.ndarray) -> np.ndarray:
    """Rows giving W, W', W'', W''' (derivatives in x/L) at ``x`` [n, 4 derivs, 4 coefs] for coefs A..D."""
    x = np.atleast_1d(np.asarray(x, float))
    if lam == 0.0:  # rigid/static polynomial limit
        one, zero = np.ones_like(x), np.zeros_like(x)
        rows = [[one, x, x**2 / 2, x**3 / 6], [zero, one, x, x**2 / 2], [zero, zero, one, x],
                [zero, zero, zero, one]]
        return np.moveaxis(np.array(rows), -1, 0)
    S, T, U, V = krylov(lam * x)
    rows = [[S, T / lam, U / lam**2, V / lam**3],
            [lam * V, S, T / lam, U / lam**2],
            [lam**2 * U, lam * V, S, T / lam],
            [lam**3 * T, lam**2 * U, lam * V, S]]
    return np.moveaxis(np.array(rows), -1, 0)


def _nondim(beam: Beam, end: End) -> tuple[float, float, float, float]:
    L, EI, mu = beam.length_m, beam.EI_Nm2, beam.mass_per_m_kg
    return (end.k_t_N_per_m * L**3 / EI, end.k_r_Nm_per_rad * L / EI, end.mass_kg / (mu * L),
            end.inertia_kgm2 / (mu * L**3))


def _condition_rows(lams: np.ndarray, beam: Beam, end: End, right: bool) -> np.ndarray:
    """Rows [n, 2, 4] of the end conditions at one end, acting on (W, W', W'', W''') there.

    Moment: W'' - s (k_r - lam^4 J) W' = 0; shear: W''' + s (k_t - lam^4 m) W = 0 with s = +1 on the left
    and -1 on the right; both scaled by 1/(1+k) so that k = inf leaves W' = 0 (W = 0).
    """
    kt, kr, m, J = _nondim(beam, end)
    s = -1.0 if right else 1.0
    l4 = lams**4
    rows = np.zeros((lams.size, 2, 4))
    for r, k, inertia, low, high, sgn in ((0, kr, J, 1, 2, -s), (1, kt, m, 0, 3, s)):
        if math.isinf(k):
            rows[:, r, low] = 1.0
        else:
            rows[:, r, high] = 1.0 / (1.0 + k)
            rows[:, r, low] = sgn * (k - l4 * inertia) / (1.0 + k)
    return rows


def _tip_values(lams: np.ndarray) -> np.ndarray:
    """W, W', W'', W''' at x = L for coefficients (A, B, C, D): [n, 4, 4] for each lambda > 0."""
    S, T, U, V = krylov(lams)
    rows = [[S, T / lams, U / lams**2, V / lams**3], [lams * V, S, T / lams, U / lams**2],
            [lams**2 * U, lams * V, S, T / lams], [lams**3 * T, lams**2 * U, lams * V, S]]
    return np.moveaxis(np.array(rows), -1, 0)


def boundary_matrices(lams: np.ndarray | float, beam: Beam, left: End, right: End) -> np.ndarray:
    """The matrices [n, 4, 4] acting on (A, B, C, D) whose determinants are the characteristic function."""
    lams = np.atleast_1d(np.asarray(lams, float))
    tip = np.empty((lams.size, 4, 4))
    zero = lams == 0.0
    if np.any(zero):
        tip[zero] = _values_at(0.0, 1.0)[0]
    tip[~zero] = _tip_values(lams[~zero])
    return np.concatenate([_condition_rows(lams, beam, left, False),
                           _condition_rows(lams, beam, right, True) @ tip], axis=1)


def characteristic(lam: float, beam: Beam, left: End, right: End) -> float:
    """Characteristic determinant at ``lam`` = beta L (zero at a natural frequency)."""
    return float(np.linalg.det(boundary_matrices(lam, beam, left, right)[0]))


@dataclass(frozen=True, eq=False)
class BeamModes:
    """Modes of a beam: ``lam`` = beta L, ``freq_hz``, coefficients (A, B, C, D) per mode [n, 4]."""

    beam: Beam
    left: End
    right: End
    lam: np.ndarray
    freq_hz: np.ndarray
    coef: np.ndarray

    def shape(self, x_m: Sequence[float] | np.ndarray | float, derivative: int = 0) -> np.ndarray:
        """d^k phi / dx^k at ``x_m`` [n_x, n_modes] (phi in kg^-1/2, derivatives per metre^k)."""
        xh = np.atleast_1d(np.asarray(x_m, float)) / self.beam.length_m
        out = np.empty((xh.size, self.lam.size))
        for i, (lam, c) in enumerate(zip(self.lam, self.coef, strict=True)):
            out[:, i] = _values_at(float(lam), xh)[:, derivative, :] @ c
        return out / self.beam.length_m**derivative

    @property
    def v(self) -> np.ndarray:
        """v_i = mu * int_0^L phi_i dx [kg^1/2 m] (seed 002 eq. 5)."""
        b = self.beam
        return b.mass_per_m_kg * b.length_m * (_GAUSS_W @ self.shape(_GAUSS_X * b.length_m))

    @property
    def slope0(self) -> np.ndarray:
        """phi_i'(0) [kg^-1/2 / m] (seed 002 eq. 6)."""
        return self.shape(0.0, 1)[0]

    @property
    def tip(self) -> np.ndarray:
        """phi_i(L) [kg^-1/2] (seed 002 eq. 6)."""
        return self.shape(self.beam.length_m)[0]


def _normalise(beam: Beam, left: End, right: End, lam: float, coef: np.ndarray) -> np.ndarray:
    L = beam.length_m
    vals = _values_at(lam, _GAUSS_X) @ coef  # [n_x, 4 derivatives]
    ends = _values_at(lam, np.array([0.0, 1.0])) @ coef
    energy = beam.mass_per_m_kg * L * (_GAUSS_W @ vals[:, 0] ** 2)
    for e, end in ((0, left), (1, right)):
        energy += end.mass_kg * ends[e, 0] ** 2 + end.inertia_kgm2 * (ends[e, 1] / L) ** 2
    c = coef / math.sqrt(energy)
    probe = _values_at(lam, np.linspace(0.0, 1.0, 21))[:, 0, :] @ c
    return c if probe[np.argmax(np.abs(probe))] > 0 else -c  # largest deflection positive


def beam_modes(beam: Beam, left: End, right: End, n_modes: int = 4, step: float = 0.05) -> BeamModes:
    """Lowest ``n_modes`` modes (rigid-body modes first, at 0 Hz) of a uniform beam with the given ends."""
    if min(beam.length_m, beam.EI_Nm2, beam.mass_per_m_kg) <= 0:
        raise ModelError(f"beam needs positive length, EI and mass per length (got {beam})")
    lams: list[float] = []
    coefs: list[np.ndarray] = []
    _, sv, vt = np.linalg.svd(boundary_matrices(0.0, beam, left, right)[0])
    for k in np.flatnonzero(sv < 1e-10 * max(sv[0], 1.0)):  # rigid-body modes
        if len(lams) < n_modes:
            lams.append(0.0)
            coefs.append(_normalise(beam, left, right, 0.0, vt[k]))
    lo = 1e-3
    while len(lams) < n_modes:  # scan a stretch of beta*L at once, refine every sign change
        grid = lo + step * np.arange(int(math.pi * (n_modes + 1) / step) + 1)
        det = np.linalg.det(boundary_matrices(grid, beam, left, right))
        for i in np.flatnonzero((det[:-1] * det[1:] < 0) | (det[:-1] == 0.0)):
            if len(lams) == n_modes:
                break
            root = grid[i] if det[i] == 0.0 else brentq(characteristic, grid[i], grid[i + 1],
                                                        args=(beam, left, right), xtol=1e-14, rtol=1e-15)
            _, _, vt = np.linalg.svd(boundary_matrices(root, beam, left, right)[0])
            lams.append(root)
            coefs.append(_normalise(beam, left, right, root, vt[-1]))
        lo = grid[-1]
        if lo > 400:
            raise ModelError(f"no more beam roots found below beta*L = 400 for {left} / {right}")
    lam = np.array(lams)
    return BeamModes(beam, left, right, lam, lam**2 * beam.omega_scale / (2 * math.pi), np.array(coefs))


def named_modes(beam: Beam, condition: str, n_modes: int = 4) -> BeamModes:
    """Modes for a named condition (``BOUNDARY_CONDITIONS``: clamped-free, free-free, pinned-pinned, ...)."""
    if condition not in BOUNDARY_CONDITIONS:
        raise ModelError(f"unknown boundary condition {condition!r} "
                         f"(expected one of {', '.join(BOUNDARY_CONDITIONS)})")
    return beam_modes(beam, *BOUNDARY_CONDITIONS[condition], n_modes)


def clamped_mass(beam: Beam, tip_mass_kg: float, tip_inertia_kgm2: float = 0.0,
                 n_modes: int = 4) -> BeamModes:
    """Cantilever with a tip mass and rotary inertia (Blevins 1979, table 8-8 for the mass alone)."""
    return beam_modes(beam, CLAMPED, End(mass_kg=tip_mass_kg, inertia_kgm2=tip_inertia_kgm2), n_modes)


def hub_beam(beam: Beam, hub_inertia_kgm2: float, joint_k_Nm_per_rad: float = 0.0, payload_kg: float = 0.0,
             payload_inertia_kgm2: float = 0.0, n_modes: int = 4) -> BeamModes:
    """A beam on a hub: pinned root with hub inertia J0 and torsional spring k, payload at the tip.

    ``k = 0``: the slewing beam of seed 002 eq. 3 (one rigid-body mode).  ``k > 0``: seed 004's flexible
    joint, with no rigid-body mode; ``k -> inf`` tends to the clamped beam with a tip payload.
    """
    return beam_modes(beam, End(INF, joint_k_Nm_per_rad, 0.0, hub_inertia_kgm2),
                      End(0.0, 0.0, payload_kg, payload_inertia_kgm2), n_modes)


def seed002_characteristic(beta_per_m: float, length_m: float, rho_kg_per_m: float, J02_kgm2: float,
                           Mp_kg: float = 0.0, Jp_kgm2: float = 0.0) -> float:
    """Seed 002 eq. 3: the slewing-beam characteristic function in beta [1/m] (zero at a root)."""
    b, r, J0, Jp, Mp = beta_per_m, rho_kg_per_m, J02_kgm2, Jp_kgm2, Mp_kg
    x = b * length_m
    s, c, sh, ch = math.sin(x), math.cos(x), math.sinh(x), math.cosh(x)
    return (c * sh - s * ch - 2 * Mp / r * b * s * sh - 2 * Jp / r * b**3 * c * ch
            - J0 / r * b**3 * (1 + c * ch)
            - Mp / r**2 * b**4 * (J0 + Jp) * (c * sh - s * ch) + J0 * Jp / r**2 * b**6 * (c * sh + s * ch)
            - J0 * Jp * Mp / r**3 * b**7 * (1 - c * ch))


# ---------------------------------------------------------------------------------------------
# seed 002: two-link arm with a flexible forearm, linearised at a pose (eqs. 4-14)


@dataclass(frozen=True)
class FlexibleForearmArm:
    """Seed 002's arm: rigid upper link, flexible forearm on a hub (SI units, eq. 7 notation)."""

    l1_m: float
    forearm: Beam
    J02_kgm2: float
    J1tot_kgm2: float
    J2tot_kgm2: float
    h3_kgm2: float
    Mp_kg: float = 0.0
    Jp_kgm2: float = 0.0


def forearm_modes(arm: FlexibleForearmArm, n_modes: int = 2) -> BeamModes:
    """The forearm's slewing-beam eigenfunctions (seed 002 eq. 3), flexible modes only."""
    modes = hub_beam(arm.forearm, arm.J02_kgm2, 0.0, arm.Mp_kg, arm.Jp_kgm2, n_modes + 1)
    keep = modes.lam > 0
    return BeamModes(modes.beam, modes.left, modes.right, modes.lam[keep], modes.freq_hz[keep],
                     modes.coef[keep])


def forearm_inertia_matrix(arm: FlexibleForearmArm, theta2_rad: float, n_modes: int = 2) -> np.ndarray:
    """B(q) of seed 002 eq. 7 at zero deflection, q = (theta1, theta2, delta_1..n); h_i of eq. 7."""
    modes = forearm_modes(arm, n_modes)
    h = (modes.v + arm.Mp_kg * modes.tip) * arm.forearm.length_m
    c = math.cos(theta2_rad)
    B = np.eye(2 + n_modes)
    B[0, 0] = arm.J1tot_kgm2 + arm.J2tot_kgm2 + 2 * arm.h3_kgm2 * c
    B[0, 1] = B[1, 0] = arm.J2tot_kgm2 + arm.h3_kgm2 * c
    B[1, 1] = arm.J2tot_kgm2
    B[0, 2:] = B[2:, 0] = h * c
    return B


def forearm_frequencies(arm: FlexibleForearmArm, theta2_rad: float, n_modes: int = 2,
                        locked: Sequence[int] = ()) -> np.ndarray:
    """Natural frequencies [Hz] of the linearised model (eq. 4, K of eq. 10, c = 0) at ``theta2_rad``.

    ``locked``: joints held fixed (1 and/or 2, e.g. by a stiff servo); each free joint adds a 0 Hz mode.
    """
    modes = forearm_modes(arm, n_modes)
    B = forearm_inertia_matrix(arm, theta2_rad, n_modes)
    K = np.diag(np.concatenate([[0.0, 0.0], (2 * math.pi * modes.freq_hz) ** 2]))
    keep = [i for i in range(2 + n_modes) if i >= 2 or i + 1 not in set(locked)]
    w2 = eigh(K[np.ix_(keep, keep)], B[np.ix_(keep, keep)], eigvals_only=True)
    return np.sqrt(np.clip(w2, 0.0, None)) / (2 * math.pi)
