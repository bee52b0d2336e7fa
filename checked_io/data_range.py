"""Measured values (samples, FRFs) within the range where the arithmetic on them stays finite.

Spectra and fits square measured values and add the squares up: a finite value above
:data:`MAX_DATA` in magnitude (a file written in the wrong unit, or with a scale factor of 1e300)
overflows to inf and NaN, which numpy reported as a RuntimeWarning on the user's terminal before an
error that blamed something else ("the FRFs are zero", "every hit was rejected"); values whose
largest magnitude is below :data:`MIN_PEAK` underflow to 0 the same way.  No quantity an arm test
measures in SI units (m/s², N, m, strain, their ratios) comes near either bound.
"""

from __future__ import annotations

import numpy as np

MAX_DATA = 1e100   # a measured value above this in magnitude: its squares, summed, overflow
MIN_PEAK = 1e-100  # values all below this in magnitude (and not all 0): their squares underflow to 0


def range_fault(values: np.ndarray) -> tuple[tuple[int, ...], str] | None:
    """Where and why finite ``values`` cannot be measured data, or None when they can.

    Parameters
    ----------
    values : numpy.ndarray
        Finite real or complex numbers (NaN and inf are the caller's own check).

    Returns
    -------
    (index, words) or None
        The index of the first value above :data:`MAX_DATA` in magnitude and words saying so, or
        ``()`` and words saying the largest magnitude lies below :data:`MIN_PEAK` (not all 0).

    Examples
    --------
    >>> range_fault(np.array([1.0, -2e300, 3.0]))
    ((1,), 'holds -2e+300, above 1e+100 in magnitude (its squares overflow: is the unit right?)')
    >>> range_fault(np.array([0.0, 3e-200]))
    ((), 'is at most 3e-200 in magnitude, below 1e-100 (its squares underflow to 0: is the unit right?)')
    >>> range_fault(np.array([0.0, 9.81])) is None
    True
    """
    magnitude = np.abs(values).astype(float, copy=False)   # float32 data: 1e100 is no float32
    over = np.argwhere(magnitude > MAX_DATA)
    if over.size:
        at = tuple(int(i) for i in over[0])
        value = values[at]
        shown = f"{value:.4g}" if np.isrealobj(values) else f"{complex(value):.4g}"
        return at, (f"holds {shown}, above {MAX_DATA:g} in magnitude (its squares overflow: is the unit "
                    "right?)")
    peak = float(magnitude.max()) if magnitude.size else 0.0
    if 0 < peak < MIN_PEAK:
        return (), (f"is at most {peak:.4g} in magnitude, below {MIN_PEAK:g} (its squares underflow to 0: "
                    "is the unit right?)")
    return None
