"""Benchmark: SSI-cov of pyOMA2 (the reference run) and of flexmodal on the same output-only record.

Data: a 6-storey shear frame (fixtures/shear_frame.py, modes 7.4 .. 53 Hz, damping 0.2 .. 2 %) under
white-noise floor forces, 6 channels x 60 000 samples at 256 Hz, 5 % sensor noise.  Both sides build
the covariance Hankel matrix with 20 block rows and compute the poles of every model order 1..100
(pyOMA2: ``SSI(method="cov", br=20, ordmax=100, step=1)`` run, its default hard criteria; flexmodal:
``modal.ssi.ssi_cov(max_order=100, order_step=1, block_rows=20)``, which also draws the stability
flags and selects the modes automatically).  Each round runs pyOMA2 first, then flexmodal, in this
process; the script prints per-round wall times, the median ratio and its spread, and the modes of
both (pyOMA2's picked at flexmodal's frequencies with ``mpe(order_in="find_min")``) against the truth.
Usage: ``python benchmarks/oma.py [--samples 60000] [--repeat 5]``.
"""

from __future__ import annotations

import argparse
import contextlib
import io
import logging
import sys
import time

import numpy as np

from flexmodal.contract.mac import mac
from flexmodal.fixtures.shear_frame import shear_frame_record
from flexmodal.modal.ssi import ssi_cov

MASS = [3000.0, 2800.0, 2600.0, 2400.0, 2000.0, 2000.0]
STIFF = [9.6e7, 8.8e7, 8.0e7, 7.2e7, 6.4e7, 6.4e7]
ZETA = [0.002, 0.005, 0.01, 0.015, 0.02, 0.01]
FS = 256.0


def _quiet_pyoma2() -> None:
    """Import pyOMA2 (outside the timed rounds) and silence its INFO logs."""
    import pyoma2.algorithms.ssi  # noqa: F401
    import pyoma2.setup.single  # noqa: F401

    for name in [n for n in logging.root.manager.loggerDict if n.startswith("pyoma2")]:
        logging.getLogger(name).setLevel(logging.WARNING)


def _pyoma2(y: np.ndarray, max_order: int, block_rows: int):
    from pyoma2.algorithms.ssi import SSI
    from pyoma2.setup.single import SingleSetup

    setup = SingleSetup(y, fs=FS)
    alg = SSI(name="ssicov", method="cov", br=block_rows, ordmax=max_order, step=1)
    setup.add_algorithms(alg)
    with contextlib.redirect_stderr(io.StringIO()):   # its progress bars
        setup.run_by_name("ssicov")
    return setup, alg


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--samples", type=int, default=60_000)
    ap.add_argument("--max-order", type=int, default=100)
    ap.add_argument("--block-rows", type=int, default=20)
    ap.add_argument("--repeat", type=int, default=5)
    args = ap.parse_args(argv)
    _quiet_pyoma2()
    rec = shear_frame_record(MASS, STIFF, ZETA, duration_s=args.samples / FS, sample_rate_hz=FS, seed=0)
    y = rec.samples
    print(f"record: {y.shape[1]} channels x {y.shape[0]} samples at {FS:g} Hz; orders 1..{args.max_order}, "
          f"{args.block_rows} block rows")
    ratios, ref_t, our_t = [], [], []
    for r in range(args.repeat):   # a loop over rounds: reference first, then ours, same data
        t0 = time.perf_counter()
        setup, alg = _pyoma2(y, args.max_order, args.block_rows)
        t1 = time.perf_counter()
        ours = ssi_cov(y, FS, max_order=args.max_order, min_order=1, order_step=1,
                       block_rows=args.block_rows)
        t2 = time.perf_counter()
        ref_t.append(t1 - t0)
        our_t.append(t2 - t1)
        ratios.append(ref_t[-1] / our_t[-1])
        print(f"round {r + 1}: pyOMA2 {ref_t[-1]:.3f} s, flexmodal {our_t[-1]:.3f} s, ratio {ratios[-1]:.1f}")
    print(f"median: pyOMA2 {np.median(ref_t):.3f} s, flexmodal {np.median(our_t):.3f} s; "
          f"ratio median {np.median(ratios):.1f} (min {min(ratios):.1f}, max {max(ratios):.1f})")
    modes = ours.modes
    with contextlib.redirect_stderr(io.StringIO()):
        setup.mpe("ssicov", sel_freq=list(modes.freq_hz), order_in="find_min")
    ref_fn, ref_zeta, ref_phi = alg.result.Fn, alg.result.Xi, alg.result.Phi
    print("truth fn [Hz]    " + " ".join(f"{f:8.3f}" for f in rec.freq_hz))
    print("flexmodal fn     " + " ".join(f"{f:8.3f}" for f in modes.freq_hz))
    print("pyOMA2 fn        " + " ".join(f"{f:8.3f}" for f in ref_fn))
    print("truth zeta [%]   " + " ".join(f"{100 * z:8.3f}" for z in rec.damping_ratio))
    print("flexmodal zeta   " + " ".join(f"{100 * z:8.3f}" for z in modes.damping_ratio))
    print("pyOMA2 zeta      " + " ".join(f"{100 * z:8.3f}" for z in ref_zeta))
    found = modes.freq_hz.size == rec.freq_hz.size
    print(f"flexmodal modes found {modes.freq_hz.size}/{rec.freq_hz.size} without being told where")
    if found:
        print(f"max |fn/truth - 1|: flexmodal {np.max(np.abs(modes.freq_hz / rec.freq_hz - 1)):.2e}, "
              f"pyOMA2 {np.max(np.abs(ref_fn / rec.freq_hz - 1)):.2e}; max |fn flexmodal/pyOMA2 - 1| "
              f"{np.max(np.abs(modes.freq_hz / ref_fn - 1)):.2e}")
        print(f"min MAC vs truth: flexmodal {np.diag(mac(modes.shapes, rec.shapes)).min():.5f}, "
              f"pyOMA2 {np.diag(mac(np.asarray(ref_phi), rec.shapes)).min():.5f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
