"""How much rounding moves pLSCF's poles at high model orders: the figures of docs/modal.md's
"Clusters" paragraph (issue 23: pyfrf_impact_frf gave 0 extra modes on one machine and 2 on another).

The FRF of tests/data/realdata/pyfrf_impact_frf (one reference, 201-7000 Hz on 1 Hz lines) in the
basis exp(-i w dt) that identify uses for it: per model order, the ratio of the largest to the
smallest eigenvalue of the reduced normal matrix (its numerical rank is lost where this nears 1e16,
or where the smallest eigenvalue comes out negative), and the relative change of the poles' damping
when the FRF is moved by relative complex noise of 1e-9 (seed 1): median and largest over the poles
of damping below 0.5 % (paired by nearest frequency).

Prints one markdown table row per order; tests/test_modal_identify_rounding.py (slow) checks that the
orders where the damping moves by more than 0.1 % in the median are those the docs name.
Usage: ``python benchmarks/pole_rounding.py``.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from flexmodal.checked_io.blas import one_blas_thread
from flexmodal.modal.lscf import PoleEstimator, _NormalEquations, _poles_of_order
from flexmodal.modal.uff import read_uff

ENTRY = Path(__file__).resolve().parents[1] / "tests" / "data" / "realdata" / "pyfrf_impact_frf"
ORDERS = (120, 200, 300, 411, 540)


def _frf() -> tuple[np.ndarray, np.ndarray]:
    data = read_uff(ENTRY / json.loads((ENTRY / "source.json").read_text())["input"])
    f = np.asarray(data.freq_hz, float)
    return f[f > 0], np.asarray(data.H)[..., f > 0]


def rows(orders=ORDERS) -> list[tuple[int, float, float, float]]:
    """(order, eigenvalue ratio of the reduced normal matrix, median and largest relative change of
    damping [-] with the FRF moved by 1e-9) per order."""
    f, H = _frf()
    rng = np.random.default_rng(1)
    moved = H * (1 + 1e-9 * (rng.standard_normal(H.shape) + 1j * rng.standard_normal(H.shape)))
    out = []
    with one_blas_thread():
        ests = [PoleEstimator(f, h, max(orders), common=True) for h in (H, moved)]
        for p in orders:   # a loop over model orders
            poles, ratio = [], 0.0
            for est in ests:   # the FRF as read, then moved
                lags = slice(est.p_cap - p, est.p_cap + p + 1)
                eqs = _NormalEquations([p], *(x[..., lags] for x in est._sums))
                if not poles:
                    lam = np.linalg.eigvalsh(eqs.reduced(0, p)[:p, :p])
                    ratio = float(lam[-1] / lam[0])
                poles.append(_poles_of_order(0, p, eqs, est.dt, f.min(), f.max(), est.basis)[0])
            (a, b) = poles
            fa, fb = np.abs(a), np.abs(b)
            za, zb = -a.real / fa, -b.real / fb
            near = np.argmin(np.abs(fa[:, None] - fb[None, :]), axis=1)
            light = za < 0.005
            change = np.abs(zb[near] / za - 1)[light]
            out.append((p, ratio, float(np.median(change)), float(change.max())))
    return out


def main() -> None:
    print("| order | largest / smallest eigenvalue of the reduced normal matrix | damping change "
          "at 1e-9, median | largest |")
    print("|---|---|---|---|")
    for p, ratio, med, top in rows():
        print(f"| {p} | {ratio:.1e} | {100 * med:.2g} % | {100 * top:.2g} % |")


if __name__ == "__main__":
    main()
