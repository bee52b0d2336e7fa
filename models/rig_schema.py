"""Shape of a rig TOML document (docs/formats.md, rig TOML) before its values are read.

:func:`flexmodal.models.rig.parse_rig` reads values field by field; this module first checks the
containers and the fields whose wrong type would otherwise escape as a Python exception or pass
silently: the array-of-tables keys must hold tables, ``base`` must be a table, pose-variable names must
be strings and fixed angles finite numbers, cross-section sizes and material constants must lie in a
range where the section formulas stay finite (``(1e300)**4`` overflows), element counts must stay
small enough for the dense eigenproblem (``elements = 2000000000`` would never finish), and every key
must be one its table has (:data:`KEYS`, :data:`SECTION_KEYS`): a misspelt optional key would
otherwise be left out of the model in silence.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Any

from flexmodal.checked_io.text import name_fault
from flexmodal.models.errors import ModelError

TABLE_ARRAYS = ("link", "joint", "member", "mass", "spring", "sensor")
MAX_ELEMENTS = 500  # per link or member
MIN_SIZE_M, MAX_SIZE_M = 1e-6, 1e3  # a cross-section dimension or a link's length, m (1 micrometre to 1 km)
MIN_E_PA, MAX_E_PA = 1e3, 1e13  # Young's modulus (soft gels: 1e3 Pa; diamond: 1.2e12 Pa)
MIN_RHO_KG_M3, MAX_RHO_KG_M3 = 0.1, 1e5  # density (aerographite: 0.2 kg/m^3; osmium: 2.3e4 kg/m^3)
# below these a typo (E_Pa = 1e-30, a length in km written as m) left "only 0 elastic modes available"
KEYS = {  # the keys each table may hold (docs/formats.md, Rig TOML): any other is a typo, refused
    "top level": {"name", "material", "base", *TABLE_ARRAYS},
    "material": {"E_Pa", "rho_kg_m3", "nu"},
    "link": {"name", "length_m", "material", "section", "elements", "segments", "stiffness_scale",
             "mass_scale"},
    "segments": {"from", "to", "section", "material"},
    "base": {"support", "k_Nm_per_rad", "angle", "angle_deg"},
    "joint": {"name", "parent", "child", "angle", "angle_deg", "kind", "k_Nm_per_rad"},
    "member": {"name", "from", "to", "section", "material", "ends", "elements", "end_k_Nm_per_rad"},
    "mass": {"at", "mass_kg", "inertia_kgm2", "name"},
    "spring": {"at", "k_N_per_m", "direction", "name"},
    "sensor": {"name", "at", "direction", "mass_kg"},
}
MAX_BY_UNIT = (  # largest magnitude of a field by the unit its name ends with (longest suffix first):
    ("_Nm_per_rad", 1e20),   # a joint, base or member-end spring (a rigid joint is kind = "rigid")
    ("_N_per_m", 1e20),      # a grounded spring
    ("_kgm2", 1e6), ("_kgm", 1e6), ("_kg", 1e6),   # masses, inertias, mass per metre (1000 t)
    ("_Nm2", 1e20), ("_N", 1e22),                  # custom section EI and EA
    ("_scale", 1e6),                               # link stiffness and mass scales
)  # a stiff spring or section standing in for a clamp or a pin is a modelling idiom: the frame keeps a
# spring's compliance clean up to 1e20 (tests/test_models_frame.py), the known-answer tests clamp with
# 1e13-1e15; at 1e308 the matrices overflow. Masses beyond 1000 t are typos
SECTION_KEYS = {"square_tube": {"outer_m", "wall_m"}, "rect_tube": {"width_m", "height_m", "wall_m"},
                "round_tube": {"outer_m", "wall_m"}, "solid_rect": {"width_m", "height_m"},
                "custom": {"EA_N", "EI_Nm2", "mass_per_m_kg", "rotary_inertia_per_m_kgm", "depth_m"}}
SECTION_COMMON_KEYS = {"shape", "shear_coefficient"}  # keys of a section of any shape


def _fail(source: str, path: str, what: str) -> ModelError:
    return ModelError(f"{source}: {path}: {what}")


def _number(value: Any) -> bool:
    """A finite number: an int or float, not a bool, not inf or NaN, and an int no larger than a float
    holds (TOML integers have no size limit; ``math.isfinite(10**400)`` raises OverflowError)."""
    if not isinstance(value, int | float) or isinstance(value, bool):
        return False
    try:
        return math.isfinite(value)
    except OverflowError:
        return False


def _tables(doc: Mapping[str, Any], key: str, source: str) -> list[Mapping[str, Any]]:
    value = doc.get(key, [])
    if not isinstance(value, list) or not all(isinstance(t, Mapping) for t in value):
        raise _fail(source, key, f"must be [[{key}]] tables (got {value!r:.60})")
    return value


def _known(t: Mapping[str, Any], kind: str, path: str, source: str) -> None:
    """Refuse the first key (alphabetically) of table ``t`` that a ``kind`` table does not have: a
    misspelt optional key (``inertia_kg_m2``, ``[[sensors]]``) would otherwise be dropped in silence and
    the model built without it."""
    extra = sorted(set(t) - KEYS[kind])
    if extra:
        where = f"{path}.{extra[0]}" if path else extra[0]
        raise _fail(source, where, f"unknown key (a {kind} table has {', '.join(sorted(KEYS[kind]))})")


def _section(spec: Any, path: str, source: str) -> None:
    if not isinstance(spec, Mapping):
        return  # parse_rig names a missing or non-table section
    shape = spec.get("shape")
    allowed = SECTION_KEYS.get(shape) if isinstance(shape, str) else None  # other shapes: parse_rig
    extra = sorted(set(spec) - SECTION_COMMON_KEYS - allowed) if allowed is not None else []
    if extra:
        has = sorted(allowed | SECTION_COMMON_KEYS - {"shape"})
        raise _fail(source, f"{path}.{extra[0]}", f"unknown key for shape {spec['shape']!r} (it has "
                                                  f"{', '.join(has)})")
    _sizes(spec, path, source)


def _sizes(t: Mapping[str, Any], path: str, source: str) -> None:
    """Refuse a length (a key ending in ``_m``) outside [:data:`MIN_SIZE_M`, :data:`MAX_SIZE_M`] (0 and
    negative lengths are parse_rig's to name)."""
    for key, value in t.items():
        if key.endswith("_m") and _number(value) and value > 0 and not MIN_SIZE_M <= value <= MAX_SIZE_M:
            raise _fail(source, f"{path}.{key}", f"{value!r} m is out of range ({MIN_SIZE_M:g} to "
                                                 f"{MAX_SIZE_M:g} m)")


def _magnitudes(node: Any, path: str, source: str) -> None:
    """Refuse the first number whose magnitude exceeds the bound of its unit (:data:`MAX_BY_UNIT`),
    anywhere in the document (iterative walk over tables and arrays)."""
    stack = [(node, path)]
    while stack:
        value, where = stack.pop()
        if isinstance(value, Mapping):
            stack += [(v, f"{where}.{k}" if where else str(k)) for k, v in value.items()]
        elif isinstance(value, list):
            stack += [(v, f"{where}[{i}]") for i, v in enumerate(value)]
        elif _number(value):
            key = where.rsplit(".", 1)[-1]
            top = next((top for unit, top in MAX_BY_UNIT if key.endswith(unit)), None)
            if top is not None and abs(value) > top:
                raise _fail(source, where, f"{value!r} is out of range (at most {top:g} in magnitude)")


def _elements(t: Mapping[str, Any], path: str, source: str) -> None:
    n = t.get("elements")
    if isinstance(n, int) and not isinstance(n, bool) and n > MAX_ELEMENTS:
        raise _fail(source, f"{path}.elements", f"{n} is more than {MAX_ELEMENTS} elements")


def _pose_variable(t: Mapping[str, Any], path: str, source: str) -> None:
    if "angle" in t and not (isinstance(t["angle"], str) and t["angle"].strip()):
        raise _fail(source, f"{path}.angle", f"must name a pose variable such as \"theta_deg\" "
                                             f"(got {t['angle']!r})")
    if "angle_deg" in t and not _number(t["angle_deg"]):
        raise _fail(source, f"{path}.angle_deg",
                    f"must be a finite number of degrees (got {t['angle_deg']!r})")


def _names(doc: Mapping[str, Any], tables: Mapping[str, list], source: str) -> None:
    """Refuse a name (of the rig, a material, link, joint, member, mass, spring or sensor, or a joint's
    pose variable) that is blank or holds a control character (checked_io.text.name_fault)."""
    named = [("name", doc.get("name"))] + [(f"material.{k!r}", k) for k in doc.get("material", {})]
    named += [(f"{key}[{i}].{field}", t.get(field)) for key, ts in tables.items() for i, t in enumerate(ts)
              for field in ("name", "angle")]
    named += [("base.angle", doc.get("base", {}).get("angle"))]
    for path, value in named:
        fault = name_fault(value) if isinstance(value, str) else None
        if fault:
            raise _fail(source, path, f"{value!r} {fault}")


def _poisson(materials: Mapping[str, Any], source: str) -> None:
    """``nu`` (optional) is Poisson's ratio of an isotropic material: a finite number in (-1, 0.5), the
    range ``models.rig.Shear`` takes (0.5 is an incompressible solid, no metal)."""
    for name, m in materials.items():
        if "nu" in m and not (_number(m["nu"]) and -1.0 < m["nu"] < 0.5):
            raise _fail(source, f"material.{name}.nu", f"must be Poisson's ratio, a number in (-1, 0.5) "
                                                       f"(got {m['nu']!r:.60})")


def check_document(doc: Any, source: str) -> None:
    """Raise ModelError naming the first field whose container or type is wrong (see module doc)."""
    if not isinstance(doc, Mapping):
        raise ModelError(f"{source}: a rig description must be a TOML table")
    if "name" in doc and not isinstance(doc["name"], str):
        raise _fail(source, "name", f"must be a string (got {doc['name']!r})")
    materials = doc.get("material", {})
    if not isinstance(materials, Mapping):
        raise _fail(source, "material", "must be [material.<name>] tables")
    for name, m in materials.items():
        if not isinstance(m, Mapping):
            raise _fail(source, f"material.{name}", "must be a table with E_Pa and rho_kg_m3")
        _known(m, "material", f"material.{name}", source)
        for key, low, top in (("E_Pa", MIN_E_PA, MAX_E_PA), ("rho_kg_m3", MIN_RHO_KG_M3, MAX_RHO_KG_M3)):
            if _number(m.get(key)) and m[key] > top:
                raise _fail(source, f"material.{name}.{key}", f"{m[key]!r} is out of range (at most {top:g})")
            if _number(m.get(key)) and 0 < m[key] < low:
                raise _fail(source, f"material.{name}.{key}",
                            f"{m[key]!r} is out of range (at least {low:g}; SI units)")
    base = doc.get("base", {})
    if not isinstance(base, Mapping):
        raise _fail(source, "base", f"must be a [base] table (got {base!r:.60})")
    _known(base, "base", "base", source)
    _pose_variable(base, "base", source)
    tables = {key: _tables(doc, key, source) for key in TABLE_ARRAYS}
    _known(doc, "top level", "", source)
    for key, ts in tables.items():
        for i, t in enumerate(ts):
            _known(t, key, f"{key}[{i}]", source)
            if isinstance(t.get("material"), Mapping):
                _known(t["material"], "material", f"{key}[{i}].material", source)
    for i, t in enumerate(tables["link"]):
        path = f"link[{i}]"
        _elements(t, path, source)
        _sizes(t, path, source)
        _section(t.get("section"), f"{path}.section", source)
        segments = _tables(t, "segments", f"{source}: {path}")
        for j, seg in enumerate(segments):
            _known(seg, "segments", f"{path}.segments[{j}]", source)
            _section(seg.get("section"), f"{path}.segments[{j}].section", source)
    for i, t in enumerate(tables["member"]):
        _elements(t, f"member[{i}]", source)
        _section(t.get("section"), f"member[{i}].section", source)
    for i, t in enumerate(tables["joint"]):
        _pose_variable(t, f"joint[{i}]", source)
    _magnitudes({k: v for k, v in doc.items() if k != "material"}, "", source)
    _poisson(materials, source)
    _names(doc, tables, source)
