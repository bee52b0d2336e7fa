"""Parameter-linear FE models for the gap diagnosis: K(h) = K0 + sum h_i K_i, M(h) = M0 + sum h_i M_i.

Every candidate effect of models/effects.py enters the frame model linearly through a few *handles*
(a joint spring k, an added mass m or inertia J, a grounded spring k, a link's stiffness or mass scale).
All effect slots are built once into one *super rig* whose DOF layout holds them all (spring joints,
a base spring, zero masses and zero springs at every candidate point), so each handle's matrices are
exact differences in one layout: rank-one rows from ``FrameSystem.observe``/``joint_rotation`` for springs
and point masses, one extra assembly per link for the link scales.  A rigid joint or clamped base is the
same layout with a stiff spring (``RIGID_FACTOR`` EI/L, relative frequency error < 1e-6).

Modes are then computed on a small Ritz basis (Bathe 2014 §10.3.3; load-dependent Ritz vectors, Wilson,
Yuan & Dickens 1982): the nominal modes plus, for each handle, its static correction ``(K+sM)^-1 R^T`` and
one Krylov step ``(K+sM)^-1 M c``.  Each candidate uses only its own handles' columns, orthonormalised in
the nominal mass metric, so a whole fit is a batch of dense eigenproblems of size ~20 (numpy batched
``eigh``), with exact eigenvalue sensitivities ``d lambda / d h = z^T (K_h - lambda M_h) z`` (Fox & Kapoor
1968) for the least-squares Jacobian.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, replace

import numpy as np
from scipy.linalg import cho_factor, cho_solve, eigh

from flexmodal.models.effects import effect_locations
from flexmodal.models.frame import assemble
from flexmodal.models.rig import Mass, Rig, Spring

RIGID_FACTOR = 1e7
"""A rigid joint or clamp is a spring of ``RIGID_FACTOR * EI / L`` in the super rig's layout."""
EXTRA_MODES = 4
"""Nominal modes kept in the Ritz basis beyond the measured ones."""


@dataclass(frozen=True)
class Handle:
    """One linear parameter of the frame model: ``kind`` is ``K`` (stiffness) or ``M`` (mass)."""

    name: str          # e.g. "k@elbow", "m@tip", "EI@link2"
    kind: str          # "K" or "M"
    nominal: float     # value in the nominal rig (SI; link scales are multipliers, nominal 1)


def _stiff(rig: Rig, link_name: str) -> float:
    link = rig.link(link_name)
    return RIGID_FACTOR * link.section.EI_Nm2 * link.stiffness_scale / link.length_m


def handles_for(rig: Rig) -> list[Handle]:
    """All handles the effects of models/effects.py can move on ``rig``."""
    out = []
    for name in effect_locations(rig, "joint_stiffness"):
        j = rig.joint(name)
        k = float(j.k_Nm_per_rad) if j.kind == "spring" else _stiff(rig, j.child)
        out.append(Handle(f"k@{name}", "K", k))
    for loc in effect_locations(rig, "joint_mass") + ["tip"]:
        out += [Handle(f"m@{loc}", "M", 0.0), Handle(f"J@{loc}", "M", 0.0)]
    if effect_locations(rig, "base_stiffness"):
        b = rig.base
        nominal = {"clamped": _stiff(rig, rig.links[0].name), "pinned": 0.0}.get(b.support,
                                                                                 b.k_Nm_per_rad or 0.0)
        out.append(Handle("k@base", "K", float(nominal)))
    out += [Handle(f"k@{m}", "K", rig.members[[x.name for x in rig.members].index(m)].end_k_Nm_per_rad)
            for m in effect_locations(rig, "end_restraint")]
    if rig.sensors:
        out.append(Handle("m@sensors", "M", 0.0))
    out += [Handle(f"ks@{p}", "K", 0.0) for p in effect_locations(rig, "grounded_spring")]
    out += [Handle(f"EI@{lk.name}", "K", 1.0) for lk in rig.links]
    out += [Handle(f"mu@{lk.name}", "M", 1.0) for lk in rig.links]
    return out


