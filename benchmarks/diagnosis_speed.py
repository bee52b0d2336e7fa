"""Speed of the gap diagnosis's fast parametric model (compare/parametric.py) against its previous
implementation, on the same run: the same numbers, bit for bit, for less CPU.

Run: ``python benchmarks/diagnosis_speed.py [--configs N] [--diagnose N]`` (from the repository root).
The case is the demo arm (fixtures/rigs/demo_arm.toml) at N configurations theta_deg -80..80, its FE
prediction with frequencies x (1 - 0.04 cos theta), 0.3 % frequency and 2 % shape noise.  Prints, in
process CPU seconds (the machine is shared; wall time says little):

1. ``reduce``: every single candidate's reduced family (``reduce_family``) against ``reference_reduce``
   (one configuration at a time, ``np.ix_`` per configuration, as before 27 Nov);
2. ``grid``: each family at a screening grid of 81 handle values (``solve_family`` without gradients,
   as ``fit_candidate`` scores its start grid) against ``reference_solve`` (one batch, with gradients);
3. ``refine``: the same with gradients (the least-squares iterations);
4. with ``--diagnose N``: ``diagnose`` itself at N configurations, the current code against the
   references patched in (``fit.solve_family``, ``diagnosis.reduce_family``), and whether the two
   diagnosis.json agree.

Every stage checks that both give equal arrays (``np.array_equal``); the default test
(tests/test_diagnosis_speed.py) checks that on a small case.  Measured 27 Nov 2026 04:25 UTC (load 8-15,
2 cores), ``--configs 200 --diagnose 200``: reduce 0.11 s vs 0.23 s (2.15x), grid 2.20 vs 3.31 s (1.51x),
refine 2.32 vs 3.16 s (1.36x), diagnose 23.3 vs 27.9 s CPU (1.20x), diagnosis.json equal.  At 2000
configurations (``flexmodal diagnose`` under /usr/bin/time, main before vs after): 385 s vs 259 s CPU
(1.49x) at load 8-15, 324 s vs 250 s (1.29x) on the quiet machine; diagnosis.json byte-identical
(docs/diagnosis.md, after "Time").
"""

from __future__ import annotations

import argparse
import math
import time
from collections.abc import Callable, Sequence
from pathlib import Path
from unittest import mock

import numpy as np

from flexmodal.compare import diagnosis as diagnosis_module
from flexmodal.compare import fit as fit_module
from flexmodal.compare import parametric
from flexmodal.compare.candidates import single_candidates
from flexmodal.compare.parametric import (
    PoseBasis,
    ReducedFamily,
    handles_for,
    pose_basis,
    reduce_family,
    solve_family,
)
from flexmodal.models.effects import EFFECTS
from flexmodal.models.rig import Rig, load_rig

RIG = Path(__file__).resolve().parents[1] / "fixtures" / "rigs" / "demo_arm.toml"
GRID = 81


def reference_reduce(bases: Sequence[PoseBasis], handle_idx: Sequence[int], nominal: np.ndarray
                     ) -> ReducedFamily:
    """``reduce_family`` as it was: a loop over configurations with ``np.ix_`` (the reference)."""
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
    n_h, C = len(handle_idx), len(blocks)
    K0, M0 = np.zeros((C, r, r)), np.zeros((C, r, r))
    Kh, Mh = np.zeros((C, n_h, r, r)), np.zeros((C, n_h, r, r))
    S = np.zeros((C, blocks[0][4].shape[0], r))
    for c, (k0, m0, kh, mh, s) in enumerate(blocks):
        q = k0.shape[0]
        K0[c] = np.diag(np.full(r, 1e6 * float(np.max(np.abs(np.diag(k0))))))
        M0[c] = np.eye(r)
        K0[c, :q, :q], M0[c, :q, :q], S[c, :, :q] = k0, m0, s
        if n_h:
            Kh[c, :, :q, :q], Mh[c, :, :q, :q] = kh, mh
    return ReducedFamily(K0, M0, Kh, Mh, S, np.asarray(nominal, float), bool(n_h and np.any(Mh != 0)))


