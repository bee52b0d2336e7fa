"""Rig description (docs/formats.md): TOML in, validated frozen dataclasses out.

A planar arm: links in a serial chain from the base, joints between them, optional extra members
(closed chains), lumped masses, grounded springs and sensors.  SI units, angles in degrees.

Section conventions: ``rect_tube`` and ``solid_rect`` bend in the plane of the arm about the axis
normal to that plane, so ``height_m`` is the in-plane depth (I = w h^3 / 12).  ``segments`` give
``from``/``to`` in metres along the link from its start.  A mass's ``mass_kg`` may name a pose variable
(e.g. ``"payload_kg"``) so payload trends need no new rig file.

Fields beyond the contract that the sim-to-real effects use (models/effects.py): ``base.k_Nm_per_rad``
with ``support = "spring"``; ``link.stiffness_scale`` and ``link.mass_scale``; ``member.end_k_Nm_per_rad``
(rotational restraint at pinned member ends); ``sensor.mass_kg``; ``[[spring]]`` grounded springs.

Shear deformation (optional, per section): ``section.shear_coefficient`` (kappa) with the material's
``nu`` makes that section's elements Timoshenko beams in models/frame.py (:class:`Shear`); without it a
section is Euler-Bernoulli, as before the key existed.
"""

from __future__ import annotations

import math
import sys
from collections.abc import Mapping
from dataclasses import dataclass, field
from numbers import Real
from pathlib import Path
from typing import Any

import numpy as np

from flexmodal.checked_io.text import read_toml
from flexmodal.checked_io.toml_fields import DOTTED_PATH, Fields
from flexmodal.models.errors import ModelError
from flexmodal.models.rig_schema import check_document

SECTION_SHAPES = ("square_tube", "rect_tube", "round_tube", "solid_rect", "custom")
SUPPORTS = ("clamped", "pinned", "free", "spring")
JOINT_KINDS = ("rigid", "pin", "spring")
MEMBER_ENDS = ("pin-pin", "clamped-pin", "clamped-clamped")
DIRECTIONS = ("transverse", "axial")
SPRING_DIRECTIONS = ("transverse", "axial", "x", "y")
MAX_GROUND_M = 1e3  # a member end on the ground lies within a kilometre of the base


KAPPA_MIN = 1e-3
"""The smallest shear coefficient ``Shear`` accepts [-]: real sections lie between about 0.1 and 1.2
(Cowper 1966); far below, phi overflows the element matrices (kappa near 1e-154 gives NaN masses).  A
large kappa is harmless (phi -> 0: the Euler-Bernoulli element)."""


@dataclass(frozen=True)
class Shear:
    """Shear deformation of a section (Timoshenko beam instead of Euler-Bernoulli, models/frame.py).

    Parameters
    ----------
    shear_coefficient : float
        Timoshenko shear coefficient kappa [-] (dimensionless, >= ``KAPPA_MIN``): 5/6 for a solid
        rectangle, about 0.5 for a thin-walled round or square tube bending in its plane (Cowper 1966).
    poisson_ratio : float
        Poisson's ratio nu [-] (dimensionless, in (-1, 0.5)); the shear modulus is G = E / (2 (1 + nu)),
        so the shear rigidity is ``kappa G A = kappa EA / (2 (1 + nu))`` from the section's ``EA_N``.
    """

    shear_coefficient: float = 5.0 / 6.0
    poisson_ratio: float = 0.3

    def __post_init__(self) -> None:
        for name, value in (("shear coefficient kappa", self.shear_coefficient),
                            ("Poisson's ratio nu", self.poisson_ratio)):
            if isinstance(value, bool) or not isinstance(value, Real):
                raise ModelError(f"{name} = {value!r} must be a number")
            if isinstance(value, int) and abs(value) > sys.float_info.max:
                raise ModelError(f"{name}: an integer of {len(str(abs(value)))} digits is beyond a "
                                 "float's range (about 1.8e308)")
        if not (math.isfinite(self.shear_coefficient) and self.shear_coefficient >= KAPPA_MIN):
            raise ModelError(f"shear coefficient kappa = {self.shear_coefficient} must be finite and at "
                             f"least {KAPPA_MIN:g} (real sections: about 0.1 to 1.2)")
        if not -1.0 < self.poisson_ratio < 0.5:
            raise ModelError(f"Poisson's ratio nu = {self.poisson_ratio} must lie in (-1, 0.5)")

    def rigidity_N(self, EA_N: np.ndarray) -> np.ndarray:
        """Shear rigidity kappa G A [N] of sections with axial rigidity ``EA_N`` [N]."""
        return self.shear_coefficient * np.asarray(EA_N, float) / (2.0 * (1.0 + self.poisson_ratio))


