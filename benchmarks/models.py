"""Benchmark of the planar frame FE (models/frame.py) on the seed 003 two-link arm.

Run: ``python benchmarks/models.py`` (from the repository root).  Prints, to stdout:
1. time per pose (assembly + 4 modes) and convergence of f1..f4 versus elements per link;
2. 1000 poses at 10 elements per link;
3. the same systems solved by a plain dense scipy ``eigh(K, M)`` of all modes (reference);
4. OpenSeesPy on the same mesh (elasticBeamColumn, consistent mass) if it imports here, with the
   frequency agreement against our FE without rotary inertia (OpenSees' beam mass has none).
BLAS runs single-threaded unless OPENBLAS_NUM_THREADS is set: on a shared 2-core machine, OpenBLAS
threads on these 60-500 DOF problems only contend (16 elements per link: 56 ms/pose threaded, 4.6 single).
"""

from __future__ import annotations

import ctypes
import math
import os
import time
from dataclasses import replace
from pathlib import Path

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")  # small dense problems: threads only contend

import numpy as np  # noqa: E402
from scipy.linalg import eigh  # noqa: E402

from flexmodal.models.frame import assemble, frame_modes, frame_modes_many  # noqa: E402
from flexmodal.models.rig import Rig, load_rig  # noqa: E402

RIG = Path(__file__).resolve().parents[1] / "examples" / "rigs" / "seed003_two_link.toml"
ANGLES = np.linspace(0.0, 150.0, 1000)


class Timing:
    """Wall-clock and process-CPU milliseconds per call (CPU time is what a quiet machine would show)."""

    def __init__(self, wall_ms: float, cpu_ms: float) -> None:
        self.wall_ms, self.cpu_ms = wall_ms, cpu_ms

    def __str__(self) -> str:
        return f"{self.wall_ms:.3f} ms wall / {self.cpu_ms:.3f} ms CPU"


def per_pose_ms(fn, poses, repeats: int = 3) -> Timing:
    """Best of ``repeats`` passes over ``poses`` (the least disturbed by other jobs, as timeit does)."""
    fn(poses[0])  # warm the topology cache
    best = Timing(math.inf, math.inf)
    for _ in range(repeats):
        t0, c0 = time.perf_counter(), time.process_time()
        for p in poses:
            fn(p)
        n = len(poses)
        wall, cpu = (time.perf_counter() - t0) / n * 1e3, (time.process_time() - c0) / n * 1e3
        best = Timing(min(best.wall_ms, wall), min(best.cpu_ms, cpu))
    return best


def element_sweep(rig: Rig) -> None:
    poses = [{"theta_deg": float(a)} for a in ANGLES[::10]]
    ref = frame_modes(rig, {"theta_deg": 0.0}, 4, elements_per_link=80).freq_hz
    print("## time per pose and convergence (theta = 0; reference: 80 elements per link)")
    heads = "  ".join(f"{f'f{i + 1} Hz':>9}" for i in range(4))
    print(f"{'elements/link':>13} {'wall ms':>8} {'CPU ms':>7}  {heads}   max |err| %")
    for n in (4, 6, 8, 10, 16, 20, 40):
        ms = per_pose_ms(lambda p, n=n: frame_modes(rig, p, 4, elements_per_link=n), poses)
        f = frame_modes(rig, {"theta_deg": 0.0}, 4, elements_per_link=n).freq_hz
        print(f"{n:>13} {ms.wall_ms:8.3f} {ms.cpu_ms:7.3f}  " + "  ".join(f"{v:9.3f}" for v in f)
              + f"   {100 * np.max(np.abs(f / ref - 1)):.4f}")


def many_poses(rig: Rig) -> float:
    poses = [{"theta_deg": float(a)} for a in ANGLES]
    frame_modes_many(rig, poses[:2])
    t0, c0 = time.perf_counter(), time.process_time()
    frame_modes_many(rig, poses)
    total, cpu = time.perf_counter() - t0, time.process_time() - c0
    print(f"\n## 1000 poses, 10 elements per link, 4 modes: {total:.3f} s wall, {cpu:.3f} s CPU")
    return total


