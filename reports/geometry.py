"""Test geometry for drawing and animating mode shapes: nodes, trace lines, displacement directions.

From a Universal File (read with pyuff): nodes from dataset 15 (single precision) or 2411 (double
precision), each with its definition and displacement coordinate system; trace lines from dataset 82
(node lists, a 0 lifts the pen); coordinate systems from dataset 18 (origin, a point on the x axis
and a point in the xz plane, in the reference system ``ref_cs_num``) or 2420 (a 4 x 3 matrix: the
local x, y and z axes as rows in global coordinates, then the origin).  A node's position is taken in
its definition system, a measured direction (``3+z``: node 3, local +z) in its displacement system;
both are turned into global coordinates [m, as in the file] here.  Only Cartesian systems are read.

For a planar arm the geometry is the rig at a pose (``models.arm_shapes.ArmModes``), not a file.
"""

from __future__ import annotations

import re
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from flexmodal.checked_io.text import shown_value
from flexmodal.reports.errors import ReportError

_DOF = re.compile(r"^(\d+)([+-])([xyz])$")
NODE_DIGITS = 10   # a UFF node number is an I10 field: a sensor naming a longer one names no node


@dataclass(frozen=True)
class Geometry:
    """Nodes ``xyz`` [n_nodes, 3] (global), their numbers ``nodes``, the displacement axes of each node
    ``axes`` [n_nodes, 3, 3] (rows: local x, y, z in global coordinates) and the trace ``lines``
    (tuples of node indices into ``xyz``, each drawn as one polyline)."""

    xyz: np.ndarray
    nodes: tuple[int, ...]
    axes: np.ndarray
    lines: tuple[tuple[int, ...], ...]
    source: str = "<geometry>"

    def direction(self, dof: str) -> tuple[int, np.ndarray]:
        """(node index, global unit vector) of a measured direction named ``<node><sign><axis>``
        (``3+z``, as modal.uff names channels); ReportError for a name or node not in the geometry."""
        m = _DOF.match(dof)
        if not m:
            raise ReportError(f"{self.source}: sensor {dof!r} is not named <node><+|-><x|y|z> (e.g. 3+z)")
        digits, sign, axis = m.group(1).lstrip("0") or "0", m.group(2), "xyz".index(m.group(3))
        node = int(digits) if len(digits) <= NODE_DIGITS else None   # 5000 digits: no int, and no node
        if node not in self.nodes:
            shown = node if node is not None else f"{digits[:12]}... ({len(digits)} digits)"
            raise ReportError(f"{self.source}: sensor {shown_value(dof, 60)}: no node {shown} in the "
                              "geometry")
        k = self.nodes.index(node)
        return k, (1.0 if sign == "+" else -1.0) * self.axes[k, axis]

    def displacement(self, shape: Mapping[str, complex]) -> np.ndarray:
        """Displacement [n_nodes, 3] (complex) of a shape given per measured direction
        (``{"3+z": 0.4, ...}``); a node measured in several directions sums them, unmeasured nodes stay."""
        disp = np.zeros((len(self.nodes), 3), complex)
        for dof, value in shape.items():
            k, unit = self.direction(dof)
            disp[k] += complex(value) * unit
        return disp


def _frame_18(s: dict) -> dict[int, tuple[np.ndarray, np.ndarray]]:
    """{cs number: (rows x, y, z [3, 3], origin [3])} of a dataset 18 (in its reference systems)."""
    out: dict[int, tuple[np.ndarray, np.ndarray]] = {}
    raw = {int(n): (int(ref), np.asarray(o, float), np.asarray(xp, float), np.asarray(xz, float), int(t))
           for n, ref, o, xp, xz, t in zip(s["cs_num"], s["ref_cs_num"], s["ref_o"], s["x_point"],
                                           s["xz_point"], s["cs_type"], strict=True)}

    def resolve(n: int, depth: int = 0) -> tuple[np.ndarray, np.ndarray]:
        if n == 0:
            return np.eye(3), np.zeros(3)
        if n in out:
            return out[n]
        if n not in raw or depth > len(raw):
            raise ReportError(f"coordinate system {n} is not defined (or refers to itself)")
        ref, o, xp, xz, kind = raw[n]
        if kind != 0:
            raise ReportError(f"coordinate system {n} is not Cartesian (type {kind})")
        ex = xp - o
        ey = np.cross(xz - o, ex)
        if np.linalg.norm(ex) == 0 or np.linalg.norm(ey) == 0:
            raise ReportError(f"coordinate system {n}: its three points do not span a plane")
        ex, ey = ex / np.linalg.norm(ex), ey / np.linalg.norm(ey)
        local = np.array([ex, ey, np.cross(ex, ey)])
        rot, origin = resolve(ref, depth + 1)
        out[n] = (local @ rot, origin + o @ rot)
        return out[n]

    for n in raw:
        resolve(n)
    return out