@dataclass(frozen=True)
class Section:
    """Cross-section properties per unit length: EA [N], EI [N m^2], mass [kg/m], rotary [kg m]; ``shear``
    (None: Euler-Bernoulli) from ``shear_coefficient`` and the material's ``nu``."""

    shape: str
    EA_N: float
    EI_Nm2: float
    mass_per_m_kg: float
    rotary_inertia_per_m_kgm: float
    depth_m: float  # in-plane depth: distance between the extreme fibres (for bending strain)
    shear: Shear | None = None


@dataclass(frozen=True)
class Segment:
    """A stretch ``[from_m, to_m]`` of a link with its own section."""

    from_m: float
    to_m: float
    section: Section


@dataclass(frozen=True)
class Link:
    name: str
    length_m: float
    section: Section
    elements: int | None = None
    segments: tuple[Segment, ...] = ()
    stiffness_scale: float = 1.0
    mass_scale: float = 1.0

    def section_at(self, s_m: float) -> Section:
        """Section at ``s_m`` metres from the link's start (segments override the link section)."""
        for seg in self.segments:
            if seg.from_m <= s_m <= seg.to_m:
                return seg.section
        return self.section


@dataclass(frozen=True)
class Base:
    support: str = "clamped"
    k_Nm_per_rad: float | None = None
    angle: str | None = None  # pose variable of the first link's absolute angle (deg)
    angle_deg: float = 0.0


@dataclass(frozen=True)
class Joint:
    name: str
    parent: str
    child: str
    angle: str | None  # pose variable setting the relative angle, degrees (0 = straight)
    kind: str = "rigid"
    k_Nm_per_rad: float | None = None
    angle_deg: float = 0.0  # fixed relative angle when ``angle`` is not given


@dataclass(frozen=True)
class Point:
    """A point on the arm: on a link at a fraction of its length, or on the ground at (x, y) m."""

    link: str | None
    fraction: float = 0.0
    ground_xy_m: tuple[float, float] | None = None

    def __str__(self) -> str:
        if self.link is None:
            return f"ground@{self.ground_xy_m[0]:g},{self.ground_xy_m[1]:g}"  # type: ignore[index]
        return f"{self.link}@{self.fraction:g}"


@dataclass(frozen=True)
class Member:
    name: str
    start: Point
    end: Point
    section: Section
    ends: str = "pin-pin"
    elements: int | None = None
    end_k_Nm_per_rad: float = 0.0  # rotational restraint at each pinned end (pin friction)


@dataclass(frozen=True)
class Mass:
    at: Point
    mass_kg: float | str  # a number, or the name of a pose variable (e.g. "payload_kg")
    inertia_kgm2: float = 0.0
    name: str = ""


@dataclass(frozen=True)
class Spring:
    """Translational spring from a point of the arm to ground."""

    at: Point
    k_N_per_m: float
    direction: str = "transverse"
    name: str = ""


@dataclass(frozen=True)
class Sensor:
    name: str
    at: Point
    direction: str = "transverse"
    mass_kg: float = 0.0


