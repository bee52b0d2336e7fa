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
"""

from __future__ import annotations

import math
import tomllib
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from flexmodal.models.errors import ModelError

SECTION_SHAPES = ("square_tube", "rect_tube", "round_tube", "solid_rect", "custom")
SUPPORTS = ("clamped", "pinned", "free", "spring")
JOINT_KINDS = ("rigid", "pin", "spring")
MEMBER_ENDS = ("pin-pin", "clamped-pin", "clamped-clamped")
DIRECTIONS = ("transverse", "axial")
SPRING_DIRECTIONS = ("transverse", "axial", "x", "y")


@dataclass(frozen=True)
class Section:
    """Cross-section properties per unit length: EA [N], EI [N m^2], mass [kg/m], rotary [kg m]."""

    shape: str
    EA_N: float
    EI_Nm2: float
    mass_per_m_kg: float
    rotary_inertia_per_m_kgm: float
    depth_m: float  # in-plane depth: distance between the extreme fibres (for bending strain)


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

    def point_of(self, where: str) -> Point:
        """Resolve ``<link>@<fraction>``, ``ground@x,y``, a joint name (its child's start), ``tip``."""
        return _parse_point(where, self, "at")


# ---------------------------------------------------------------------------------------------
# parsing


class _Ctx:
    """Error context: the file and the dotted field path."""

    def __init__(self, source: str) -> None:
        self.source = source

    def fail(self, path: str, what: str) -> ModelError:
        return ModelError(f"{self.source}: {path}: {what}")


def _get(table: Mapping[str, Any], key: str, path: str, ctx: _Ctx, default: Any = ...) -> Any:
    if key in table:
        return table[key]
    if default is ...:
        raise ctx.fail(f"{path}.{key}" if path else key, "missing required field")
    return default


def _positive(value: Any, path: str, ctx: _Ctx, allow_zero: bool = False) -> float:
    if isinstance(value, bool) or not isinstance(value, int | float):
        raise ctx.fail(path, f"must be a number (got {value!r})")
    v = float(value)
    if not math.isfinite(v) or v < 0 or (v == 0 and not allow_zero):
        raise ctx.fail(path, f"must be {'>= 0' if allow_zero else '> 0'} (got {value!r})")
    return v


def _choice(value: Any, options: tuple[str, ...], path: str, ctx: _Ctx) -> str:
    if value not in options:
        raise ctx.fail(path, f"unknown value {value!r} (expected one of {', '.join(options)})")
    return str(value)


def _name(value: Any, path: str, ctx: _Ctx) -> str:
    if not isinstance(value, str) or not value.strip():
        raise ctx.fail(path, f"must be a non-empty string (got {value!r})")
    return value


def section_properties(spec: Mapping[str, Any], material: Mapping[str, float] | None, path: str,
                       ctx: _Ctx | None = None) -> Section:
    """Section properties from a section table and a material {E_Pa, rho_kg_m3}."""
    ctx = ctx or _Ctx("<rig>")
    if not isinstance(spec, Mapping):
        raise ctx.fail(path, "must be a table such as { shape = \"square_tube\", ... }")
    shape = _choice(_get(spec, "shape", path, ctx), SECTION_SHAPES, f"{path}.shape", ctx)
    if shape == "custom":
        EA = _positive(_get(spec, "EA_N", path, ctx), f"{path}.EA_N", ctx)
        EI = _positive(_get(spec, "EI_Nm2", path, ctx), f"{path}.EI_Nm2", ctx)
        mpl = _positive(_get(spec, "mass_per_m_kg", path, ctx), f"{path}.mass_per_m_kg", ctx)
        rot = _get(spec, "rotary_inertia_per_m_kgm", path, ctx, mpl * EI / EA)
        rot = _positive(rot, f"{path}.rotary_inertia_per_m_kgm", ctx, allow_zero=True)
        depth = _positive(_get(spec, "depth_m", path, ctx, 2.0 * math.sqrt(EI / EA)), f"{path}.depth_m", ctx)
        return Section(shape, EA, EI, mpl, rot, depth)
    if material is None:
        raise ctx.fail(path, f"shape {shape!r} needs a material")

    def dim(key: str) -> float:
        return _positive(_get(spec, key, path, ctx), f"{path}.{key}", ctx)

    if shape == "square_tube":
        b, t = dim("outer_m"), dim("wall_m")
        if 2 * t >= b:
            raise ctx.fail(f"{path}.wall_m", f"wall {t} m is too thick for outer size {b} m")
        bi = b - 2 * t
        area, inertia, depth = b * b - bi * bi, (b**4 - bi**4) / 12.0, b
    elif shape == "rect_tube":
        w, h, t = dim("width_m"), dim("height_m"), dim("wall_m")
        if 2 * t >= min(w, h):
            raise ctx.fail(f"{path}.wall_m", f"wall {t} m is too thick for a {w} x {h} m tube")
        area = w * h - (w - 2 * t) * (h - 2 * t)
        inertia, depth = (w * h**3 - (w - 2 * t) * (h - 2 * t) ** 3) / 12.0, h
    elif shape == "round_tube":
        d, t = dim("outer_m"), dim("wall_m")
        if 2 * t > d:
            raise ctx.fail(f"{path}.wall_m", f"wall {t} m is too thick for outer diameter {d} m")
        di = d - 2 * t
        area, inertia, depth = math.pi / 4 * (d**2 - di**2), math.pi / 64 * (d**4 - di**4), d
    else:  # solid_rect
        w, h = dim("width_m"), dim("height_m")
        area, inertia, depth = w * h, w * h**3 / 12.0, h
    E, rho = material["E_Pa"], material["rho_kg_m3"]
    return Section(shape, E * area, E * inertia, rho * area, rho * inertia, depth)


def _material(doc: Mapping[str, Any], spec: Any, path: str, ctx: _Ctx) -> Mapping[str, float] | None:
    if spec is None:
        return None
    materials = doc.get("material", {})
    if isinstance(spec, str):
        if spec not in materials:
            raise ctx.fail(path, f"unknown material {spec!r} (defined: {', '.join(materials) or 'none'})")
        spec, path = materials[spec], f"material.{spec}"
    if not isinstance(spec, Mapping):
        raise ctx.fail(path, "must name a [material.<name>] table")
    return {"E_Pa": _positive(_get(spec, "E_Pa", path, ctx), f"{path}.E_Pa", ctx),
            "rho_kg_m3": _positive(_get(spec, "rho_kg_m3", path, ctx), f"{path}.rho_kg_m3", ctx)}


def _elements(table: Mapping[str, Any], path: str, ctx: _Ctx) -> int | None:
    n = table.get("elements")
    if n is None:
        return None
    if isinstance(n, bool) or not isinstance(n, int) or n < 1:
        raise ctx.fail(f"{path}.elements", f"must be a whole number >= 1 (got {n!r})")
    return n


def _parse_link(doc: Mapping[str, Any], t: Mapping[str, Any], i: int, ctx: _Ctx) -> Link:
    path = f"link[{i}]"
    name = _name(_get(t, "name", path, ctx), f"{path}.name", ctx)
    length = _positive(_get(t, "length_m", path, ctx), f"{path}.length_m", ctx)
    mat = _material(doc, t.get("material"), f"{path}.material", ctx)
    section = section_properties(_get(t, "section", path, ctx), mat, f"{path}.section", ctx)
    segments = []
    for j, seg in enumerate(t.get("segments", [])):
        sp = f"{path}.segments[{j}]"
        a = _positive(_get(seg, "from", sp, ctx), f"{sp}.from", ctx, allow_zero=True)
        b = _positive(_get(seg, "to", sp, ctx), f"{sp}.to", ctx)
        if not a < b <= length * (1 + 1e-9):
            raise ctx.fail(sp, f"needs 0 <= from < to <= length_m ({length} m), got {a}..{b}")
        smat = _material(doc, seg.get("material"), f"{sp}.material", ctx) or mat
        segments.append(Segment(a, b, section_properties(_get(seg, "section", sp, ctx), smat,
                                                         f"{sp}.section", ctx)))
    scales = {k: _positive(t.get(k, 1.0), f"{path}.{k}", ctx) for k in ("stiffness_scale", "mass_scale")}
    return Link(name, length, section, _elements(t, path, ctx), tuple(segments), **scales)


def _parse_point(text: Any, rig_or_links: Any, path: str, ctx: _Ctx | None = None) -> Point:
    """Parse a point reference against a Rig or a {link name: Link} mapping plus joints."""
    ctx = ctx or _Ctx(getattr(rig_or_links, "source", "<rig>"))
    if isinstance(rig_or_links, Rig):
        links = {lk.name: lk for lk in rig_or_links.links}
        joints = {j.name: j for j in rig_or_links.joints}
    else:
        links, joints = rig_or_links
    if not isinstance(text, str):
        raise ctx.fail(path, f"must be a string like 'link1@0.5' (got {text!r})")
    if text == "tip":
        return Point(list(links)[-1], 1.0)
    if text in joints:
        return Point(joints[text].child, 0.0)
    head, sep, tail = text.partition("@")
    if not sep:
        raise ctx.fail(path, f"{text!r} is not '<link>@<fraction>', 'ground@x,y', 'tip' or a joint name")
    try:
        if head == "ground":
            x, y = (float(v) for v in tail.split(","))
            return Point(None, 0.0, (x, y))
        frac = float(tail)
    except ValueError:
        raise ctx.fail(path, f"cannot read the position in {text!r}") from None
    if head not in links:
        raise ctx.fail(path, f"{text!r} names no link (links: {', '.join(links)})")
    if not 0.0 <= frac <= 1.0:
        raise ctx.fail(path, f"{text!r}: the fraction must lie in [0, 1] (the member end is off its link)")
    return Point(head, frac)


def parse_rig(doc: Mapping[str, Any], source: str = "<rig>") -> Rig:
    """Validate a parsed rig TOML document; raises ModelError naming the field on any mistake."""
    ctx = _Ctx(source)
    name = str(doc.get("name", Path(source).stem))
    raw_links = _get(doc, "link", "", ctx)
    if not isinstance(raw_links, list) or not raw_links:
        raise ctx.fail("link", "needs at least one [[link]] table")
    links = tuple(_parse_link(doc, t, i, ctx) for i, t in enumerate(raw_links))
    link_names = [lk.name for lk in links]
    if len(set(link_names)) != len(link_names):
        raise ctx.fail("link", f"duplicate link names in {link_names}")

    b = doc.get("base", {})
    support = _choice(b.get("support", "clamped"), SUPPORTS, "base.support", ctx)
    kb = b.get("k_Nm_per_rad")
    if support == "spring":
        kb = _positive(_get(b, "k_Nm_per_rad", "base", ctx), "base.k_Nm_per_rad", ctx)
    base = Base(support, kb, b.get("angle"), float(b.get("angle_deg", 0.0)))

    joints = []
    for i, t in enumerate(doc.get("joint", [])):
        path = f"joint[{i}]"
        jname = _name(_get(t, "name", path, ctx), f"{path}.name", ctx)
        parent, child = _get(t, "parent", path, ctx), _get(t, "child", path, ctx)
        for key, val in (("parent", parent), ("child", child)):
            if val not in link_names:
                raise ctx.fail(f"{path}.{key}", f"joint {jname!r} names a missing link {val!r}")
        if link_names.index(child) != link_names.index(parent) + 1:
            raise ctx.fail(path, f"joint {jname!r}: child {child!r} must be the link after {parent!r}")
        kind = _choice(t.get("kind", "rigid"), JOINT_KINDS, f"{path}.kind", ctx)
        k = t.get("k_Nm_per_rad")
        if kind == "spring":
            k = _positive(_get(t, "k_Nm_per_rad", path, ctx), f"{path}.k_Nm_per_rad", ctx)
        joints.append(Joint(jname, parent, child, t.get("angle"), kind, k, float(t.get("angle_deg", 0.0))))
    joined = {j.child for j in joints}
    for lk in links[1:]:
        if lk.name not in joined:
            raise ctx.fail("joint", f"link {lk.name!r} is joined to nothing (add a [[joint]] with child)")
    refs = ({lk.name: lk for lk in links}, {j.name: j for j in joints})

    members = []
    for i, t in enumerate(doc.get("member", [])):
        path = f"member[{i}]"
        mname = _name(_get(t, "name", path, ctx), f"{path}.name", ctx)
        mat = _material(doc, t.get("material"), f"{path}.material", ctx)
        members.append(Member(
            mname,
            _parse_point(_get(t, "from", path, ctx), refs, f"{path}.from", ctx),
            _parse_point(_get(t, "to", path, ctx), refs, f"{path}.to", ctx),
            section_properties(_get(t, "section", path, ctx), mat, f"{path}.section", ctx),
            _choice(t.get("ends", "pin-pin"), MEMBER_ENDS, f"{path}.ends", ctx),
            _elements(t, path, ctx),
            _positive(t.get("end_k_Nm_per_rad", 0.0), f"{path}.end_k_Nm_per_rad", ctx, allow_zero=True),
        ))

    masses = []
    for i, t in enumerate(doc.get("mass", [])):
        path = f"mass[{i}]"
        m = _get(t, "mass_kg", path, ctx)
        if not isinstance(m, str):
            m = _positive(m, f"{path}.mass_kg", ctx, allow_zero=True)
        inertia = _positive(t.get("inertia_kgm2", 0.0), f"{path}.inertia_kgm2", ctx, allow_zero=True)
        at = _parse_point(_get(t, "at", path, ctx), refs, f"{path}.at", ctx)
        masses.append(Mass(at, m, inertia, str(t.get("name", ""))))

    springs = []
    for i, t in enumerate(doc.get("spring", [])):
        path = f"spring[{i}]"
        springs.append(Spring(
            _parse_point(_get(t, "at", path, ctx), refs, f"{path}.at", ctx),
            _positive(_get(t, "k_N_per_m", path, ctx), f"{path}.k_N_per_m", ctx),
            _choice(t.get("direction", "transverse"), SPRING_DIRECTIONS, f"{path}.direction", ctx),
            str(t.get("name", ""))))

    sensors = []
    for i, t in enumerate(doc.get("sensor", [])):
        path = f"sensor[{i}]"
        sensors.append(Sensor(
            _name(_get(t, "name", path, ctx), f"{path}.name", ctx),
            _parse_point(_get(t, "at", path, ctx), refs, f"{path}.at", ctx),
            _choice(t.get("direction", "transverse"), DIRECTIONS, f"{path}.direction", ctx),
            _positive(t.get("mass_kg", 0.0), f"{path}.mass_kg", ctx, allow_zero=True)))
    sensor_names = [s.name for s in sensors]
    if len(set(sensor_names)) != len(sensor_names):
        raise ctx.fail("sensor", f"duplicate sensor names in {sensor_names}")
    return Rig(name, links, tuple(joints), base, tuple(members), tuple(masses), tuple(springs),
               tuple(sensors), source)


def load_rig(path: str | Path) -> Rig:
    """Read and validate a rig TOML file (docs/formats.md)."""
    p = Path(path)
    try:
        with p.open("rb") as fh:
            doc = tomllib.load(fh)
    except FileNotFoundError:
        raise ModelError(f"{p}: rig file not found") from None
    except tomllib.TOMLDecodeError as exc:
        raise ModelError(f"{p}: not valid TOML ({exc})") from None
    return parse_rig(doc, str(p))
