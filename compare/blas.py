"""Single-threaded OpenBLAS for the diagnosis' many tiny eigenproblems (thread start-up dominates them).

The diagnosis solves thousands of ~15x15 problems; OpenBLAS threads only add hand-over costs there,
and on a loaded 2-core machine they more than double the run time.  ``single_threaded()`` sets the
thread count of every loaded OpenBLAS (found in /proc/self/maps, as threadpoolctl does) to one and
restores it afterwards; where that is not possible it does nothing.
"""

from __future__ import annotations

import ctypes
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

_PREFIXES = ("scipy_openblas_", "openblas_")
_SUFFIXES = ("64_", "")


def _openblas_controls() -> list[tuple[object, object]]:
    maps = Path("/proc/self/maps")
    if not maps.is_file():
        return []
    paths = sorted({line.split()[-1] for line in maps.read_text().splitlines()
                    if "openblas" in line and line.split()[-1].startswith("/")})
    out = []
    for path in paths:
        try:
            lib = ctypes.CDLL(path)
        except OSError:
            continue
        for pre in _PREFIXES:
            for suf in _SUFFIXES:
                get, put = f"{pre}get_num_threads{suf}", f"{pre}set_num_threads{suf}"
                if hasattr(lib, get) and hasattr(lib, put):
                    out.append((getattr(lib, get), getattr(lib, put)))
                    break
            else:
                continue
            break
    return out


@contextmanager
def single_threaded() -> Iterator[None]:
    """Run the body with one OpenBLAS thread, restoring the previous counts on exit."""
    controls = _openblas_controls()
    saved = [get() for get, _ in controls]
    for _, put in controls:
        put(1)
    try:
        yield
    finally:
        for (_, put), n in zip(controls, saved, strict=True):
            put(n)
