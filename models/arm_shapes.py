"""Frame FE mode shapes of a rig at a pose, sampled along the links for drawing on the arm.

What the sensors see is what is sampled: displacement normal to each link (so every link is its own
curve and the axial motion the accelerometers do not measure is left out), and at each sensor the
displacement along its own direction (transverse or axial).  ``reports.plots.plot_mode_shapes`` draws
the result; it solves nothing itself.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np

from flexmodal.models.errors import ModelError
from flexmodal.models.frame import assemble, link_geometry, solve_modes
from flexmodal.models.rig import Rig


@dataclass(frozen=True, eq=False)
class ArmModes:
    """The lowest frame FE modes of a rig at one pose, sampled for drawing.

    ``freq_hz`` [n_modes] (rigid-body modes at 0 Hz included); per link ``link_xy`` [n_points, 2] (m,
    undeformed) and ``link_disp`` [n_points, n_modes] (displacement normal to the link, along
    ``link_normal`` [n_links, 2]; mass-normalised shapes, m per sqrt(kg)); per sensor ``sensor_xy``
    [n_sensors, 2] (m), ``sensor_dir`` [n_sensors, 2] (unit vector of what it measures) and
    ``sensor_disp`` [n_sensors, n_modes] (the same shapes at the sensors).
    """

    freq_hz: np.ndarray
    link_xy: tuple[np.ndarray, ...]
    link_normal: np.ndarray
    link_disp: tuple[np.ndarray, ...]
    sensor_names: tuple[str, ...]
    sensor_xy: np.ndarray
    sensor_dir: np.ndarray
    sensor_disp: np.ndarray


def arm_modes(rig: Rig, pose: Mapping[str, float], sensors: Sequence[str] | None = None, n_modes: int = 8,
              points_per_link: int = 25) -> ArmModes:
    """Solve the frame FE model (models.frame) of ``rig`` at ``pose`` (degrees, kg) for its ``n_modes``
    lowest modes (at most its DOF count) and sample them along each link and at ``sensors`` (names;
    default every sensor of the rig, in the rig's order)."""
    names = [s.name for s in rig.sensors] if sensors is None else list(sensors)
    unknown = [n for n in names if n not in {s.name for s in rig.sensors}]
    if unknown:
        raise ModelError(f"{rig.source}: no sensor {unknown[0]!r}")
    chosen = [next(s for s in rig.sensors if s.name == n) for n in names]
    system = assemble(rig, pose)
    fe = solve_modes(system, min(n_modes, system.n_dof))
    angles, starts = link_geometry(rig, pose)
    along = np.column_stack([np.cos(angles), np.sin(angles)])    # unit vector along each link
    normal = np.column_stack([-along[:, 1], along[:, 0]])
    fractions = np.linspace(0.0, 1.0, points_per_link)
    link_xy = tuple(starts[i] + np.outer(fractions * lk.length_m, along[i]) for i, lk in enumerate(rig.links))
    link_disp = tuple(np.array([system.observe(f"{lk.name}@{f:.6f}", "transverse") for f in fractions])
                      @ fe.phi for lk in rig.links)
    links = [lk.name for lk in rig.links]
    sensor_xy = np.array([starts[links.index(s.at.link)]
                          + s.at.fraction * rig.links[links.index(s.at.link)].length_m
                          * along[links.index(s.at.link)] for s in chosen]).reshape(-1, 2)
    sensor_dir = np.array([normal[links.index(s.at.link)] if s.direction == "transverse"
                           else along[links.index(s.at.link)] for s in chosen]).reshape(-1, 2)
    rows = np.array([system.observe(str(s.at), s.direction) for s in chosen]).reshape(-1, system.n_dof)
    return ArmModes(fe.freq_hz, link_xy, normal, link_disp, tuple(names), sensor_xy, sensor_dir,
                    rows @ fe.phi)