def super_rig(rig: Rig) -> Rig:
    """The rig with every effect slot present at zero: spring joints/base (k = 0), zero masses/springs."""
    joints = tuple(replace(j, kind="spring", k_Nm_per_rad=0.0) if j.kind != "pin" else j for j in rig.joints)
    base = replace(rig.base, support="spring", k_Nm_per_rad=0.0) if effect_locations(rig, "base_stiffness") \
        else rig.base
    masses = tuple(Mass(rig.point_of(loc) if loc != "base" else rig.point_of(f"{rig.links[0].name}@0"), 0.0,
                        0.0, name=f"slot@{loc}") for loc in effect_locations(rig, "joint_mass") + ["tip"])
    springs = tuple(Spring(rig.point_of(p), 0.0, "transverse", name=f"slot@{p}")
                    for p in effect_locations(rig, "grounded_spring"))
    members = tuple(replace(m, end_k_Nm_per_rad=0.0) for m in rig.members)
    return replace(rig, joints=joints, base=base, masses=rig.masses + masses, springs=rig.springs + springs,
                   members=members)


def _rows(system, rig: Rig, handle: Handle) -> np.ndarray | None:
    """Rows R with K_h (or M_h) = R^T R for rank-deficient handles; None for link scales."""
    what, _, loc = handle.name.partition("@")
    if what == "k" and loc == "base":
        return system.observe(f"{rig.links[0].name}@0", "rotation")[None]
    if what == "k" and loc in [j.name for j in rig.joints]:
        return system.joint_rotation(loc)[None]
    if what == "k":  # member end restraint: each pinned end's rotation relative to its host
        m = rig.members[[x.name for x in rig.members].index(loc)]
        ends = {"pin-pin": (0, 1), "clamped-pin": (1,), "clamped-clamped": ()}[m.ends]
        rows = []
        for e in ends:
            host = (m.start, m.end)[e]
            own = system.observe(f"{m.name}@{e}", "rotation")
            rows.append(own - (system.observe(str(host), "rotation") if host.link else 0.0))
        return np.array(rows).reshape(-1, system.n_dof)
    if what == "ks":
        return system.observe(loc, "transverse")[None]
    if what in ("m", "J"):
        at = f"{rig.links[0].name}@0" if loc == "base" else loc
        if loc == "sensors":
            return np.array([system.observe(str(s.at), q) for s in rig.sensors for q in ("x", "y")])
        if what == "m":
            return np.array([system.observe(at, "x"), system.observe(at, "y")])
        return system.observe(at, "rotation")[None]
    return None


@dataclass(frozen=True)
class PoseBasis:
    """One pose's global Ritz basis and the reduced nominal and handle matrices on it.

    ``groups[h]`` lists the basis columns that belong to handle ``h`` (columns ``0..n_modes-1`` are the
    nominal modes and belong to every candidate).
    """

    K0: np.ndarray            # [R, R] nominal reduced stiffness
    M0: np.ndarray            # [R, R] nominal reduced mass
    Kh: np.ndarray            # [H, R, R] per-handle d K / d h
    Mh: np.ndarray            # [H, R, R] per-handle d M / d h
    sensors: np.ndarray       # [n_sensors, R] sensor rows on the basis
    n_modes: int
    groups: tuple[tuple[int, ...], ...]


def _handle_matrices(sys0, sys2, rig: Rig, handles: Sequence[Handle]) -> list[tuple[np.ndarray, np.ndarray]]:
    """(dK/dh, dM/dh) in the full DOF space; rank-one parts as R^T R, link scales from the x2 assembly."""
    n = sys0.n_dof
    out = []
    for h in handles:
        what, _, loc = h.name.partition("@")
        rows = _rows(sys0, rig, h)
        if rows is not None:
            G = rows.T @ rows
            out.append((G, np.zeros((n, n))) if h.kind == "K" else (np.zeros((n, n)), G))
        else:
            s2 = sys2[loc]
            zero = np.zeros((n, n))
            out.append((s2.K - sys0.K, zero) if what == "EI" else (zero, s2.M - sys0.M))
    return out


