"""Accuracy of output-only identification against known answers: the figures of docs/oma.md.

1. 5-storey shear frame (fixtures/shear_frame.py: modes 8.7-52.5 Hz, zeta 0.2-2 %), white-noise floor
   forces, 5 channels x 10 min at 256 Hz, 5 % sensor noise, seeds 0 and 1: SSI-cov and
   FDD/EFDD errors of frequency, damping and MAC against the exact modes.
2. Multi-setup: 11-storey frame, 3 setups x (2 references + 3 roving), 5 min each at a different
   excitation level, PoSER merge: modes merged, frequency error, MAC of the 11-point shapes.
3. The demo arm with its hidden compliant elbow at three poses: SSI on 60 s operational records vs
   pLSCF on 8 s impact tests, and `diagnose` on each modal table.

Prints markdown table rows; tests/test_oma_docs.py checks that every row stands in docs/oma.md.
Usage: ``python benchmarks/oma_accuracy.py``.
"""

from __future__ import annotations

import sys

import numpy as np
import pandas as pd

from flexmodal.compare.diagnosis import diagnose
from flexmodal.contract.mac import mac
from flexmodal.contract.table import ModalTable
from flexmodal.fixtures.demo import DEMO_EFFECTS, FMAX_HZ
from flexmodal.fixtures.rig_sim import DEMO_RIG, simulate
from flexmodal.fixtures.shear_frame import shear_frame_modes, shear_frame_record
from flexmodal.modal.compute import frf_of_record
from flexmodal.modal.fdd import fdd
from flexmodal.modal.identify import identify, modes_table
from flexmodal.modal.multisetup import OmaSetup, ssi_multisetup
from flexmodal.modal.oma import identify_output_only
from flexmodal.modal.ssi import ssi_cov
from flexmodal.models.rig import load_rig

MASS = [3000.0, 2800.0, 2600.0, 2400.0, 2000.0]
STIFF = [9.6e7, 8.8e7, 8.0e7, 7.2e7, 6.4e7]
ZETA = [0.002, 0.005, 0.01, 0.015, 0.02]


def shear_frame_rows() -> list[str]:
    rows = []
    for seed in (0, 1):   # a loop over records
        rec = shear_frame_record(MASS, STIFF, ZETA, seed=seed)
        found = (("SSI-cov", ssi_cov(rec.samples, 256.0).modes), ("FDD/EFDD", fdd(rec.samples, 256.0).modes))
        for name, modes in found:
            df = np.abs(modes.freq_hz / rec.freq_hz - 1).max()
            dz = np.abs(modes.damping_ratio / rec.damping_ratio - 1)
            macs = np.diag(mac(modes.shapes, rec.shapes)).min()
            rows.append(f"| shear frame, seed {seed}, {name} | {modes.freq_hz.size}/5 | {100 * df:.3f} % | "
                        f"{100 * dz.max():.0f} % (0.2 % mode: {100 * dz[0]:.0f} %) | {macs:.4f} |")
    worst = np.zeros(3)
    found = 0
    for seed in range(10):   # a loop over records: SSI's spread over ten noise realisations
        rec = shear_frame_record(MASS, STIFF, ZETA, seed=seed)
        modes = ssi_cov(rec.samples, 256.0).modes
        if modes.freq_hz.size == 5:
            found += 1
            worst = np.maximum(worst, [np.abs(modes.freq_hz / rec.freq_hz - 1).max(),
                                       np.abs(modes.damping_ratio / rec.damping_ratio - 1).max(),
                                       1 - np.diag(mac(modes.shapes, rec.shapes)).min()])
    rows.append(f"| shear frame, seeds 0-9, SSI-cov | all 5 in {found}/10 records | {100 * worst[0]:.3f} % | "
                f"{100 * worst[1]:.0f} % | {1 - worst[2]:.4f} |")
    return rows


def multisetup_rows() -> list[str]:
    n = 11
    mass, stiff = np.full(n, 2000.0), np.full(n, 1e8)
    names = tuple(f"floor{i + 1}" for i in range(n))
    refs, roving = [10, 5], [[0, 1, 2], [3, 4, 6], [7, 8, 9]]
    setups = []
    for s, rows in enumerate(roving):   # a loop over setups
        rec = shear_frame_record(mass, stiff, 0.01, duration_s=300.0, seed=10 + s,
                                 force_rms_N=100.0 * (1 + s))
        cols = refs + rows
        setups.append(OmaSetup(rec.samples[:, cols], 256.0, tuple(names[c] for c in cols),
                                tuple(names[c] for c in refs)))
    merged = ssi_multisetup(setups, max_order=60)
    fn, phi = shear_frame_modes(mass, stiff)
    macs = np.diag(mac(merged.modes.shapes, phi[[names.index(p) for p in merged.points]]))
    df = np.abs(merged.modes.freq_hz / fn - 1).max()
    return [f"| multi-setup, 3 x (2 + 3) sensors, PoSER | {merged.modes.freq_hz.size}/11 modes, "
            f"{len(merged.points)} points | {100 * df:.3f} % | - | {macs.min():.4f} |"]


def arm_rows() -> list[str]:
    rig = load_rig(DEMO_RIG)
    oma, imp = [], []
    for k, theta in enumerate((0, 60, 120)):   # a loop over poses
        pose = {"theta_deg": float(theta)}
        op = simulate(rig, pose, excitation="operational", duration_s=60.0, sample_rate_hz=2048.0,
                      effects=DEMO_EFFECTS, seed=3 + k)
        res, outs = identify_output_only(op.samples, 2048.0, [c.name for c in op.channels],
                                         [c.kind for c in op.channels], fmin=20.0, fmax=FMAX_HZ)
        oma.append(modes_table(res.modes, outs, config=f"theta{theta}", pose=pose).frame)
        im = simulate(rig, pose, excitation="impact", sample_rate_hz=2048.0, effects=DEMO_EFFECTS,
                      seed=13 + k)
        names, kinds = [c.name for c in im.channels], [c.kind for c in im.channels]
        fr = frf_of_record(im.samples, 2048.0, names, kinds, excitation="impact",
                           triggers=[e.sample_index for e in im.events if e.kind == "trigger"])
        md = identify(fr.freq_hz, fr.H, fmin=5.0, fmax=FMAX_HZ, decay_rate_per_s=fr.decay_rate_per_s)
        imp.append(modes_table(md, fr.outputs, config=f"theta{theta}", pose=pose).frame)
    tables = [ModalTable.from_frame(pd.concat(t, ignore_index=True)) for t in (oma, imp)]
    rows = []
    for config in tables[0].configs:
        f_oma, f_imp = tables[0].freq_hz(config), tables[1].freq_hz(config)
        rows.append(f"| arm {config}: SSI (60 s operational) vs pLSCF (impact) | "
                    + ", ".join(f"{a:.2f}/{b:.2f}" for a, b in zip(f_oma, f_imp, strict=True))
                    + f" Hz | {100 * np.abs(f_oma / f_imp - 1).max():.3f} % |")
    for name, table in zip(("OMA", "impact"), tables, strict=True):
        v = diagnose(rig, table).verdict
        rows.append(f"| diagnose on the {name} table | {v.effect} at {v.location}, "
                    f"k = {v.params['k_Nm_per_rad']:.0f} N m/rad (hidden: 8000) | "
                    f"explained: {v.explained} |")
    return rows


def main() -> int:
    for row in shear_frame_rows() + multisetup_rows() + arm_rows():
        print(row)
    return 0


if __name__ == "__main__":
    sys.exit(main())
