"""Planar Euler-Bernoulli (opt-in: Timoshenko) frame finite elements for a rig (docs/formats.md) at a pose.

Each link (and each extra member) is a chain of two-node frame elements with three DOFs per node
(global ``x``, ``y`` translation in m and rotation in rad): axial bar plus Hermite-cubic bending,
consistent mass with rotary inertia (Przemieniecki 1968, ch. 11; Cook et al. 2002 §11.3) or an
HRZ-lumped diagonal mass (translations mL/2, rotations mL^3/78 + rho*I*L/2, Hinton-Rock-Zienkiewicz 1976).
Shear deformation is off by default: a section with ``shear`` (the rig's ``shear_coefficient``) makes its
elements Timoshenko beams (Friedman & Kosmatka 1993), for thick or thin-walled links whose shear
flexibility matters; the keyword ``shear=Shear(kappa, nu)`` does so for every element at once.

Connections are made by sharing DOFs (exact elimination, never penalties): a rigid joint shares all
three DOFs; a pin or spring joint shares the translations and gives the child its own rotation, a
torsional spring ``k`` [N m/rad] linking the two rotations (``k = 0`` is a pin).  The child's rotation
DOF of a spring is then replaced by the *relative* rotation (theta_child - theta_parent), so ``k`` sits
alone on a diagonal: a spring approaching rigid never subtracts huge numbers (no lost digits), and the
result tends smoothly to the rigid joint.  Member ends share the link point's translations; a clamped
end also its rotation, a pinned end gets its own rotation plus ``end_k_Nm_per_rad`` to the link (again
as a relative rotation).  Base: clamped fixes the first node, pinned frees its rotation, spring adds
``base.k_Nm_per_rad`` to ground, free frees all three.  Pose-independent data (mesh, DOF maps, local
element matrices, sensor interpolation) are cached per rig; ``assemble_many`` vectorises the element
transforms and the scatter over many poses.

The eigenproblem is solved in inverse form, ``M phi = mu (K + sigma M) phi`` with ``mu = 1/(omega^2 +
sigma)`` (a small shift, Bathe 2014 §11.2): the wanted low modes are the *largest* ``mu``, which LAPACK
returns to full relative precision however stiff a spring is, and rigid-body modes need no special case.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass
from functools import lru_cache

import numpy as np
from scipy.linalg import LinAlgError, eigh

from flexmodal.checked_io.text import available_memory_bytes
from flexmodal.contract.mac import largest_positive
from flexmodal.models.errors import ModelError
from flexmodal.models.rig import Point, Rig, Section, Shear

DEFAULT_ELEMENTS = 10
DENSE_COPIES = 6  # dense n x n float arrays alive per pose while assembling and solving (K, M, sums, eigh)
QUANTITIES = ("transverse", "axial", "x", "y", "rotation", "curvature")
_SNAP = 0.3  # an attachment point within this fraction of an element of a grid node moves that node


# ---------------------------------------------------------------------------------------------
# element matrices


_AX, _BD = np.array([0, 3]), np.array([1, 2, 4, 5])
# Hermite bending matrices in (v1, theta1, v2, theta2): entry ij carries L^(p_i + p_j), p = (0, 1, 0, 1)
_KB = np.array([[12, 6, -12, 6], [6, 4, -6, 2], [-12, -6, 12, -6], [6, 2, -6, 4]], float)
_MB = np.array([[156, 22, 54, -13], [22, 4, 13, -3], [54, 13, 156, -22], [-13, -3, -22, 4]], float)
_MR = np.array([[36, 3, -36, 3], [3, 4, -3, -1], [-36, -3, 36, -3], [3, -1, -3, 4]], float)
# Timoshenko terms in phi = 12 EI / (kappa G A L^2) (Friedman & Kosmatka 1993): stiffness
# EI/(L^3 (1+phi)) (_KB + phi _KS); translational mass mL/(420 (1+phi)^2) (_MB + phi _MB1 + phi^2 _MB2);
# rotary mass rho I/(30 L (1+phi)^2) (_MR + phi _MR1 + phi^2 _MR2)
_KS = np.array([[0, 0, 0, 0], [0, 1, 0, -1], [0, 0, 0, 0], [0, -1, 0, 1]], float)
_MB1 = np.array([[294, 38.5, 126, -31.5], [38.5, 7, 31.5, -7], [126, 31.5, 294, -38.5],
                 [-31.5, -7, -38.5, 7]])
_MB2 = np.array([[140, 17.5, 70, -17.5], [17.5, 3.5, 17.5, -3.5], [70, 17.5, 140, -17.5],
                 [-17.5, -3.5, -17.5, 3.5]])
_MR1 = np.array([[0, -15, 0, -15], [-15, 5, 15, -5], [0, 15, 0, 15], [-15, -5, 15, 5]], float)
_MR2 = np.array([[0, 0, 0, 0], [0, 10, 0, 5], [0, 0, 0, 0], [0, 5, 0, 10]], float)
_BAR_K, _BAR_M = np.array([[1.0, -1.0], [-1.0, 1.0]]), np.array([[2.0, 1.0], [1.0, 2.0]])


def shear_phi(shear_rigidity_N: np.ndarray, EI_Nm2: np.ndarray, length_m: np.ndarray) -> np.ndarray:
    """Timoshenko shear parameter phi = 12 EI / (kappa G A L^2) [-] of elements of length ``length_m`` [m]
    and shear rigidity kappa G A ``shear_rigidity_N`` [N] (Friedman & Kosmatka 1993); an infinite
    rigidity gives exactly 0 (the Euler-Bernoulli element).

    Examples
    --------
    >>> float(shear_phi(Shear(0.5, 0.25).rigidity_N(np.array([2.0])), np.array([1.0]), np.array([1.0]))[0])
    30.0
    >>> float(shear_phi(np.array([np.inf]), np.array([1.0]), np.array([1.0]))[0])
    0.0
    """
    L = np.asarray(length_m, float)
    return 12.0 * np.asarray(EI_Nm2, float) / (np.asarray(shear_rigidity_N, float) * L**2)


def element_matrices(length_m: np.ndarray, EA_N: np.ndarray, EI_Nm2: np.ndarray, mass_per_m_kg: np.ndarray,
                     rotary_per_m_kgm: np.ndarray, lumped: bool = False, *,
                     shear_rigidity_N: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Local stiffness and mass matrices [n_el, 6, 6] of planar frame elements.

    DOF order per element: (u1, v1, theta1, u2, v2, theta2), u axial and v transverse [m], theta [rad].
    Without ``shear_rigidity_N`` (kappa G A [N] per element; the default None and an infinite value alike)
    the bending part is the Euler-Bernoulli Hermite element with consistent translational and rotary
    mass (Przemieniecki 1968, ch. 5 and 11).  With a finite one it is the two-node
    Timoshenko element built on the exact static interpolation (Przemieniecki 1968 ch. 5 and 11; Friedman &
    Kosmatka 1993, Comput. Struct. 47(3), 473-481): shear-flexible stiffness, phi = 12 EI / (kappa G A L^2),
    and the matching consistent mass, translational and rotary; theta is then the section rotation.  phi = 0
    gives the Euler-Bernoulli matrices exactly (same arithmetic).  HRZ-lumped mass (``lumped``) ignores phi.
    """
    L = np.asarray(length_m, float)
    n = L.size
    k = np.zeros((n, 6, 6))
    m = np.zeros((n, 6, 6))
    powers = L[:, None] ** np.array([0, 1, 0, 1])
    Lp = powers[:, :, None] * powers[:, None, :]
    phi = np.zeros(L.shape) if shear_rigidity_N is None else shear_phi(shear_rigidity_N, EI_Nm2, L)
    ph, ph2 = phi[:, None, None], (phi**2)[:, None, None]
    k[:, _AX[:, None], _AX] = (EA_N / L)[:, None, None] * _BAR_K
    k[:, _BD[:, None], _BD] = (EI_Nm2 / L**3 / (1.0 + phi))[:, None, None] * (_KB + ph * _KS) * Lp
    mu, rot = np.asarray(mass_per_m_kg, float), np.asarray(rotary_per_m_kgm, float)
    if lumped:
        m[:, range(6), range(6)] = np.stack([mu * L / 2, mu * L / 2, mu * L**3 / 78 + rot * L / 2] * 2, -1)
        return k, m
    m[:, _AX[:, None], _AX] = (mu * L / 6)[:, None, None] * _BAR_M
    bending = ((mu * L / 420 / (1.0 + phi) ** 2)[:, None, None] * (_MB + ph * _MB1 + ph2 * _MB2)
               + (rot / (30 * L) / (1.0 + phi) ** 2)[:, None, None] * (_MR + ph * _MR1 + ph2 * _MR2))
    m[:, _BD[:, None], _BD] = bending * Lp
    return k, m