def pose_basis(rig: Rig, handles: Sequence[Handle], pose: Mapping[str, float], n_measured: int) -> PoseBasis:
    """Assemble the super rig at ``pose`` and project the nominal model and every handle onto a Ritz basis."""
    srig = super_rig(rig)
    sys0 = assemble(srig, pose)
    def doubled(name: str) -> Rig:
        return replace(srig, links=tuple(
            replace(x, stiffness_scale=2 * x.stiffness_scale, mass_scale=2 * x.mass_scale) if x.name == name
            else x for x in srig.links))

    sys2 = {lk.name: assemble(doubled(lk.name), pose) for lk in rig.links}
    mats = _handle_matrices(sys0, sys2, srig, handles)
    # the super rig is assembled with every handle at 0 except the link scales (at 1)
    at = [1.0 if h.name.startswith(("EI@", "mu@")) else 0.0 for h in handles]
    K = sys0.K + sum((h.nominal - a) * dK for h, a, (dK, _) in zip(handles, at, mats, strict=True))
    M = sys0.M + sum((h.nominal - a) * dM for h, a, (_, dM) in zip(handles, at, mats, strict=True))
    n = K.shape[0]
    n_modes = min(n, n_measured + EXTRA_MODES)
    shift = 1e-6 * float(np.median(np.diag(K) / np.maximum(np.diag(M), 1e-300)))
    mu, vec = eigh(M, K + shift * M, subset_by_index=[n - n_modes, n - 1])
    phi = vec[:, ::-1] / np.sqrt(np.einsum("im,ij,jm->m", vec[:, ::-1], M, vec[:, ::-1]))
    fac = cho_factor(K + shift * M)
    cols, groups = [phi], []
    start = n_modes
    for h, (dK, dM) in zip(handles, mats, strict=True):
        rows = _rows(sys0, srig, h)
        load = rows.T if rows is not None else (dK if h.kind == "K" else dM) @ phi[:, :n_measured]
        c1 = cho_solve(fac, load)
        block = _orthonormal(np.hstack([c1, cho_solve(fac, M @ c1)]), phi, M)
        cols.append(block)
        groups.append(tuple(range(start, start + block.shape[1])))
        start += block.shape[1]
    V = np.hstack(cols)
    Kh = np.array([V.T @ dK @ V for dK, _ in mats])
    Mh = np.array([V.T @ dM @ V for _, dM in mats])
    return PoseBasis(V.T @ K @ V, V.T @ M @ V, Kh, Mh, sys0.sensor_matrix @ V, n_modes, tuple(groups))


def _orthonormal(C: np.ndarray, phi: np.ndarray, M: np.ndarray, tol: float = 1e-9) -> np.ndarray:
    """Columns of C made M-orthogonal to ``phi`` and M-orthonormal among themselves (rank-revealing)."""
    C = C - phi @ (phi.T @ (M @ C))
    G = C.T @ M @ C
    w, U = np.linalg.eigh(0.5 * (G + G.T))
    keep = w > tol * max(float(w.max()), 1e-300)
    return C @ (U[:, keep] / np.sqrt(w[keep]))


@dataclass(frozen=True)
class ReducedFamily:
    """A candidate's reduced model over configurations: A(h) = K0 + sum (h-h_nom) Kh, B likewise.

    Arrays are stacked over configurations and padded to a common size with decoupled stiff DOFs.
    """

    K0: np.ndarray            # [C, r, r]
    M0: np.ndarray            # [C, r, r]
    Kh: np.ndarray            # [C, H, r, r]
    Mh: np.ndarray            # [C, H, r, r]
    sensors: np.ndarray       # [C, n_sensors, r]
    nominal: np.ndarray       # [H]
    has_mass: bool