@dataclass(frozen=True)
class Rig:
    name: str
    links: tuple[Link, ...]
    joints: tuple[Joint, ...]
    base: Base = field(default_factory=Base)
    members: tuple[Member, ...] = ()
    masses: tuple[Mass, ...] = ()
    springs: tuple[Spring, ...] = ()
    sensors: tuple[Sensor, ...] = ()
    source: str = "<rig>"

    def link(self, name: str) -> Link:
        for link in self.links:
            if link.name == name:
                return link
        raise ModelError(f"{self.source}: no link named {name!r}")

    def joint(self, name: str) -> Joint:
        for joint in self.joints:
            if joint.name == name:
                return joint
        raise ModelError(f"{self.source}: no joint named {name!r}")

    @property
    def pose_variables(self) -> tuple[str, ...]:
        """Names of the pose variables the rig reads (joint angles, base angle, mass pose vars)."""
        names = [self.base.angle] if self.base.angle else []
        names += [j.angle for j in self.joints if j.angle]
        names += [m.mass_kg for m in self.masses if isinstance(m.mass_kg, str)]
        return tuple(dict.fromkeys(names))

    def check_pose(self, pose: Mapping[str, float]) -> None:
        """Raise ModelError naming the first pose variable the rig needs that ``pose`` lacks."""
        for name in self.pose_variables:
            if name not in pose:
                raise ModelError(f"{self.source}: pose has no value for {name!r} (have {sorted(pose)})")

    def check_euler_bernoulli(self, where: str) -> None:
        """Raise ModelError (``where``: the file and model) naming the first link whose section or segment
        sets shear deformation, for a model that is an Euler-Bernoulli beam (shear is the frame's)."""
        for lk in self.links:
            if any(sec.shear for sec in (lk.section, *(seg.section for seg in lk.segments))):
                raise ModelError(f"{where} has no shear deformation but link {lk.name!r} sets "
                                 "shear_coefficient (use --model fe)")

    def point_of(self, where: str) -> Point:
        """Resolve ``<link>@<fraction>``, ``ground@x,y``, a joint name (its child's start), ``tip``."""
        return _parse_point(where, self, "at")


# ---------------------------------------------------------------------------------------------
# parsing (flexmodal.checked_io.toml_fields: errors name the file and the field's dotted path)


def _fields(doc: Any, source: str, path: str) -> Fields:
    """Typed access to the table at ``path`` of the rig file ``source`` (errors: ModelError)."""
    return Fields(doc, source, ModelError, path=path, wording=DOTTED_PATH)


def _positive(t: Fields, key: str, default: Any = ..., *, allow_zero: bool = False) -> float:
    """A finite number > 0 (>= 0 with ``allow_zero``), in the SI unit its name ends with."""
    return t.number(key, default, lo=0.0, lo_open=not allow_zero)


def _name(t: Fields) -> str:
    """The table's ``name``: a string with more than white space."""
    return t.get("name", str, check=str.strip, why="must be a non-empty string")


def _elements(t: Fields) -> int | None:
    """The table's ``elements`` (finite elements per link or member), None when not given."""
    return t.get("elements", int, None, check=lambda n: n >= 1, why="must be a whole number >= 1")