def _local_rows(stations: np.ndarray, frac: float, quantity: str, length_m: float,
                phi: np.ndarray | None = None) -> list[tuple[int, np.ndarray]]:
    """(element within the body, local 6-vector) pairs interpolating a local quantity at ``frac``.

    Hermite cubics for transverse/rotation/curvature, linear for axial (Cook et al. 2002 §2.4); with the
    elements' Timoshenko parameters ``phi`` [-] (one per element of the body) the interdependent
    interpolation of the shear-flexible element (Friedman & Kosmatka 1993), whose rotation is the
    section's and whose curvature is the rotation's derivative; both reduce to the Hermite cubics at
    phi = 0.  At a node between two elements the curvature is the average of both sides.
    """
    lo = max(int(np.searchsorted(stations, frac - 1e-12)) - 1, 0)
    hits = [e for e in (lo, lo + 1)
            if e < len(stations) - 1 and stations[e] - 1e-12 <= frac <= stations[e + 1] + 1e-12]
    if quantity != "curvature":
        hits = hits[:1]
    out = []
    for e in hits:
        le = (stations[e + 1] - stations[e]) * length_m
        x = (frac - stations[e]) / (stations[e + 1] - stations[e])
        x2, x3 = x * x, x**3
        if quantity == "axial":
            out.append((e, np.array([1 - x, 0, 0, x, 0, 0])))
            continue
        f = 0.0 if phi is None else float(phi[e])
        if quantity == "transverse":
            h = [1 - 3 * x2 + 2 * x3 + f * (1 - x), le * (x - 2 * x2 + x3 + f * (x - x2) / 2),
                 3 * x2 - 2 * x3 + f * x, le * (x3 - x2 - f * (x - x2) / 2)]
        elif quantity == "rotation":
            h = [(-6 * x + 6 * x2) / le, 1 - 4 * x + 3 * x2 + f * (1 - x), (6 * x - 6 * x2) / le,
                 3 * x2 - 2 * x + f * x]
        else:
            h = [(-6 + 12 * x) / le**2, (-4 + 6 * x - f) / le, (6 - 12 * x) / le**2, (-2 + 6 * x + f) / le]
        out.append((e, np.array([0, h[0], h[1], 0, h[2], h[3]]) / ((1 + f) * len(hits))))
    return out


