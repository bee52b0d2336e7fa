"""Parameter-linear FE models for the gap diagnosis: K(h) = K0 + sum h_i K_i, M(h) = M0 + sum h_i M_i.

Every effect of the registry (models/effects.py) enters the frame model linearly through a few
*handles* (a joint spring k, an added mass m or inertia J, a grounded spring k, a link's stiffness or mass
scale), which its entry lists with their matrices.  All effect slots are built once into one *super rig*
whose DOF layout holds them all (spring joints, a base spring, zero masses and zero springs at every
candidate point), so each handle's matrices are exact differences in one layout: rank-deficient rows from
``FrameSystem.observe``/``joint_rotation`` for springs and point masses, one extra assembly per link for
the link scales.  A rigid joint or clamped base is the same layout with a stiff spring
(``models.effects.RIGID_FACTOR`` EI/L, relative frequency error < 1e-6).

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
from dataclasses import dataclass

import numpy as np
from scipy.linalg import cho_factor, cho_solve, eigh

from flexmodal.compare.errors import CompareError
from flexmodal.models.effects import REGISTRY, Handle
from flexmodal.models.frame import assemble
from flexmodal.models.rig import Rig

EXTRA_MODES = 4
"""Nominal modes kept in the Ritz basis beyond the measured ones."""


def handles_for(rig: Rig) -> list[Handle]:
    """All handles the registered effects (models/effects.py) can move on ``rig``, in registry order; a
    handle two effects share (e.g. ``k@<joint>``) is listed once."""
    out: dict[str, Handle] = {}
    for effect in REGISTRY.values():
        for h in effect.handles(rig):
            out.setdefault(h.name, h)
    return list(out.values())


def super_rig(rig: Rig) -> Rig:
    """The rig with every effect slot present at its handles' ``slot`` values (spring joints/base with
    k = 0, zero masses and springs, link scales as they are)."""
    srig = rig
    for effect in REGISTRY.values():
        srig = effect.slots(rig, srig)
    return srig


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


def _handle_matrices(sys0, srig: Rig, pose: Mapping[str, float], handles: Sequence[Handle]
                     ) -> tuple[list[tuple[np.ndarray, np.ndarray]], list[np.ndarray | None]]:
    """(dK/dh, dM/dh) in the full DOF space and the rows R of each handle (None for a unit change):
    rank-deficient parts as R^T R, the others as the assembly after the effect's unit change minus the
    super rig's (one assembly per distinct change, e.g. one per link for its stiffness and mass scales)."""
    n = sys0.n_dof
    zero = np.zeros((n, n))
    changed: dict[tuple, object] = {}
    mats, all_rows = [], []
    for h in handles:
        effect = REGISTRY[h.effect]
        rows = effect.rows(sys0, srig, h)
        all_rows.append(rows)
        if rows is not None:
            G = rows.T @ rows
            mats.append((G, zero) if h.kind == "K" else (zero, G))
            continue
        if effect.unit_change is None:
            raise CompareError(f"effect {h.effect!r}: handle {h.name!r} has neither rows nor a unit change")
        key = (effect.unit_change, h.location)
        if key not in changed:
            changed[key] = assemble(effect.unit_change(srig, h.location), pose)
        s2 = changed[key]
        mats.append((s2.K - sys0.K, zero) if h.kind == "K" else (zero, s2.M - sys0.M))
    return mats, all_rows


def pose_basis(rig: Rig, handles: Sequence[Handle], pose: Mapping[str, float], n_measured: int) -> PoseBasis:
    """Assemble the super rig at ``pose`` and project the nominal model and every handle onto a Ritz basis."""
    srig = super_rig(rig)
    sys0 = assemble(srig, pose)
    mats, all_rows = _handle_matrices(sys0, srig, pose, handles)
    # the super rig is assembled with every handle at its slot value
    K = sys0.K + sum((h.nominal - h.slot) * dK for h, (dK, _) in zip(handles, mats, strict=True))
    M = sys0.M + sum((h.nominal - h.slot) * dM for h, (_, dM) in zip(handles, mats, strict=True))
    n = K.shape[0]
    n_modes = min(n, n_measured + EXTRA_MODES)
    shift = 1e-6 * float(np.median(np.diag(K) / np.maximum(np.diag(M), 1e-300)))
    mu, vec = eigh(M, K + shift * M, subset_by_index=[n - n_modes, n - 1])
    phi = vec[:, ::-1] / np.sqrt(np.einsum("im,ij,jm->m", vec[:, ::-1], M, vec[:, ::-1]))
    fac = cho_factor(K + shift * M)
    cols, groups = [phi], []
    start = n_modes
    for h, (dK, dM), rows in zip(handles, mats, all_rows, strict=True):
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
