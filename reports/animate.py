"""Animated mode shapes: inline SVG for the self-contained report, animated GIF for slides.

A :class:`Shape` is one mode on the structure, already in the drawing plane: undeformed points ``xy``
[n, 2] (m), their displacement ``disp`` [n, 2] (complex, exaggerated for display), the polylines to
draw through them and the points to mark (sensors).  A frame at phase φ draws ``xy + Re(disp e^{iφ})``,
so every point moves along its own shape vector (a complex shape traces an ellipse).

Shapes come from the rig (:func:`arm_pairs`: the planar arm at a configuration's pose, the measured
shape at the sensors beside the frame FE model's best-matching mode along the links) or from a test
geometry (:func:`geometry_shapes`: a Universal File's nodes and trace lines, reports/geometry.py; a 3-D
structure is drawn in an axonometric view).

:func:`svg` writes one shape as an ``<svg>`` whose data sit in a ``data-shape`` attribute; the page's
one :data:`SCRIPT` moves every such shape (click one to pause; nothing is fetched).  :func:`write_gif`
draws shapes side by side in a ``matplotlib.figure.Figure`` and saves the loop with
``matplotlib.animation.PillowWriter``.
"""

from __future__ import annotations

import html
import json
import math
import shutil
import tempfile
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from flexmodal.contract.mac import mac, to_real
from flexmodal.contract.table import ModalTable
from flexmodal.reports.errors import ReportError
from flexmodal.reports.geometry import Geometry

EXAGGERATION = 0.12        # largest displacement drawn as this share of the structure's extent
PERIOD_MS = 1600           # one cycle of the animation
AZIMUTH_DEG, ELEVATION_DEG = -50.0, 25.0   # axonometric view of a 3-D geometry


@dataclass(frozen=True)
class Shape:
    """One mode to animate (see the module docstring): ``title``, ``xy`` [n, 2] m, ``disp`` [n, 2]
    complex (display scale), ``lines`` (index tuples drawn as polylines), ``dots`` (indices marked)."""

    title: str
    xy: np.ndarray
    disp: np.ndarray
    lines: tuple[tuple[int, ...], ...]
    dots: tuple[int, ...] = ()

    def at(self, phase: float) -> np.ndarray:
        """Point positions [n, 2] (m) at ``phase`` [rad]: ``xy + Re(disp e^{i phase})``."""
        return self.xy + (self.disp * np.exp(1j * phase)).real


def _scaled(xy: np.ndarray, disp: np.ndarray) -> np.ndarray:
    """``disp`` scaled so its largest amplitude is EXAGGERATION of the extent of ``xy``."""
    extent = float(np.ptp(xy, axis=0).max()) or 1.0
    biggest = float(np.abs(disp).max())
    return disp * (EXAGGERATION * extent / biggest) if biggest > 0 else disp


def view(xyz: np.ndarray) -> np.ndarray:
    """Drawing-plane projection [.., 3] -> [.., 2]: x, y for a structure in the xy plane, else an
    axonometric view (azimuth AZIMUTH_DEG about z, then elevation ELEVATION_DEG)."""
    xyz = np.asarray(xyz)
    a, e = math.radians(AZIMUTH_DEG), math.radians(ELEVATION_DEG)
    right = np.array([-math.sin(a), math.cos(a), 0.0])
    up = np.array([-math.cos(a) * math.sin(e), -math.sin(a) * math.sin(e), math.cos(e)])
    return np.stack([xyz @ right, xyz @ up], axis=-1)


def geometry_shapes(geometry: Geometry, table: ModalTable, config: str) -> list[Shape]:
    """Each mode of ``config`` in ``table`` on the test geometry: the table's shape columns name the
    measured directions (``shape.3+z``), turned into global displacements by the nodes' systems."""
    sensors = table.sensors
    if not sensors:
        raise ReportError(f"{table.source}: no mode shapes to animate")
    shapes = table.shapes(config, sensors)
    freqs = table.freq_hz(config)
    directions = np.array([geometry.direction(s)[1] for s in sensors])
    planar = bool(np.ptp(geometry.xyz[:, 2]) == 0 and np.allclose(directions[:, 2], 0))
    flat = geometry.xyz[:, :2] if planar else view(geometry.xyz)
    out = []
    for k in range(shapes.shape[1]):
        disp3 = geometry.displacement({s: np.nan_to_num(shapes[i, k]) for i, s in enumerate(sensors)})
        disp = disp3[:, :2] if planar else view(disp3.real) + 1j * view(disp3.imag)
        out.append(Shape(f"mode {k + 1}: {freqs[k]:.4g} Hz", flat, _scaled(flat, disp), geometry.lines,
                         tuple(sorted({geometry.direction(s)[0] for s in sensors}))))
    return out