def _rotations(angle_rad: np.ndarray) -> np.ndarray:
    """Element transformation T [n_el, 6, 6] with local = T @ global."""
    c, s = np.cos(angle_rad), np.sin(angle_rad)
    T = np.zeros((angle_rad.size, 6, 6))
    for o in (0, 3):
        T[:, o, o], T[:, o, o + 1], T[:, o + 1, o], T[:, o + 1, o + 1] = c, s, -s, c
        T[:, o + 2, o + 2] = 1.0
    return T


# ---------------------------------------------------------------------------------------------
# topology: everything that does not depend on the pose (cached per rig)


@dataclass(frozen=True, eq=False)
class _Body:
    """A discretised link or member: node stations as fractions of its length, its elements."""

    name: str
    is_member: bool
    stations: np.ndarray          # [n_nodes] fractions in [0, 1]
    node_dofs: np.ndarray         # [n_nodes, 3] DOF index (x, y, rotation); n_dof = fixed
    first_element: int

    def node(self, fraction: float) -> np.ndarray:
        """DOFs (x, y, rotation) of the node nearest ``fraction`` (every attachment point is a node)."""
        return self.node_dofs[int(np.argmin(np.abs(self.stations - fraction)))]


@dataclass(frozen=True, eq=False)
class _Topology:
    n_dof: int
    bodies: tuple[_Body, ...]
    elem_body: np.ndarray         # [n_el] body index
    elem_dofs: np.ndarray         # [n_el, 6]
    elem_frac: np.ndarray         # [n_el, 2] start/end station fractions
    EA: np.ndarray
    EI: np.ndarray
    mu: np.ndarray
    rot: np.ndarray
    GA: np.ndarray                # [n_el] shear rigidity kappa G A [N]; inf: Euler-Bernoulli
    rot_springs: np.ndarray       # [n, 2] (reference, relative) rotation DOFs; relative = n_dof: to ground
    rot_spring_k: np.ndarray      # [n] N m/rad
    lumped: bool
    k_loc: np.ndarray             # [n_el, 6, 6] local matrices (member rows are redone per pose)
    m_loc: np.ndarray
    elem_is_member: np.ndarray    # [n_el] bool
    sensor_elems: np.ndarray      # [n_pieces] element index of each sensor interpolation piece
    sensor_vecs: np.ndarray       # [n_pieces, 6] local interpolation vectors
    sensor_of_piece: np.ndarray   # [n_pieces] sensor index


def _stations(n_el: int, required: Iterable[float]) -> np.ndarray:
    """Uniform stations with each required fraction made a node (snapping a nearby grid node)."""
    grid = list(np.linspace(0.0, 1.0, n_el + 1))
    locked = [True] + [False] * (n_el - 1) + [True]
    for f in sorted(set(required)):
        j = int(np.argmin(np.abs(np.array(grid) - f)))
        if abs(grid[j] - f) <= 1e-12 or (not locked[j] and abs(grid[j] - f) < _SNAP / n_el):
            grid[j], locked[j] = f, True
        else:
            at = int(np.searchsorted(grid, f))
            grid.insert(at, f)
            locked.insert(at, True)
    return np.array(grid)