def reference_solve(fam: ReducedFamily, h: np.ndarray, n_modes: int, gradients: bool = True
                    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``solve_family`` as it was: all points in one batch, gradients always (the reference)."""
    return parametric._solve_slice(fam, h, n_modes, True)


def poses(rig: Rig, n_configs: int) -> list[dict[str, float]]:
    """``n_configs`` poses, every joint angle of ``rig`` -80..80 degrees (the second one reversed)."""
    angles = np.linspace(-80.0, 80.0, n_configs)
    return [{v: float(t if i % 2 == 0 else -t) for i, v in enumerate(rig.pose_variables)} for t in angles]


def measured_table(rig: Rig, n_configs: int, seed: int = 0):
    """The benchmark's measured table (see the module docstring)."""
    from flexmodal.api import predict
    from flexmodal.contract.table import ModalTable

    table = predict(rig, {f"c{i:04d}": p for i, p in enumerate(poses(rig, n_configs))})
    df = table.frame.copy()
    rng = np.random.default_rng(seed)
    theta = np.radians(df["pose.theta_deg"].to_numpy(float))
    df["freq_hz"] = df["freq_hz"] * (1 - 0.04 * np.cos(theta)) * (1 + 0.003 * rng.standard_normal(len(df)))
    for col in [c for c in df.columns if c.startswith("shape.")]:
        df[col] = df[col] * (1 + 0.02 * rng.standard_normal(len(df)))
    return ModalTable.from_frame(df, "benchmark")


def cpu(fn: Callable[[], object]) -> tuple[float, object]:
    """Process CPU seconds of one call, and its result."""
    c0 = time.process_time()
    out = fn()
    return time.process_time() - c0, out


def _equal(a, b) -> bool:
    if isinstance(a, ReducedFamily):
        keys = ("K0", "M0", "Kh", "Mh", "sensors")
        return all(np.array_equal(getattr(a, k), getattr(b, k)) for k in keys) and a.has_mass == b.has_mass
    return all(x is None or np.array_equal(x, y) for x, y in zip(a, b, strict=True))


def stages(rig: Rig, n_configs: int, n_modes: int = 4, grid: int = GRID
           ) -> tuple[dict[str, tuple[float, float]], list[str]]:
    """CPU seconds (current, reference) of each stage over every single candidate's family, and the
    stages and candidates where the two do not give equal arrays (none expected)."""
    handles = handles_for(rig)
    index = {h.name: i for i, h in enumerate(handles)}
    bases = [pose_basis(rig, handles, p, n_modes) for p in poses(rig, n_configs)]
    out = dict.fromkeys(("reduce", "grid", "refine"), (0.0, 0.0))
    differs = []
    scale = np.logspace(-1, 1, grid)
    for cand in single_candidates(rig, EFFECTS, {}):
        idx = [index[h] for h in cand.handles]
        nominal = np.array([handles[i].nominal for i in idx])
        c_new, fam = cpu(lambda idx=idx, nominal=nominal: reduce_family(bases, idx, nominal))
        c_ref, ref = cpu(lambda idx=idx, nominal=nominal: reference_reduce(bases, idx, nominal))
        if not _equal(fam, ref):
            differs.append(f"reduce {cand.effect}@{cand.location}")
        out["reduce"] = (out["reduce"][0] + c_new, out["reduce"][1] + c_ref)
        base = np.where(nominal > 0, nominal, 1.0)
        h = np.broadcast_to((scale[:, None] * base)[:, None, :], (grid, n_configs, len(idx))).copy()
        for stage, grad in (("grid", False), ("refine", True)):
            c_new, got = cpu(lambda h=h, grad=grad, fam=fam: solve_family(fam, h, n_modes + 2, grad))
            c_ref, want = cpu(lambda h=h, fam=fam: reference_solve(fam, h, n_modes + 2))
            if not _equal(got, want):
                differs.append(f"{stage} {cand.effect}@{cand.location}")
            out[stage] = (out[stage][0] + c_new, out[stage][1] + c_ref)
    return out, differs


def whole(rig: Rig, n_configs: int) -> tuple[float, float, bool]:
    """CPU seconds of ``diagnose`` (current, reference implementation patched in) and whether the two
    diagnosis.json agree to 1e-9 relative."""
    from flexmodal.compare.diagnosis import diagnose

    table = measured_table(rig, n_configs)
    c_new, new = cpu(lambda: diagnose(rig, table).to_dict())
    with mock.patch.object(fit_module, "solve_family", reference_solve), \
            mock.patch.object(diagnosis_module, "reduce_family", reference_reduce):
        c_ref, ref = cpu(lambda: diagnose(rig, table).to_dict())
    return c_new, c_ref, same_json(new, ref)


def same_json(a, b, rtol: float = 1e-9) -> bool:
    """Equal JSON-like trees, numbers to ``rtol`` relative."""
    if isinstance(a, dict):
        return isinstance(b, dict) and a.keys() == b.keys() and all(same_json(a[k], b[k], rtol) for k in a)
    if isinstance(a, list | tuple):
        return isinstance(b, list | tuple) and len(a) == len(b) and all(
            same_json(x, y, rtol) for x, y in zip(a, b, strict=True))
    if isinstance(a, float) and isinstance(b, float):
        return (math.isnan(a) and math.isnan(b)) or math.isclose(a, b, rel_tol=rtol, abs_tol=0.0)
    return a == b


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--configs", type=int, default=200, help="configurations of the stage benchmark")
    ap.add_argument("--diagnose", type=int, default=0, help="also diagnose this many configurations")
    args = ap.parse_args()
    rig = load_rig(RIG)
    total_new = total_ref = 0.0
    times, differs = stages(rig, args.configs)
    for stage, (c_new, c_ref) in times.items():
        total_new, total_ref = total_new + c_new, total_ref + c_ref
        print(f"{stage:7s} {args.configs} configurations: {c_new:7.2f} s CPU vs reference {c_ref:7.2f} s "
              f"= {c_ref / max(c_new, 1e-9):.2f}x")
    print("arrays:", "DIFFER: " + ", ".join(differs) if differs else "equal to the reference's, bit for bit")
    print(f"stages  total: {total_new:.2f} s vs {total_ref:.2f} s = {total_ref / max(total_new, 1e-9):.2f}x")
    if args.diagnose:
        c_new, c_ref, same = whole(rig, args.diagnose)
        print(f"diagnose {args.diagnose} configurations: {c_new:.1f} s CPU vs reference {c_ref:.1f} s = "
              f"{c_ref / max(c_new, 1e-9):.2f}x; diagnosis.json {'equal' if same else 'DIFFERS'} to 1e-9")


if __name__ == "__main__":
    main()
