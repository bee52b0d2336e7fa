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
    """Restrict every pose basis to the nominal modes plus the columns of ``handle_idx``; orthonormalise.

    Configurations whose bases have the same size and the same columns for these handles (and a pose
    basis object that repeats) are reduced together, one batched ``eigh`` and product per group: the
    same per-matrix LAPACK and BLAS calls as one configuration at a time, so the same numbers bit for bit
    (``benchmarks/diagnosis_speed.py``).
    """
    handle_idx = list(handle_idx)
    n_h, C = len(handle_idx), len(bases)
    groups: dict[tuple, list[int]] = {}
    for c, b in enumerate(bases):
        cols = tuple(range(b.n_modes)) + tuple(col for h in handle_idx for col in b.groups[h])
        groups.setdefault((b.K0.shape[0], cols), []).append(c)
    reduced = []                              # (configurations, k0, kh, mh, s) per group of equal size
    for (_, cols), members in groups.items():
        distinct = list({id(bases[c]): bases[c] for c in members}.values())
        where = {id(b): i for i, b in enumerate(distinct)}
        of = np.array([where[id(bases[c])] for c in members])
        ix = np.array(cols)
        sub, rows = ix[:, None], ix[None, :]
        hix = np.array(handle_idx, int)[:, None, None]
        M0 = np.stack([b.M0[sub, rows] for b in distinct])
        K0 = np.stack([b.K0[sub, rows] for b in distinct])
        Kh = np.stack([b.Kh[hix, sub[None], rows[None]] for b in distinct])
        Mh = np.stack([b.Mh[hix, sub[None], rows[None]] for b in distinct])
        S = np.stack([b.sensors[:, ix] for b in distinct])
        w, U = np.linalg.eigh(0.5 * (M0 + np.swapaxes(M0, -1, -2)))
        keep = w > 1e-10 * w.max(axis=1, keepdims=True)
        patterns: dict[bytes, list[int]] = {}
        for i, k in enumerate(keep):
            patterns.setdefault(k.tobytes(), []).append(i)
        back = np.full(len(distinct), -1)
        for rows_of in patterns.values():
            sel = np.array(rows_of)
            k = keep[sel[0]]
            T = U[sel][..., k] / np.sqrt(w[sel][:, k])[:, None, :]
            Tt = np.swapaxes(T, -1, -2)
            out = (Tt @ K0[sel] @ T, Tt[:, None] @ Kh[sel] @ T[:, None], Tt[:, None] @ Mh[sel] @ T[:, None],
                   S[sel] @ T)
            back[:] = -1
            back[sel] = np.arange(len(sel))
            mine = back[of] >= 0
            reduced.append((np.array(members)[mine], *(a[back[of][mine]] for a in out)))
    r = max(red[1].shape[-1] for red in reduced)
    n_s = reduced[0][4].shape[1]
    K0, M0 = np.zeros((C, r, r)), np.repeat(np.eye(r)[None], C, axis=0)
    Kh, Mh = np.zeros((C, n_h, r, r)), np.zeros((C, n_h, r, r))
    S = np.zeros((C, n_s, r))
    diag = np.arange(r)
    for cs, k0, kh, mh, s in reduced:
        q = k0.shape[-1]
        big = 1e6 * np.max(np.abs(np.diagonal(k0, axis1=1, axis2=2)), axis=1)
        K0[cs[:, None], diag, diag] = big[:, None]
        K0[cs, :q, :q], S[cs, :, :q] = k0, s
        if n_h:
            Kh[cs, :, :q, :q], Mh[cs, :, :q, :q] = kh, mh
    has_mass = bool(n_h and np.any(Mh != 0))
    return ReducedFamily(K0, M0, Kh, Mh, S, np.asarray(nominal, float), has_mass)


CHUNK_BYTES = 4 << 20
"""Working-set size of one batch of ``solve_family`` (a few MB: the temporaries stay in cache and are
re-used by the allocator instead of being mapped afresh, which cost as much system as user time)."""


def solve_family(fam: ReducedFamily, h: np.ndarray, n_modes: int, gradients: bool = True
                 ) -> tuple[np.ndarray, np.ndarray | None, np.ndarray]:
    """Lowest modes of the family at handle values ``h`` [P, C, H].

    Returns eigenvalues ``lam`` [P, C, n] (rad^2/s^2), their sensitivities ``dlam`` [P, C, n, H] (None
    when ``gradients`` is false) and the sensor shapes [P, C, n_sensors, n] (mass-normalised).  The
    points are solved in slices of about ``CHUNK_BYTES``; every matrix is solved on its own, so the
    slicing changes no number.
    """
    P, C = h.shape[:2]
    r = fam.K0.shape[-1]
    per_point = 8 * C * r * max(2 * r, (fam.Kh.shape[1] + 1) * n_modes)
    step = max(1, CHUNK_BYTES // per_point)
    parts = [_solve_slice(fam, h[p:p + step], n_modes, gradients) for p in range(0, max(P, 1), step)]
    if len(parts) == 1:
        return parts[0]
    lam, dlam, shapes = zip(*parts, strict=True)
    return (np.concatenate(lam), np.concatenate(dlam) if gradients else None, np.concatenate(shapes))


def _solve_slice(fam: ReducedFamily, h: np.ndarray, n_modes: int, gradients: bool
                 ) -> tuple[np.ndarray, np.ndarray | None, np.ndarray]:
    """``solve_family`` on one slice of points."""
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
    shapes = fam.sensors[None] @ Z
    if not gradients:
        return lam, None, shapes
    Zh = Z[:, :, None]                                                    # [P, C, 1, r, n]
    dK = np.sum(Zh * (fam.Kh[None] @ Zh), axis=-2)                         # [P, C, H, n]
    if fam.has_mass:
        dK = dK - lam[:, :, None, :] * np.sum(Zh * (fam.Mh[None] @ Zh), axis=-2)
    return lam, np.swapaxes(dK, -1, -2), shapes


def lam_to_hz(lam: np.ndarray) -> np.ndarray:
    """Natural frequency [Hz] from an eigenvalue omega^2 (negative round-off clipped to 0)."""
    return np.sqrt(np.clip(lam, 0.0, None)) / (2 * math.pi)