def _required_fractions(rig: Rig) -> dict[str, list[float]]:
    req: dict[str, list[float]] = {lk.name: [] for lk in rig.links}
    points: list[Point] = [s.at for s in rig.sensors] + [m.at for m in rig.masses]
    points += [s.at for s in rig.springs]
    points += [p for mb in rig.members for p in (mb.start, mb.end)]
    for p in points:
        if p.link is not None:
            req[p.link].append(p.fraction)
    for lk in rig.links:
        for seg in lk.segments:
            req[lk.name] += [seg.from_m / lk.length_m, min(seg.to_m / lk.length_m, 1.0)]
    return req


def _scaled(section: Section, stiffness_scale: float, mass_scale: float
            ) -> tuple[float, float, float, float, float]:
    """EA [N], EI [N m^2], mass [kg/m], rotary inertia [kg m] and shear rigidity kappa G A [N] (infinite:
    Euler-Bernoulli) of ``section`` under a link's scales (kappa G A scales with E, as EA does)."""
    EA = section.EA_N * stiffness_scale
    GA = math.inf if section.shear is None else float(section.shear.rigidity_N(EA))
    return (EA, section.EI_Nm2 * stiffness_scale, section.mass_per_m_kg * mass_scale,
            section.rotary_inertia_per_m_kgm * mass_scale, GA)


@lru_cache(maxsize=64)
def _topology(rig: Rig, elements: int | None, lumped: bool, shear: Shear | None = None) -> _Topology:
    counter = iter(range(1 << 30))
    FIXED = -1  # replaced by n_dof at the end
    joints = {j.child: j for j in rig.joints}
    link_order = {lk.name: i for i, lk in enumerate(rig.links)}  # links are the first bodies, in order
    req = _required_fractions(rig)
    bodies: list[_Body] = []
    el_body, el_dofs, el_frac, props = [], [], [], []
    springs: list[tuple[int, int, float]] = []

    def add_body(name: str, is_member: bool, st: np.ndarray, dofs: np.ndarray, sect_at, scales) -> None:
        start = len(el_dofs)
        for e in range(len(st) - 1):
            el_body.append(len(bodies))
            el_dofs.append(np.concatenate([dofs[e], dofs[e + 1]]))
            el_frac.append((st[e], st[e + 1]))
            props.append(_scaled(sect_at(0.5 * (st[e] + st[e + 1])), *scales))
        bodies.append(_Body(name, is_member, st, dofs, start))

    for i, lk in enumerate(rig.links):
        n_el = elements or lk.elements or DEFAULT_ELEMENTS
        st = _stations(n_el, req[lk.name])
        dofs = np.array([[next(counter) for _ in range(3)] for _ in st])
        if i == 0:
            support = rig.base.support
            if support != "free":
                dofs[0, :2] = FIXED
            if support == "clamped":
                dofs[0, 2] = FIXED
            if support == "spring":
                springs.append((int(dofs[0, 2]), FIXED, float(rig.base.k_Nm_per_rad or 0.0)))
        else:
            joint = joints[lk.name]
            parent = bodies[link_order[joint.parent]]
            dofs[0, :2] = parent.node_dofs[-1, :2]
            if joint.kind == "rigid":
                dofs[0, 2] = parent.node_dofs[-1, 2]
            elif joint.kind == "spring" and joint.k_Nm_per_rad:
                springs.append((int(parent.node_dofs[-1, 2]), int(dofs[0, 2]), float(joint.k_Nm_per_rad)))
        add_body(lk.name, False, st, dofs, lambda f, lk=lk: lk.section_at(f * lk.length_m),
                 (lk.stiffness_scale, lk.mass_scale))

    for mb in rig.members:
        n_el = elements or mb.elements or DEFAULT_ELEMENTS
        st = np.linspace(0.0, 1.0, n_el + 1)
        dofs = np.array([[next(counter) for _ in range(3)] for _ in st])
        clamped = {"pin-pin": (False, False), "clamped-pin": (True, False), "clamped-clamped": (True, True)}
        for end, p, is_clamped in ((0, mb.start, clamped[mb.ends][0]), (-1, mb.end, clamped[mb.ends][1])):
            host = bodies[link_order[p.link]].node(p.fraction) if p.link is not None else np.full(3, FIXED)
            dofs[end, :2] = host[:2]
            if is_clamped:
                dofs[end, 2] = host[2]
            elif mb.end_k_Nm_per_rad > 0:
                pair = (int(host[2]), int(dofs[end, 2])) if host[2] != FIXED else (int(dofs[end, 2]), FIXED)
                springs.append((*pair, mb.end_k_Nm_per_rad))
        add_body(mb.name, True, st, dofs, lambda f, mb=mb: mb.section, (1.0, 1.0))

    # renumber the DOFs actually used, contiguously; fixed -> n_dof
    spring_dofs = np.array([(a, b) for a, b, _ in springs], int).reshape(-1, 2)
    all_dofs = np.concatenate([b.node_dofs.ravel() for b in bodies] + [spring_dofs.ravel()])
    used = np.unique(all_dofs[all_dofs >= 0])
    n_dof = used.size
    remap = np.full(int(used.max()) + 2 if used.size else 1, n_dof)
    remap[used] = np.arange(n_dof)

    def rn(a: np.ndarray) -> np.ndarray:
        a = np.asarray(a, int)
        return np.where(a >= 0, remap[np.clip(a, 0, None)], n_dof)

    bodies = [_Body(b.name, b.is_member, b.stations, rn(b.node_dofs), b.first_element) for b in bodies]
    p = np.array(props, float)
    el_body, el_frac = np.array(el_body), np.array(el_frac)
    is_member = np.array([bodies[b].is_member for b in el_body])
    length = np.array([1.0 if m else rig.links[b].length_m for b, m in zip(el_body, is_member, strict=True)])
    EA, EI, mu, rot, GA = p.T
    if shear is not None:   # one kappa and nu for every element, in place of the sections' own
        GA = shear.rigidity_N(EA)
    k_loc, m_loc = element_matrices((el_frac[:, 1] - el_frac[:, 0]) * length, EA, EI, mu, rot, lumped,
                                    shear_rigidity_N=GA)
    spring_k = np.array([k for *_, k in springs], float)
    phi = shear_phi(GA, EI, (el_frac[:, 1] - el_frac[:, 0]) * length)
    pieces = [(k, bodies[link_order[sn.at.link]].first_element + e, v)
              for k, sn in enumerate(rig.sensors)
              for e, v in _local_rows(bodies[link_order[sn.at.link]].stations, sn.at.fraction, sn.direction,
                                      rig.links[link_order[sn.at.link]].length_m,
                                      phi[bodies[link_order[sn.at.link]].first_element:])]
    piece_sensor = np.array([k for k, _, _ in pieces], int)
    piece_elem = np.array([e for _, e, _ in pieces], int)
    piece_vecs = np.array([v for *_, v in pieces]).reshape(-1, 6)
    return _Topology(n_dof, tuple(bodies), el_body, rn(np.array(el_dofs)), el_frac, EA, EI, mu, rot,
                     GA, rn(spring_dofs), spring_k, lumped, k_loc, m_loc, is_member, piece_elem,
                     piece_vecs, piece_sensor)