def reduce_family(bases: Sequence[PoseBasis], handle_idx: Sequence[int], nominal: np.ndarray
                  ) -> ReducedFamily:
    """Restrict every pose basis to the nominal modes plus the columns of ``handle_idx``; orthonormalise."""
    blocks = []
    for b in bases:
        cols = list(range(b.n_modes)) + [c for h in handle_idx for c in b.groups[h]]
        M0 = b.M0[np.ix_(cols, cols)]
        w, U = np.linalg.eigh(0.5 * (M0 + M0.T))
        keep = w > 1e-10 * w.max()
        T = U[:, keep] / np.sqrt(w[keep])
        sel = np.ix_(list(handle_idx), cols, cols)
        blocks.append((T.T @ b.K0[np.ix_(cols, cols)] @ T, np.eye(T.shape[1]), T.T @ b.Kh[sel] @ T,
                       T.T @ b.Mh[sel] @ T, b.sensors[:, cols] @ T))
    r = max(bl[0].shape[0] for bl in blocks)
    n_h = len(handle_idx)
    C = len(blocks)
    K0, M0 = np.zeros((C, r, r)), np.zeros((C, r, r))
    Kh, Mh = np.zeros((C, n_h, r, r)), np.zeros((C, n_h, r, r))
    S = np.zeros((C, blocks[0][4].shape[0], r))
    for c, (k0, m0, kh, mh, s) in enumerate(blocks):
        q = k0.shape[0]
        big = 1e6 * float(np.max(np.abs(np.diag(k0))))
        K0[c] = np.diag(np.full(r, big))
        M0[c] = np.eye(r)
        K0[c, :q, :q], M0[c, :q, :q], S[c, :, :q] = k0, m0, s
        if n_h:
            Kh[c, :, :q, :q], Mh[c, :, :q, :q] = kh, mh
    has_mass = bool(n_h and np.any(Mh != 0))
    return ReducedFamily(K0, M0, Kh, Mh, S, np.asarray(nominal, float), has_mass)


def solve_family(fam: ReducedFamily, h: np.ndarray, n_modes: int
                 ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Lowest modes of the family at handle values ``h`` [P, C, H].

    Returns eigenvalues ``lam`` [P, C, n] (rad^2/s^2), their sensitivities ``dlam`` [P, C, n, H] and the
    sensor shapes [P, C, n_sensors, n] (mass-normalised).
    """
    dh = h - fam.nominal
    A = fam.K0[None] + np.einsum("pch,chij->pcij", dh, fam.Kh)
    if fam.has_mass:
        B = fam.M0[None] + np.einsum("pch,chij->pcij", dh, fam.Mh)
        L = np.linalg.cholesky(B)
        Linv = np.linalg.inv(L)
        lam, Y = np.linalg.eigh(Linv @ A @ np.swapaxes(Linv, -1, -2))
        Z = np.swapaxes(Linv, -1, -2) @ Y[..., :n_modes]
    else:
        lam, Y = np.linalg.eigh(A)
        Z = Y[..., :n_modes]
    lam = lam[..., :n_modes]
    Zh = Z[:, :, None]                                                    # [P, C, 1, r, n]
    dK = np.sum(Zh * (fam.Kh[None] @ Zh), axis=-2)                         # [P, C, H, n]
    if fam.has_mass:
        dK = dK - lam[:, :, None, :] * np.sum(Zh * (fam.Mh[None] @ Zh), axis=-2)
    dK = np.swapaxes(dK, -1, -2)
    shapes = fam.sensors[None] @ Z
    return lam, dK, shapes


def lam_to_hz(lam: np.ndarray) -> np.ndarray:
    """Natural frequency [Hz] from an eigenvalue omega^2 (negative round-off clipped to 0)."""
    return np.sqrt(np.clip(lam, 0.0, None)) / (2 * math.pi)