def section_properties(spec: Any, material: Mapping[str, Any] | None, path: str,
                       source: str = "<rig>") -> Section:
    """Section properties from a section table and a material {E_Pa, rho_kg_m3, [nu]}: EA, EI about the
    axis normal to the arm's plane, mass and rotary inertia per metre, and shear deformation when the
    table has ``shear_coefficient`` (else Euler-Bernoulli)."""
    if not isinstance(spec, Mapping):
        raise ModelError(f"{source}: {path}: must be a table such as {{ shape = \"square_tube\", ... }}")
    t = _fields(spec, source, path)
    shape = t.choice("shape", SECTION_SHAPES)
    if shape == "custom":
        EA, EI, mpl = (_positive(t, key) for key in ("EA_N", "EI_Nm2", "mass_per_m_kg"))
        rot = _positive(t, "rotary_inertia_per_m_kgm", mpl * EI / EA, allow_zero=True)
        return Section(shape, EA, EI, mpl, rot, _positive(t, "depth_m", 2.0 * math.sqrt(EI / EA)),
                       _shear(t, material))
    if material is None:
        raise t.fail("", f"shape {shape!r} needs a material")
    if shape == "square_tube":
        b, wall = _positive(t, "outer_m"), _positive(t, "wall_m")
        if 2 * wall >= b:
            raise t.fail("wall_m", f"wall {wall} m is too thick for outer size {b} m")
        bi = b - 2 * wall
        area, inertia, depth = b * b - bi * bi, (b**4 - bi**4) / 12.0, b
    elif shape == "rect_tube":
        w, h, wall = _positive(t, "width_m"), _positive(t, "height_m"), _positive(t, "wall_m")
        if 2 * wall >= min(w, h):
            raise t.fail("wall_m", f"wall {wall} m is too thick for a {w} x {h} m tube")
        area = w * h - (w - 2 * wall) * (h - 2 * wall)
        inertia, depth = (w * h**3 - (w - 2 * wall) * (h - 2 * wall) ** 3) / 12.0, h
    elif shape == "round_tube":
        d, wall = _positive(t, "outer_m"), _positive(t, "wall_m")
        if 2 * wall > d:
            raise t.fail("wall_m", f"wall {wall} m is too thick for outer diameter {d} m")
        di = d - 2 * wall
        area, inertia, depth = math.pi / 4 * (d**2 - di**2), math.pi / 64 * (d**4 - di**4), d
    else:  # solid_rect
        w, h = _positive(t, "width_m"), _positive(t, "height_m")
        area, inertia, depth = w * h, w * h**3 / 12.0, h
    E, rho = material["E_Pa"], material["rho_kg_m3"]
    return Section(shape, E * area, E * inertia, rho * area, rho * inertia, depth, _shear(t, material))


def _shear(t: Fields, material: Mapping[str, Any] | None) -> Shear | None:
    """The section's shear deformation: ``shear_coefficient`` (kappa [-]) with its material's ``nu``
    [-]; None (Euler-Bernoulli) when the section has no ``shear_coefficient``."""
    if "shear_coefficient" not in t.doc:
        return None
    if material is None or "nu" not in material:
        raise t.fail("shear_coefficient", "needs Poisson's ratio: give the section's material a nu "
                                          "(G = E / (2 (1 + nu)))")
    kappa = t.doc["shear_coefficient"]
    try:
        Shear(kappa)
    except ModelError as e:
        raise t.fail("shear_coefficient", str(e)) from None
    try:
        return Shear(kappa, material["nu"])
    except ModelError as e:
        raise t.fail("shear_coefficient", f"{e} (the nu of the section's material)") from None


def _material(doc: Mapping[str, Any], t: Fields) -> Mapping[str, Any] | None:
    """The material a table names (``material = "steel"`` or an inline table); None when it names none."""
    spec, path = t.doc.get("material"), t.field("material")
    if spec is None:
        return None
    materials = doc.get("material", {})
    if isinstance(spec, str):
        if spec not in materials:
            raise t.fail("material", f"unknown material {spec!r} (defined: {', '.join(materials) or 'none'})")
        spec, path = materials[spec], f"material.{spec}"
    if not isinstance(spec, Mapping):
        raise t.fail("material", "must name a [material.<name>] table")
    m = _fields(spec, t.where, path)
    nu = {"nu": spec["nu"]} if "nu" in spec else {}   # Poisson's ratio: read by a section's shear only
    return {"E_Pa": _positive(m, "E_Pa"), "rho_kg_m3": _positive(m, "rho_kg_m3"), **nu}


def _section(t: Fields, material: Mapping[str, Any] | None) -> Section:
    """The ``section`` of a link, segment or member table, made of ``material``."""
    return section_properties(t.get("section", object), material, t.field("section"), t.where)


def _parse_link(doc: Mapping[str, Any], t: Fields) -> Link:
    name, length, material = _name(t), _positive(t, "length_m"), _material(doc, t)
    section = _section(t, material)
    segments = []
    for j, seg in enumerate(t.doc.get("segments", [])):
        s = _fields(seg, t.where, f"{t.path}.segments[{j}]")
        a, b = _positive(s, "from", allow_zero=True), _positive(s, "to")
        if not a < b <= length * (1 + 1e-9):
            raise s.fail("", f"needs 0 <= from < to <= length_m ({length} m), got {a}..{b}")
        segments.append(Segment(a, b, _section(s, _material(doc, s) or material)))
    scales = {k: _positive(t, k, 1.0) for k in ("stiffness_scale", "mass_scale")}
    return Link(name, length, section, _elements(t), tuple(segments), **scales)