# ---------------------------------------------------------------------------------------------
# pose geometry


def link_geometry(rig: Rig, pose: Mapping[str, float]) -> tuple[np.ndarray, np.ndarray]:
    """Absolute link angles [rad] and link start points [n_links, 2] (m) at ``pose`` (degrees)."""
    base = rig.base.angle
    angle = math.radians(float(pose[base]) if base else rig.base.angle_deg)
    joints = {j.child: j for j in rig.joints}
    angles, starts = [], []
    xy = np.zeros(2)
    for i, lk in enumerate(rig.links):
        if i:
            j = joints[lk.name]
            angle += math.radians(float(pose[j.angle]) if j.angle else j.angle_deg)
        angles.append(angle)
        starts.append(xy.copy())
        xy = xy + lk.length_m * np.array([math.cos(angle), math.sin(angle)])
    return np.array(angles), np.array(starts)


def _point_xy(rig: Rig, p: Point, angles: np.ndarray, starts: np.ndarray) -> np.ndarray:
    if p.link is None:
        return np.array(p.ground_xy_m, float)
    i = [lk.name for lk in rig.links].index(p.link)
    s = p.fraction * rig.links[i].length_m
    return starts[i] + s * np.array([math.cos(angles[i]), math.sin(angles[i])])


def _body_geometry(rig: Rig, pose: Mapping[str, float]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Per body: angle [rad], length [m], start point [2]."""
    angles, starts = link_geometry(rig, pose)
    b_ang, b_len, b_start = list(angles), [lk.length_m for lk in rig.links], list(starts)
    for mb in rig.members:
        a, b = _point_xy(rig, mb.start, angles, starts), _point_xy(rig, mb.end, angles, starts)
        d = b - a
        length = float(np.hypot(*d))
        if length < 1e-9:
            raise ModelError(f"{rig.source}: member {mb.name!r} has zero length at this pose")
        b_ang.append(math.atan2(d[1], d[0]))
        b_len.append(length)
        b_start.append(a)
    return np.array(b_ang), np.array(b_len), np.array(b_start)


# ---------------------------------------------------------------------------------------------
# the assembled system


@dataclass(frozen=True, eq=False)
class FrameSystem:
    """Stiffness ``K`` [N/m, N, N m] and mass ``M`` over the free DOFs, sensors and observation rows."""

    K: np.ndarray
    M: np.ndarray
    sensor_matrix: np.ndarray        # [n_sensors, n_dof] sensor displacement along its direction
    sensor_names: tuple[str, ...]
    node_xy_m: np.ndarray            # [n_nodes, 2] coordinates of every body node (members included)
    rig: Rig
    _topo: _Topology
    _body_angle: np.ndarray
    _body_length: np.ndarray

    @property
    def n_dof(self) -> int:
        return self.K.shape[0]

    def _resolve(self, at: str) -> tuple[int, float]:
        head, sep, tail = at.partition("@")
        names = [b.name for b in self._topo.bodies]
        if sep and head in names and self._topo.bodies[names.index(head)].is_member:
            frac = float(tail)
            if not 0.0 <= frac <= 1.0:
                raise ModelError(f"{self.rig.source}: {at!r}: the fraction must lie in [0, 1]")
            return names.index(head), frac
        p = self.rig.point_of(at)
        if p.link is None:
            raise ModelError(f"{self.rig.source}: {at!r} is a ground point; nothing moves there")
        return names.index(p.link), p.fraction

    def observe(self, at: str, quantity: str = "transverse") -> np.ndarray:
        """Row ``r`` [n_dof] such that ``r @ u`` is ``quantity`` at point ``at`` for DOF vector ``u``.

        ``at``: ``<link>@<fraction>``, ``<member>@<fraction>``, ``tip`` or a joint name.  ``quantity``:
        ``transverse``/``axial`` (m, along the body's local normal/axis), ``x``/``y`` (m, global),
        ``rotation`` (rad) or ``curvature`` (1/m; bending strain = curvature * depth/2).  Values come from
        the element's own shape functions (Hermite cubic bending, linear axial; with ``shear`` the
        Timoshenko element's interdependent interpolation, rotation = the section's); curvature at a node
        between two elements is their average.
        """
        if quantity not in QUANTITIES:
            raise ModelError(f"unknown quantity {quantity!r} (expected one of {', '.join(QUANTITIES)})")
        return self._row(*self._resolve(at), quantity)

    def _row(self, bi: int, frac: float, quantity: str) -> np.ndarray:
        topo, body = self._topo, self._topo.bodies[bi]
        angle = self._body_angle[bi]
        c, s = math.cos(angle), math.sin(angle)
        T = _rotations(np.array([angle]))[0]
        row = np.zeros(self.n_dof + 1)
        els = slice(body.first_element, body.first_element + len(body.stations) - 1)
        le = np.diff(body.stations) * self._body_length[bi]
        phi = shear_phi(topo.GA[els], topo.EI[els], le)
        if quantity in ("x", "y"):
            pieces = [(e, (c * a - s * t) if quantity == "x" else (s * a + c * t)) for (e, a), (_, t) in
                      zip(_local_rows(body.stations, frac, "axial", self._body_length[bi]),
                          _local_rows(body.stations, frac, "transverse", self._body_length[bi], phi),
                          strict=True)]
        else:
            pieces = _local_rows(body.stations, frac, quantity, self._body_length[bi], phi)
        for e, local in pieces:
            np.add.at(row, topo.elem_dofs[body.first_element + e], local @ T)
        return self._relative(row)[:-1]

    def _relative(self, row: np.ndarray) -> np.ndarray:
        """Apply ``assemble``'s change of variables (spring DOFs become relative rotations) to a row."""
        for a, b in self._topo.rot_springs[::-1]:
            if b != self.n_dof:
                row[a] += row[b]
        return row

    def joint_rotation(self, joint_name: str) -> np.ndarray:
        """Row giving the joint's relative rotation, child minus parent [rad] (zero for a rigid joint)."""
        j = self.rig.joint(joint_name)
        names = [b.name for b in self._topo.bodies]
        row = np.zeros(self.n_dof + 1)
        row[self._topo.bodies[names.index(j.child)].node_dofs[0, 2]] += 1.0
        row[self._topo.bodies[names.index(j.parent)].node_dofs[-1, 2]] -= 1.0
        return self._relative(row)[:-1]


@dataclass(frozen=True, eq=False)
class FrameModes:
    """Natural frequencies [Hz], mass-normalised shapes over the free DOFs, shapes at the sensors."""

    freq_hz: np.ndarray
    phi: np.ndarray
    sensor_shapes: np.ndarray
    sensor_names: tuple[str, ...] = ()


def _mass_value(rig: Rig, value: float | str, pose: Mapping[str, float]) -> float:
    if isinstance(value, str):
        v = float(pose[value])
        if not math.isfinite(v) or v < 0:
            raise ModelError(f"{rig.source}: pose variable {value!r} = {v} is not a mass >= 0 kg")
        return v
    return float(value)


def assemble(rig: Rig, pose: Mapping[str, float], elements_per_link: int | None = None,
             lumped_mass: bool = False, *, shear: Shear | None = None) -> FrameSystem:
    """Assemble K and M of ``rig`` at ``pose`` (joint angles in degrees, pose masses in kg).

    ``elements_per_link`` overrides the rig's ``elements`` (default 10 per link and per member).
    Shear deformation: each section's own (``Section.shear``, from the rig's ``shear_coefficient``;
    Euler-Bernoulli where it has none); ``shear`` (keyword, default None) makes every link and member a
    Timoshenko beam with one kappa and nu instead, see ``Shear``.
    """
    return assemble_many(rig, [pose], elements_per_link, lumped_mass, shear=shear)[0]


def assemble_many(rig: Rig, poses: Sequence[Mapping[str, float]], elements_per_link: int | None = None,
                  lumped_mass: bool = False, *, shear: Shear | None = None) -> list[FrameSystem]:
    """``assemble`` for several poses at once: element transforms and scatter vectorised over the poses."""
    topo = _topology(rig, elements_per_link, bool(lumped_mass), shear)
    if not poses:
        return []
    per_pose = DENSE_COPIES * (topo.n_dof + 1) ** 2 * 8   # bytes of K, M and their temporaries
    room = available_memory_bytes()
    if per_pose > room:
        raise ModelError(f"{rig.source}: {topo.n_dof} degrees of freedom: the dense stiffness and mass "
                         f"matrices need {per_pose / 2**30:.1f} GiB, more than the {room / 2**30:.1f} GiB of "
                         "memory available (fewer links, members or elements)")
    if len(poses) > 1 and len(poses) * per_pose > room:   # assembled a few poses at a time instead
        half = len(poses) // 2
        return (assemble_many(rig, poses[:half], elements_per_link, lumped_mass, shear=shear)
                + assemble_many(rig, poses[half:], elements_per_link, lumped_mass, shear=shear))
    for pose in poses:
        rig.check_pose(pose)
    geometry = [_body_geometry(rig, pose) for pose in poses]
    b_ang = np.array([g[0] for g in geometry])                  # [P, n_bodies]
    b_len = np.array([g[1] for g in geometry])
    P, n = len(poses), topo.n_dof
    k_loc = np.broadcast_to(topo.k_loc, (P, *topo.k_loc.shape))
    m_loc = np.broadcast_to(topo.m_loc, (P, *topo.m_loc.shape))
    if rig.members:
        k_loc, m_loc, mem = k_loc.copy(), m_loc.copy(), topo.elem_is_member
        le = (topo.elem_frac[mem, 1] - topo.elem_frac[mem, 0]) * b_len[:, topo.elem_body[mem]]
        EA, EI, mu, rot, GA = (np.tile(x[mem], P) for x in (topo.EA, topo.EI, topo.mu, topo.rot, topo.GA))
        km, mm = element_matrices(le.ravel(), EA, EI, mu, rot, lumped=topo.lumped, shear_rigidity_N=GA)
        k_loc[:, mem], m_loc[:, mem] = km.reshape(P, -1, 6, 6), mm.reshape(P, -1, 6, 6)
    T = _rotations(b_ang[:, topo.elem_body].ravel()).reshape(P, -1, 6, 6)
    Tt = T.transpose(0, 1, 3, 2)
    size = (n + 1) ** 2
    idx = (topo.elem_dofs[:, :, None] * (n + 1) + topo.elem_dofs[:, None, :]).ravel()
    idx = (idx[None, :] + size * np.arange(P)[:, None]).ravel()
    K = np.bincount(idx, (Tt @ k_loc @ T).ravel(), size * P).reshape(P, n + 1, n + 1)
    M = np.bincount(idx, (Tt @ m_loc @ T).ravel(), size * P).reshape(P, n + 1, n + 1)

    link_index = {lk.name: i for i, lk in enumerate(rig.links)}

    def node(p: Point) -> tuple[int, np.ndarray]:
        bi = link_index[p.link]
        return bi, topo.bodies[bi].node(p.fraction)

    for mass in rig.masses:
        _, d = node(mass.at)
        mk = np.array([_mass_value(rig, mass.mass_kg, pose) for pose in poses])
        M[:, d[0], d[0]] += mk
        M[:, d[1], d[1]] += mk
        M[:, d[2], d[2]] += mass.inertia_kgm2
    for sensor in rig.sensors:
        _, d = node(sensor.at)
        M[:, d[0], d[0]] += sensor.mass_kg
        M[:, d[1], d[1]] += sensor.mass_kg
    for spring in rig.springs:
        bi, d = node(spring.at)
        c, s = np.cos(b_ang[:, bi]), np.sin(b_ang[:, bi])
        one, zero = np.ones(P), np.zeros(P)
        n_vec = {"x": (one, zero), "y": (zero, one), "axial": (c, s), "transverse": (-s, c)}[spring.direction]
        n_vec = np.stack(n_vec, 1)
        K[np.ix_(range(P), d[:2], d[:2])] += spring.k_N_per_m * n_vec[:, :, None] * n_vec[:, None, :]

    # each spring's DOF b becomes the relative rotation theta_b - theta_a: u_raw = E_n ... E_2 E_1 u_new with
    # E_i: u[b] += u[a] (springs listed references first), so K <- E^T K E runs from the last spring back
    for (a, b), k in zip(topo.rot_springs[::-1], topo.rot_spring_k[::-1], strict=True):
        if b == n:  # spring to ground
            K[:, a, a] += k
            continue
        for A in (K, M):
            A[:, a, :] += A[:, b, :]
            A[:, :, a] += A[:, :, b]
        K[:, b, b] += k

    rows = np.zeros((P, len(rig.sensors), n + 1))
    if rig.sensors:
        vals = np.einsum("qi,pqij->pqj", topo.sensor_vecs, T[:, topo.sensor_elems])
        pieces = (slice(None), topo.sensor_of_piece[:, None], topo.elem_dofs[topo.sensor_elems])
        np.add.at(rows, pieces, vals)
        for a, b in topo.rot_springs[::-1]:
            if b != n:
                rows[:, :, a] += rows[:, :, b]
    names = tuple(s.name for s in rig.sensors)
    systems = []
    for i, (ang, length, start) in enumerate(geometry):
        nodes = np.concatenate([start[j] + np.outer(b.stations * length[j], (math.cos(a), math.sin(a)))
                                for j, (b, a) in enumerate(zip(topo.bodies, ang, strict=True))])
        systems.append(FrameSystem(K[i, :n, :n], M[i, :n, :n], rows[i, :, :n], names, nodes, rig, topo, ang,
                                   length))
    return systems


def solve_modes(system: FrameSystem, n_modes: int = 4) -> FrameModes:
    """Lowest ``n_modes`` modes of ``system`` (rigid-body modes included, reported at 0 Hz).

    Shapes are mass-normalised (phi^T M phi = 1) with a deterministic sign: the largest-magnitude sensor
    component is positive (the largest DOF component when the rig has no sensors).
    """
    K, M = system.K, system.M
    n = K.shape[0]
    if not 1 <= n_modes <= n:
        raise ModelError(f"{system.rig.source}: asked for {n_modes} modes of a model with {n} DOFs")
    dk, dm = np.diag(K), np.diag(M)
    positive = dm > 0
    sigma = 1e-6 * float(np.median(dk[positive] / dm[positive])) if positive.any() else 1.0
    for _ in range(6):
        try:
            mu, vec = eigh(M, K + sigma * M, subset_by_index=[n - n_modes, n - 1], check_finite=False)
            break
        except LinAlgError:
            sigma *= 1e3
    else:
        raise ModelError(f"{system.rig.source}: the frame has a mechanism with no mass (singular model)")
    mu, vec = mu[::-1], vec[:, ::-1]
    if np.any(mu <= 0):
        raise ModelError(f"{system.rig.source}: the frame has fewer than {n_modes} modes with mass")
    omega2 = np.clip(1.0 / mu - sigma, 0.0, None)
    norm = np.sqrt(np.sum(vec * (M @ vec), axis=0))
    phi = vec / norm
    ref = system.sensor_matrix @ phi if system.sensor_matrix.shape[0] else phi
    phi = phi * largest_positive(ref)
    return FrameModes(np.sqrt(omega2) / (2 * math.pi), phi, system.sensor_matrix @ phi, system.sensor_names)


def frame_modes(rig: Rig, pose: Mapping[str, float], n_modes: int = 4, elements_per_link: int | None = None,
                lumped_mass: bool = False, *, shear: Shear | None = None) -> FrameModes:
    """Assemble and solve in one call (see ``assemble`` and ``solve_modes``)."""
    return solve_modes(assemble(rig, pose, elements_per_link, lumped_mass, shear=shear), n_modes)


def frame_modes_many(rig: Rig, poses: Iterable[Mapping[str, float]], n_modes: int = 4,
                     elements_per_link: int | None = None, lumped_mass: bool = False,
                     *, chunk: int = 256, shear: Shear | None = None) -> list[FrameModes]:
    """``frame_modes`` for each pose: assembly vectorised over chunks of poses, one eigensolve per pose."""
    poses = list(poses)
    return [solve_modes(system, n_modes) for i in range(0, len(poses), chunk)
            for system in assemble_many(rig, poses[i:i + chunk], elements_per_link, lumped_mass,
                                        shear=shear)]
