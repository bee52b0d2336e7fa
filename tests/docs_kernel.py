"""The BLAS kernel the figures of docs/oma.md and docs/diagnosis.md's coverage block were measured under, and
a process that runs under it.

A share or an error at its rounding edge moves with OpenBLAS's kernel: for example (measured at main
afaeb46, before the gear-order refinement changed these figures), on an AVX-512 host (SkylakeX) the
tracking two-joint path's mode 4 is within 1 % in 91 % of the windows against Haswell's 92 % (its map
damping's median error 6 % against 7 %), and the crossing's mode 6 has a largest error of 0.6 % against
0.8 %. tests/test_track_docs.py runs benchmarks/track.py in a process with the kernel forced, and
tests/test_modal_uncertainty.py runs benchmarks/diagnosis_doc.py's coverage block so (there the first EMA
setting's frequency coverage is 94.5 % under SkylakeX against the docs' 94.2 %), so every x86-64 machine
gives the same figures.
"""

from __future__ import annotations

import os
import subprocess
import sys

from test_outputs_reference import KERNELS, NO_KERNEL_CHOICE

KERNEL = {"OPENBLAS_CORETYPE": KERNELS[0][0], "OPENBLAS_NUM_THREADS": KERNELS[0][1]}
"""OpenBLAS's Haswell kernel (AVX2) on one thread."""

_PROBE = ("import numpy; from threadpoolctl import threadpool_info; print(*sorted({i.get('architecture') "
          "for i in threadpool_info() if i['internal_api'] == 'openblas'}))")


def run_under_docs_kernel(argv: list[str], timeout_s: float) -> str:
    """The stdout of ``argv`` run with ``KERNEL`` forced; fails (never skips) where it cannot be forced."""
    assert not NO_KERNEL_CHOICE, f"the docs' figures need OpenBLAS's Haswell kernel: {NO_KERNEL_CHOICE}"
    env = {**os.environ, **KERNEL}
    arch = subprocess.run([sys.executable, "-c", _PROBE], env=env, capture_output=True, text=True,
                          check=True, timeout=120).stdout.strip()
    assert arch == KERNEL["OPENBLAS_CORETYPE"], f"OpenBLAS ran {arch!r}: OPENBLAS_CORETYPE ignored"
    return subprocess.run(argv, env=env, capture_output=True, text=True, check=True,
                          timeout=timeout_s).stdout