def arm_pairs(arm, measured: ModalTable, config: str, n_predicted: int | None = None
              ) -> list[tuple[Shape | None, Shape | None]]:
    """(test, model) per measured mode of ``config`` on the planar arm, and (None, model) for each
    further FE mode among the lowest ``n_predicted`` that no measured mode pairs with.

    ``arm``: a ``models.arm_shapes.ArmModes`` at the configuration's pose.  Test: the measured shape
    at the sensors (each along its measuring direction), joined from the arm's base along the arm.
    Model: the FE mode with the highest MAC at the sensors, along the links, signed to move in phase
    with the test.
    """
    names = list(arm.sensor_names)
    if len(names) < 2:
        raise ReportError(f"{measured.source}: needs shapes at two or more of the rig's sensors to animate")
    measured_shapes = to_real(np.nan_to_num(measured.shapes(config, names)))
    freqs = measured.freq_hz(config)
    macs = mac(measured_shapes, arm.sensor_disp)
    curve = np.concatenate(arm.link_xy)
    model_disp = np.concatenate([d[:, :, None] * arm.link_normal[i] for i, d in enumerate(arm.link_disp)])
    along = np.argsort([int(np.argmin(np.linalg.norm(curve - p, axis=1))) for p in arm.sensor_xy])
    test_xy = np.vstack([curve[:1], arm.sensor_xy[along]])
    test_line = (tuple(range(len(test_xy))),)
    model_line = (tuple(range(len(curve))),)          # the links, base to tip, as one line

    def model(j: int, sign: float = 1.0) -> Shape:
        return Shape(f"FE mode {j + 1}: {arm.freq_hz[j]:.4g} Hz", curve,
                     _scaled(curve, sign * model_disp[:, j, :]).astype(complex), model_line)

    pairs: list[tuple[Shape | None, Shape | None]] = []
    used = set()
    for k in range(measured_shapes.shape[1]):
        j = int(np.argmax(np.nan_to_num(macs[k], nan=-1.0)))   # a zero shape: MAC undefined
        used.add(j)
        disp = np.vstack([np.zeros((1, 2)), (measured_shapes[:, k, None] * arm.sensor_dir)[along]])
        test = Shape(f"mode {k + 1}: {freqs[k]:.4g} Hz (MAC {macs[k, j]:.2f} with FE mode {j + 1})", test_xy,
                     _scaled(test_xy, disp).astype(complex), test_line, tuple(range(1, len(test_xy))))
        in_phase = float(arm.sensor_disp[:, j] @ measured_shapes[:, k]) >= 0   # shapes' signs are arbitrary
        pairs.append((test, model(j, 1.0 if in_phase else -1.0)))
    last = len(arm.freq_hz) if n_predicted is None else min(n_predicted, len(arm.freq_hz))
    pairs += [(None, model(j)) for j in range(last) if j not in used and arm.freq_hz[j] > 0]
    return pairs


def _box(shape: Shape) -> tuple[float, float, float, float]:
    """(x0, y0, width, height) holding every frame of ``shape``, with a margin."""
    amp = np.abs(shape.disp)
    lo, hi = (shape.xy - amp).min(axis=0), (shape.xy + amp).max(axis=0)
    pad = 0.06 * float(max(hi - lo)) or 0.05
    size = hi - lo + 2 * pad
    return float(lo[0] - pad), float(lo[1] - pad), float(size[0]), float(size[1])


def svg(shape: Shape, width_px: int = 260) -> str:
    """One animated shape as an inline ``<svg>`` (y up; the data in ``data-shape`` for :data:`SCRIPT`),
    showing the undeformed structure (grey) and the moving one."""
    x0, y0, w, h = _box(shape)
    height_px = int(round(width_px * min(max(h / w, 0.3), 1.2)))
    flip = np.array([1.0, -1.0])
    xy = shape.xy * flip
    d = shape.disp * flip
    data = {"p": np.round(xy, 6).tolist(),
            "d": np.round(np.column_stack([d.real, d.imag]), 6).tolist(),
            "lines": [list(line) for line in shape.lines], "dots": list(shape.dots)}
    stroke = 0.008 * max(w, h)

    def pts(line: Sequence[int]) -> str:
        return " ".join(f"{xy[i, 0]:.5g},{xy[i, 1]:.5g}" for i in line)

    parts = [f'<svg class="fm-shape" role="img" '
             f'aria-label="{html.escape(shape.title)}" width="{width_px}" height="{height_px}" '
             f'viewBox="{x0:.5g} {-(y0 + h):.5g} {w:.5g} {h:.5g}" preserveAspectRatio="xMidYMid meet" '
             f"data-shape='{html.escape(json.dumps(data, separators=(',', ':')), quote=True)}'>"]
    parts += [f'<polyline class="fm-rest" points="{pts(line)}" fill="none" stroke="#bbb" '
              f'stroke-width="{stroke:.4g}" stroke-dasharray="{3 * stroke:.4g}"/>' for line in shape.lines]
    parts += [f'<polyline class="fm-moving" points="{pts(line)}" fill="none" stroke="#1f77b4" '
              f'stroke-width="{1.6 * stroke:.4g}" stroke-linejoin="round"/>' for line in shape.lines]
    parts += [f'<circle class="fm-node" cx="{xy[i, 0]:.5g}" cy="{xy[i, 1]:.5g}" r="{2.2 * stroke:.4g}" '
              f'fill="#d62728"/>' for i in shape.dots]
    parts.append("</svg>")
    return "".join(parts)