def scipy_reference(rig: Rig) -> None:
    poses = [{"theta_deg": float(a)} for a in ANGLES[::5]]
    ours = per_pose_ms(lambda p: frame_modes(rig, p, 4), poses)

    def dense(p):
        s = assemble(rig, p)
        return eigh(s.K, s.M, eigvals_only=False)

    ref = per_pose_ms(dense, poses)
    print(f"\n## plain scipy reference (assembly + full dense eigh(K, M)): {ref} per pose; ours {ours}; "
          f"CPU ratio reference/ours = {ref.cpu_ms / ours.cpu_ms:.2f}")


def import_opensees():
    """openseespy, preloading the BLAS its wheel ships when the system has none; None if unavailable."""
    try:
        import openseespy.opensees as ops
        return ops
    except ImportError:
        return None
    except RuntimeError:
        pass
    try:
        import importlib.util

        spec = importlib.util.find_spec("openseespylinux")
        lib = Path(spec.origin).parent / "lib" / "libblas.so.3"  # type: ignore[union-attr, arg-type]
        ctypes.CDLL(str(lib), mode=ctypes.RTLD_GLOBAL)
        import openseespy.opensees as ops
        return ops
    except (ImportError, OSError, RuntimeError, AttributeError):
        return None


def opensees_modes(ops, rig: Rig, theta_deg: float, n_el: int = 10, n_modes: int = 4) -> np.ndarray:
    """The seed 003 arm in OpenSees: elasticBeamColumn elements with consistent mass, clamped base."""
    ops.wipe()
    ops.model("basic", "-ndm", 2, "-ndf", 3)
    sec = rig.links[0].section
    E = 1.0
    A, Iz = sec.EA_N / E, sec.EI_Nm2 / E
    ops.geomTransf("Linear", 1)
    node = 1
    ops.node(node, 0.0, 0.0)
    ops.fix(node, 1, 1, 1)
    xy, angle = np.zeros(2), 0.0
    for k, link in enumerate(rig.links):
        if k:
            angle += math.radians(theta_deg)
        step = link.length_m / n_el * np.array([math.cos(angle), math.sin(angle)])
        for _ in range(n_el):
            xy = xy + step
            ops.node(node + 1, float(xy[0]), float(xy[1]))
            ops.element("elasticBeamColumn", node, node, node + 1, A, E, Iz, 1, "-mass", sec.mass_per_m_kg,
                        "-cMass")
            node += 1
    lam = np.array(ops.eigen(n_modes))  # default solver: banded ARPACK
    return np.sqrt(lam) / (2 * math.pi)


def against_opensees(rig: Rig) -> None:
    ops = import_opensees()
    if ops is None:
        print("\n## OpenSeesPy: not importable here (pip install openseespy); skipped")
        return
    links = tuple(replace(lk, section=replace(lk.section, rotary_inertia_per_m_kgm=0.0)) for lk in rig.links)
    no_rotary = replace(rig, links=links)
    worst = 0.0
    for theta in (0.0, 60.0, 150.0):
        ours = frame_modes(no_rotary, {"theta_deg": theta}, 4).freq_hz
        theirs = opensees_modes(ops, rig, theta)
        worst = max(worst, float(np.max(np.abs(ours / theirs - 1))))
    poses = [{"theta_deg": float(a)} for a in ANGLES[::20]]
    t_ops = per_pose_ms(lambda p: opensees_modes(ops, rig, p["theta_deg"]), poses)
    t_ours = per_pose_ms(lambda p: frame_modes(no_rotary, p, 4), poses)
    print(f"\n## OpenSeesPy (same mesh, 10 elements per link, ARPACK): {t_ops} per pose; ours {t_ours}; "
          f"CPU ratio OpenSees/ours = {t_ops.cpu_ms / t_ours.cpu_ms:.2f}; "
          f"max frequency difference {100 * worst:.2e} %")
    ops.wipe()


def main() -> int:
    rig = load_rig(RIG)
    print(f"# seed 003 arm, OPENBLAS_NUM_THREADS={os.environ['OPENBLAS_NUM_THREADS']}")
    element_sweep(rig)
    many_poses(rig)
    scipy_reference(rig)
    against_opensees(rig)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