def _frame_2420(s: dict) -> dict[int, tuple[np.ndarray, np.ndarray]]:
    out = {}
    for n, kind, m in zip(s["CS_sys_labels"], s["CS_types"], s["CS_matrices"], strict=True):
        if int(kind) != 0:
            raise ReportError(f"coordinate system {int(n)} is not Cartesian (type {int(kind)})")
        m = np.asarray(m, float).reshape(4, 3)
        out[int(n)] = (m[:3], m[3])
    return out


def read_uff_geometry(path: str | Path) -> Geometry:
    """The test geometry of a Universal File: nodes (15 or 2411), trace lines (82), coordinate systems
    (18 or 2420).  ReportError naming the file when it holds no nodes or a line names a missing node."""
    import pyuff

    from flexmodal.checked_io.text import fits_in_memory
    from flexmodal.checked_io.uff_blocks import check_blocks

    p = fits_in_memory(path, ReportError, "geometry file")   # no FIFO, device or file beyond memory
    try:
        check_blocks(p, p.read_bytes(), ReportError)
        sets = pyuff.UFF(str(p)).read_sets()
    except ReportError:
        raise
    except Exception as exc:  # pyuff raises bare Exceptions and parse errors of every kind
        raise ReportError(f"{p}: not a readable Universal File ({exc})") from None
    sets = [sets] if isinstance(sets, dict) else sets
    frames: dict[int, tuple[np.ndarray, np.ndarray]] = {}
    nodes: list[int] = []
    xyz, def_cs, disp_cs = [], [], []
    traces: list[np.ndarray] = []
    try:
        for s in sets:
            kind = int(s["type"])
            if kind == 18:
                frames.update(_frame_18(s))
            elif kind == 2420:
                frames.update(_frame_2420(s))
            elif kind in (15, 2411):
                nodes += [int(n) for n in s["node_nums"]]
                xyz += list(np.column_stack([s["x"], s["y"], s["z"]]).astype(float))
                def_cs += [int(c) for c in s["def_cs"]]
                disp_cs += [int(c) for c in s["disp_cs"]]
            elif kind == 82:
                traces.append(np.asarray(s["nodes"], int)[: max(int(s["n_nodes"]), 0)])
    except ReportError as exc:
        raise ReportError(f"{p}: {exc}") from None
    if not nodes:
        raise ReportError(f"{p}: no nodes (UFF dataset 15 or 2411) in the file")

    def frame(n: int) -> tuple[np.ndarray, np.ndarray]:
        if n == 0:
            return np.eye(3), np.zeros(3)
        if n not in frames:
            raise ReportError(f"{p}: coordinate system {n} is used by a node but not defined "
                              "(dataset 18 or 2420)")
        return frames[n]

    points = np.array([frame(c)[1] + np.asarray(x) @ frame(c)[0] for x, c in zip(xyz, def_cs, strict=True)])
    axes = np.array([frame(c)[0] for c in disp_cs])
    index = {n: k for k, n in enumerate(nodes)}
    lines = []
    for trace in traces:
        for run in np.split(trace, np.flatnonzero(trace == 0)):
            run = run[run != 0]
            missing = [int(n) for n in run if int(n) not in index]
            if missing:
                raise ReportError(f"{p}: trace line names node {missing[0]}, which has no coordinates")
            if run.size >= 2:
                lines.append(tuple(index[int(n)] for n in run))
    return Geometry(points, tuple(nodes), axes, tuple(lines), str(p))