# Moves every svg.fm-shape of the page: positions p + Re(d e^{i phase}); a click pauses or resumes.
SCRIPT = """(() => {
  const shapes = [...document.querySelectorAll("svg.fm-shape")].map(svg => ({
    data: JSON.parse(svg.dataset.shape), lines: [...svg.querySelectorAll(".fm-moving")],
    dots: [...svg.querySelectorAll(".fm-node")]}));
  const draw = phase => {
    const c = Math.cos(phase), s = Math.sin(phase);
    for (const {data, lines, dots} of shapes) {
      const at = i => [data.p[i][0] + data.d[i][0] * c - data.d[i][2] * s,
                       data.p[i][1] + data.d[i][1] * c - data.d[i][3] * s];
      data.lines.forEach((line, k) => lines[k].setAttribute("points",
        line.map(i => at(i).map(v => v.toFixed(5)).join(",")).join(" ")));
      data.dots.forEach((i, k) => { const [x, y] = at(i);
        dots[k].setAttribute("cx", x.toFixed(5)); dots[k].setAttribute("cy", y.toFixed(5)); });
    }
  };
  let paused = false;
  const tick = now => {
    if (!paused) draw(2 * Math.PI * (now % PERIOD) / PERIOD);
    requestAnimationFrame(tick);
  };
  document.addEventListener("click", e => { if (e.target.closest("svg.fm-shape")) paused = !paused; });
  window.flexmodalShapes = {draw, count: shapes.length, pause: () => { paused = true; }};
  if (shapes.length) requestAnimationFrame(tick);
})();""".replace("PERIOD", str(PERIOD_MS))


def write_gif(shapes: Sequence[Shape], path: str | Path, frames: int = 24, fps: int = 12,
              width_in: float = 4.0) -> Path:
    """Shapes side by side, animated over one cycle (``frames`` frames at ``fps``), saved as an
    animated GIF at ``path`` with matplotlib's PillowWriter (moved into place whole); returns ``path``."""
    from matplotlib.animation import FuncAnimation, PillowWriter
    from matplotlib.figure import Figure

    from flexmodal.checked_io.output import atomic_path
    from flexmodal.reports.plots import text

    if not shapes:
        raise ReportError("animation: no shapes to draw")
    fig = Figure(figsize=(width_in * len(shapes), width_in * 0.8), layout="constrained")
    axes = np.atleast_1d(fig.subplots(1, len(shapes), squeeze=False)).ravel()
    moving = []
    for ax, shape in zip(axes, shapes, strict=True):
        x0, y0, w, h = _box(shape)
        for line in shape.lines:
            ax.plot(*shape.xy[list(line)].T, color="0.75", lw=1.2, ls="--")
        lines = [ax.plot(*shape.xy[list(line)].T, color="#1f77b4", lw=2)[0] for line in shape.lines]
        dots = ax.plot(*shape.xy[list(shape.dots)].T, "o", color="#d62728", ms=5)[0] if shape.dots else None
        moving.append((shape, lines, dots))
        ax.set_xlim(x0, x0 + w)
        ax.set_ylim(y0, y0 + h)
        ax.set_aspect("equal")
        ax.set_axis_off()
        ax.set_title(text(shape.title), fontsize=9)

    def frame(k: int):
        changed = []
        for shape, lines, dots in moving:
            at = shape.at(2 * math.pi * k / frames)
            for artist, line in zip(lines, shape.lines, strict=True):
                artist.set_data(*at[list(line)].T)
                changed.append(artist)
            if dots is not None:
                dots.set_data(*at[list(shape.dots)].T)
                changed.append(dots)
        return changed

    target = Path(path)
    with tempfile.TemporaryDirectory(prefix="flexmodal-gif-") as folder, atomic_path(target) as part:
        gif = Path(folder) / "shapes.gif"          # PillowWriter picks the format from the suffix
        FuncAnimation(fig, frame, frames=frames, blit=False).save(str(gif), writer=PillowWriter(fps=fps),
                                                                   dpi=80)
        shutil.copyfile(gif, part)
    return target