def _parse_point(text: Any, rig_or_links: Any, path: str, source: str | None = None, *,
                 ground: bool = False) -> Point:
    """Parse a point reference against a Rig or a {link name: Link} mapping plus joints; ``ground@x,y``
    (finite metres) only where ``ground`` (a member's end: a mass, spring or sensor on the ground
    is not part of the arm)."""
    source = source or getattr(rig_or_links, "source", "<rig>")

    def fail(what: str) -> ModelError:
        return ModelError(f"{source}: {path}: {what}")

    if isinstance(rig_or_links, Rig):
        links = {lk.name: lk for lk in rig_or_links.links}
        joints = {j.name: j for j in rig_or_links.joints}
    else:
        links, joints = rig_or_links
    if not isinstance(text, str):
        raise fail(f"must be a string like 'link1@0.5' (got {text!r})")
    if text == "tip":
        return Point(list(links)[-1], 1.0)
    if text in joints:
        return Point(joints[text].child, 0.0)
    head, sep, tail = text.partition("@")
    if not sep:
        raise fail(f"{text!r} is not '<link>@<fraction>', 'ground@x,y', 'tip' or a joint name")
    try:
        xy = tuple(float(v) for v in tail.split(",")) if head == "ground" else None
        frac = 0.0 if xy is not None else float(tail)
        if xy is not None and len(xy) != 2:
            raise ValueError(tail)
    except ValueError:
        raise fail(f"cannot read the position in {text!r}") from None
    if xy is not None:
        if not ground:
            raise fail(f"{text!r} is a ground point: only a member's end may be there (use "
                       "'<link>@<fraction>', 'tip' or a joint name)")
        if not all(math.isfinite(v) and abs(v) <= MAX_GROUND_M for v in xy):
            raise fail(f"{text!r}: ground coordinates must be finite and within {MAX_GROUND_M:g} m")
        return Point(None, 0.0, xy)
    if head not in links:
        raise fail(f"{text!r} names no link (links: {', '.join(links)})")
    if not 0.0 <= frac <= 1.0:
        raise fail(f"{text!r}: the fraction must lie in [0, 1] (the member end is off its link)")
    return Point(head, frac)


def _tables(doc: Mapping[str, Any], key: str, source: str) -> list[Fields]:
    """The ``[[key]]`` tables of the document, each with its path ``key[i]``."""
    return [_fields(t, source, f"{key}[{i}]") for i, t in enumerate(doc.get(key, []))]


