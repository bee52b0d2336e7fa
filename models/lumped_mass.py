"""Lumped-mass model from the flexibility matrix (seed 003 §3.1), for a serial arm at any pose.

Each link is cut into ``masses_per_link`` equal stretches whose mass goes half to each end (the
trapezoidal lumping; a joint point collects from both links, the clamped base point keeps none), plus
the rig's own lumped masses (payloads, sensor masses).  The
flexibility matrix ``a_ij`` (deflection along coordinate i per unit force along coordinate j) follows
from the unit-load method (Maxwell-Mohr): ``a_ij = int M_i M_j / EI ds`` over all links plus ``M_i M_j / k``
at each spring joint and a spring base, where ``M_i(s)`` is the bending moment at section s of a unit
force at coordinate i (non-zero only for sections between the base and the load).  The integrand is
piecewise quadratic, so two-point Gauss rules on stretches split at the load points are exact.  Axial
deformation and rotary inertia are neglected, as in the seed.

``coordinates="transverse"`` keeps one coordinate per mass, normal to its own link (seed 003's choice);
``"planar"`` gives every mass both in-plane translations, so a link carried sideways by the bending of
the link before it keeps its inertia (the transverse-only model loses it once the arm is bent).
Frequencies solve ``a M x = (1/omega^2) x`` in the symmetric form ``M^1/2 a M^1/2``.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np
from scipy.linalg import eigh

from flexmodal.contract.mac import largest_positive
from flexmodal.models.errors import ModelError
from flexmodal.models.frame import link_geometry
from flexmodal.models.rig import Point, Rig

_GAUSS2 = np.array([0.5 - 0.5 / math.sqrt(3.0), 0.5 + 0.5 / math.sqrt(3.0)])
MAX_COORDS = 4000  # coordinates of the lumped-mass model (its dense flexibility matrix and eigenproblem)


@dataclass(frozen=True, eq=False)
class LumpedModes:
    """Frequencies [Hz], mass-normalised shapes over the mass coordinates, shapes at the sensors."""

    freq_hz: np.ndarray
    phi: np.ndarray
    sensor_shapes: np.ndarray
    flexibility: np.ndarray   # [n_coords, n_coords] m/N
    masses_kg: np.ndarray     # [n_coords]


def _check(rig: Rig) -> None:
    where = f"{rig.source}: model 'lumped-mass'"
    if rig.base.support not in ("clamped", "spring"):
        raise ModelError(f"{where} needs a clamped or spring base (base.support = {rig.base.support!r})")
    for j in rig.joints:
        if j.kind == "pin" or (j.kind == "spring" and not j.k_Nm_per_rad):
            raise ModelError(f"{where}: joint {j.name!r} is a pin (a flexibility matrix needs a stiff chain)")
    if rig.members:
        raise ModelError(f"{where} cannot represent member {rig.members[0].name!r} (use --model fe)")
    if rig.springs:
        raise ModelError(f"{where} cannot represent a grounded spring at {rig.springs[0].at} "
                         "(use --model fe)")
    rig.check_euler_bernoulli(where)


def lumped_mass_modes(rig: Rig, pose: Mapping[str, float], n_modes: int = 4, masses_per_link: int = 4,
                      coordinates: str = "planar") -> LumpedModes:
    """Modes of the lumped-mass flexibility model of ``rig`` at ``pose`` (degrees, kg)."""
    _check(rig)
    rig.check_pose(pose)
    if coordinates not in ("transverse", "planar"):
        raise ModelError(f"lumped-mass coordinates must be 'transverse' or 'planar' (got {coordinates!r})")
    angles, starts = link_geometry(rig, pose)
    index = {lk.name: i for i, lk in enumerate(rig.links)}
    tangent = np.stack([np.cos(angles), np.sin(angles)], 1)
    normal = np.stack([-np.sin(angles), np.cos(angles)], 1)

    # points: (link index, s along the link [m], mass kg); each stretch's mass goes half to each end,
    # a joint point belongs to the parent's end, the base point (which cannot move) is dropped
    lumps: dict[tuple[int, float], float] = {}
    for i, lk in enumerate(rig.links):
        fr = np.linspace(0.0, 1.0, masses_per_link + 1) * lk.length_m
        for a, b in zip(fr[:-1], fr[1:], strict=True):
            mu = np.mean([lk.section_at(a + (b - a) * g).mass_per_m_kg for g in _GAUSS2]) * lk.mass_scale
            mass = mu * (b - a)
            start = (i - 1, rig.links[i - 1].length_m) if i and a == 0.0 else (i, float(a))
            for key in (start, (i, float(b))):
                lumps[key] = lumps.get(key, 0.0) + mass / 2
    points = [(li, s, m) for (li, s), m in lumps.items() if (li, s) != (0, 0.0)]

    def at(p: Point) -> tuple[int, float]:
        return index[p.link], p.fraction * rig.links[index[p.link]].length_m

    for m in rig.masses:
        value = float(pose[m.mass_kg]) if isinstance(m.mass_kg, str) else float(m.mass_kg)
        points.append((*at(m.at), value))
    points += [(*at(s.at), s.mass_kg) for s in rig.sensors if s.mass_kg > 0]
    sensor_points = [(*at(s.at), 0.0) for s in rig.sensors]
    all_points = points + sensor_points
    n_mass_pts = len(points)

    coords: list[tuple[int, np.ndarray]] = []  # (point index, unit direction)
    for p, (li, _, _) in enumerate(points):
        coords.append((p, normal[li]))
        if coordinates == "planar":
            coords.append((p, tangent[li]))
    n_mass_coords = len(coords)
    for k, s in enumerate(rig.sensors):
        li = sensor_points[k][0]
        coords.append((n_mass_pts + k, normal[li] if s.direction == "transverse" else tangent[li]))

    if len(coords) > MAX_COORDS:  # refused before the flexibility matrix (links x coordinates^2 work)
        raise ModelError(f"{rig.source}: model 'lumped-mass' would have {len(coords)} coordinates (at most "
                         f"{MAX_COORDS}; fewer links or --masses-per-link, or --model fe)")
    xy = np.array([starts[li] + s * tangent[li] for li, s, _ in all_points])
    pt_link = np.array([li for li, _, _ in all_points])
    pt_s = np.array([s for _, s, _ in all_points])
    c_pt = np.array([p for p, _ in coords])
    c_dir = np.array([d for _, d in coords])
    c_xy, c_link, c_s = xy[c_pt], pt_link[c_pt], pt_s[c_pt]

    def moments(link: int, s: np.ndarray) -> np.ndarray:
        """Bending moment [N m per N] at sections (link, s[q]) of a unit force along each coordinate."""
        sec_xy = starts[link] + np.outer(s, tangent[link])
        arm = c_xy[None, :, :] - sec_xy[:, None, :]
        moment = arm[..., 0] * c_dir[None, :, 1] - arm[..., 1] * c_dir[None, :, 0]
        distal = (c_link[None, :] > link) | ((c_link[None, :] == link) & (c_s[None, :] > s[:, None]))
        return np.where(distal, moment, 0.0)

    flex = np.zeros((len(coords), len(coords)))
    for li, lk in enumerate(rig.links):
        cuts = {0.0, lk.length_m} | {float(s) for s in pt_s[pt_link == li]}
        cuts |= {min(seg.from_m, lk.length_m) for seg in lk.segments} | {min(seg.to_m, lk.length_m)
                                                                       for seg in lk.segments}
        edges = np.array(sorted(cuts))
        lo, hi = edges[:-1], edges[1:]
        sq = (lo[:, None] + (hi - lo)[:, None] * _GAUSS2[None, :]).ravel()
        wq = np.repeat((hi - lo) / 2, 2)
        EI = np.array([lk.section_at(s).EI_Nm2 for s in sq]) * lk.stiffness_scale
        G = moments(li, sq)
        flex += G.T @ (G * (wq / EI)[:, None])
        spring = rig.base.k_Nm_per_rad if li == 0 and rig.base.support == "spring" else None
        if li > 0:
            joint = next(j for j in rig.joints if j.child == lk.name)
            spring = joint.k_Nm_per_rad if joint.kind == "spring" else None
        if spring:
            g = moments(li, np.array([-1e-12]))[0]  # just inside the link's start: every load on it counts
            flex += np.outer(g, g) / spring

    masses = np.array([points[p][2] for p, _ in coords[:n_mass_coords]])
    keep = masses > 0
    a = flex[np.ix_(np.flatnonzero(keep), np.flatnonzero(keep))]
    d = np.sqrt(masses[keep])
    n_keep = int(keep.sum())
    if not 1 <= n_modes <= n_keep:
        raise ModelError(f"{rig.source}: the lumped-mass model has {n_keep} coordinates, "
                         f"not enough for {n_modes} modes")
    mu, v = eigh(d[:, None] * a * d[None, :], subset_by_index=[n_keep - n_modes, n_keep - 1])
    mu, v = mu[::-1], v[:, ::-1]
    if np.any(mu <= 0):
        raise ModelError(f"{rig.source}: lumped-mass model has fewer than {n_modes} flexible modes")
    omega2 = 1.0 / mu
    phi = v / d[:, None]
    sensor_rows = flex[n_mass_coords:, :n_mass_coords][:, keep]
    shapes = omega2[None, :] * (sensor_rows @ (masses[keep][:, None] * phi))
    ref = shapes if shapes.shape[0] else phi
    sign = largest_positive(ref)
    phi_full = np.zeros((n_mass_coords, n_modes))
    phi_full[keep] = phi * sign
    return LumpedModes(np.sqrt(omega2) / (2 * math.pi), phi_full, shapes * sign,
                       flex[:n_mass_coords, :n_mass_coords], masses)