def parse_rig(doc: Mapping[str, Any], source: str = "<rig>") -> Rig:
    """Validate a parsed rig TOML document; raises ModelError naming the field on any mistake."""
    check_document(doc, source)
    top = _fields(doc, source, "")
    name = str(doc.get("name", Path(source).stem))
    top.get("link", list, check=bool, why="needs at least one [[link]] table")
    links = tuple(_parse_link(doc, t) for t in _tables(doc, "link", source))
    link_names = [lk.name for lk in links]
    if len(set(link_names)) != len(link_names):
        raise top.fail("link", f"duplicate link names in {link_names}")

    b = top.table("base", {})
    support = b.choice("support", SUPPORTS, "clamped")
    kb = _positive(b, "k_Nm_per_rad") if support == "spring" else b.doc.get("k_Nm_per_rad")
    base = Base(support, kb, b.doc.get("angle"), float(b.doc.get("angle_deg", 0.0)))

    joints = []
    for t in _tables(doc, "joint", source):
        jname = _name(t)
        parent, child = t.get("parent", object), t.get("child", object)
        for key, val in (("parent", parent), ("child", child)):
            if val not in link_names:
                raise t.fail(key, f"joint {jname!r} names a missing link {val!r}")
        if link_names.index(child) != link_names.index(parent) + 1:
            raise t.fail("", f"joint {jname!r}: child {child!r} must be the link after {parent!r}")
        kind = t.choice("kind", JOINT_KINDS, "rigid")
        k = _positive(t, "k_Nm_per_rad") if kind == "spring" else t.doc.get("k_Nm_per_rad")
        joints.append(Joint(jname, parent, child, t.doc.get("angle"), kind, k,
                            float(t.doc.get("angle_deg", 0.0))))
    joined = {j.child for j in joints}
    for lk in links[1:]:
        if lk.name not in joined:
            raise top.fail("joint", f"link {lk.name!r} is joined to nothing (add a [[joint]] with child)")
    _check_places(top, links, joints, ())
    refs = ({lk.name: lk for lk in links}, {j.name: j for j in joints})

    def point(t: Fields, key: str, ground: bool = False) -> Point:
        return _parse_point(t.get(key, object), refs, t.field(key), source, ground=ground)

    members = tuple(Member(_name(t), point(t, "from", True), point(t, "to", True),
                           _section(t, _material(doc, t)),
                           t.choice("ends", MEMBER_ENDS, "pin-pin"), _elements(t),
                           _positive(t, "end_k_Nm_per_rad", 0.0, allow_zero=True))
                    for t in _tables(doc, "member", source))
    _check_places(top, links, joints, members)
    masses = tuple(Mass(point(t, "at"),
                        t.get("mass_kg", str) if isinstance(t.doc.get("mass_kg"), str)
                        else _positive(t, "mass_kg", allow_zero=True),
                        _positive(t, "inertia_kgm2", 0.0, allow_zero=True), str(t.doc.get("name", "")))
                   for t in _tables(doc, "mass", source))
    springs = tuple(Spring(point(t, "at"), _positive(t, "k_N_per_m"),
                           t.choice("direction", SPRING_DIRECTIONS, "transverse"), str(t.doc.get("name", "")))
                    for t in _tables(doc, "spring", source))
    sensors = tuple(Sensor(_name(t), point(t, "at"), t.choice("direction", DIRECTIONS, "transverse"),
                           _positive(t, "mass_kg", 0.0, allow_zero=True))
                    for t in _tables(doc, "sensor", source))
    sensor_names = [s.name for s in sensors]
    if len(set(sensor_names)) != len(sensor_names):
        raise top.fail("sensor", f"duplicate sensor names in {sensor_names}")
    return Rig(name, links, tuple(joints), base, members, masses, springs, sensors, source)


RESERVED_PLACES = ("tip", "base", "ground")   # the words a point or a diagnosis location means itself


def _check_places(top: Fields, links, joints, members) -> None:
    """Links, joints and members are places (a point ``<link>@<fraction>``, a joint name, a diagnosis
    location): each name must say one place, so none is shared between them, none is a reserved word
    and none holds ``@`` (a joint called ``tip`` was read as the free end; a joint and a link of one
    name made a location of the diagnosis ambiguous)."""
    seen: dict[str, str] = {}
    for kind, items in (("link", links), ("joint", joints), ("member", members)):
        for item in items:
            if item.name in RESERVED_PLACES or "@" in item.name:
                why = "is a reserved word of rig points" if "@" not in item.name else "holds '@'"
                raise top.fail(kind, f"{kind} name {item.name!r} {why} (reserved: "
                               f"{', '.join(RESERVED_PLACES)}; '@' separates a link from a fraction)")
            if item.name in seen and seen[item.name] != kind:
                raise top.fail(kind, f"{kind} {item.name!r} has the name of a {seen[item.name]}: links, "
                               "joints and members name places, each name one place")
            if item.name in seen:
                raise top.fail(kind, f"duplicate {kind} name {item.name!r}")
            seen[item.name] = kind


def load_rig(path: str | Path) -> Rig:
    """Read and validate a rig TOML file (docs/formats.md)."""
    return parse_rig(read_toml(path, ModelError, "rig file"), str(path))
