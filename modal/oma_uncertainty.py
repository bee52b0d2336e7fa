"""Uncertainty of output-only natural frequencies and damping ratios from the record's own scatter.

The record is cut into ``n_b`` contiguous blocks (``N_BLOCKS``, fewer for short records); the
identification is repeated on the estimate (the output covariances for SSI, the cross-spectral matrix
for FDD) of all blocks but one, and the scatter of those replicates is the delete-one-block jackknife
(Efron & Stein 1981; the block scheme of Reynders, Pintelon & De Roeck 2008, MSSP 22:948-969, whose
first-order propagation of the same block scatter through the SVD was tried first: at flexmodal's high
SSI orders it overestimated the sigma about three-fold in Monte-Carlo, and on real records of lightly
damped modes the block deviations reached 60 % of the largest singular value, where no first-order
expansion holds; the jackknife re-identifies instead):

``jackknife_std(estimates) -> ndarray``
    ``sd = sqrt((n_b - 1) / n_b sum_j (theta_(-j) - mean)^2)`` over replicates [n_b, ...] each made
    without one block.  SSI (modal/ssi.py): each replicate re-identifies, at a few of the orders the
    mode's stable poles came from, the pole nearest each, and takes their medians as the selection
    does.  FDD (modal/fdd.py): each replicate repeats EFDD on the same bell of lines.

Blocks are independent samples only when a mode's correlation decays within one: a mode whose decay
time ``1 / (zeta omega_n)`` exceeds ``MAX_DECAY_FRACTION`` of a block gets NaN.  The model order, the
selection of the poles and the block count are not part of this error.

Examples
--------
>>> import numpy as np
>>> round(float(jackknife_std(np.array([[1.0], [1.1], [0.9], [1.0]]))[0]), 4)
0.1225
"""

from __future__ import annotations

import numpy as np

MAX_MEMBERS = 4
"""Stable poles per SSI mode (evenly spread over its orders) re-identified in each jackknife replicate."""
MAX_DECAY_FRACTION = 0.5
"""A mode whose decay time 1 / (zeta omega_n) exceeds this fraction of a block gets no SSI sigma."""
N_BLOCKS = 20
"""Blocks the record is cut into (Reynders et al. 2008 use 20-100; fewer when the record is short)."""


def jackknife_std(estimates: np.ndarray) -> np.ndarray:
    """Delete-one jackknife standard deviation [...] of estimates [n_b, ...] each made without one block
    (module docstring); NaN where any is NaN."""
    e = np.asarray(estimates, float)
    n_b = e.shape[0]
    return np.sqrt((n_b - 1) / n_b * np.sum((e - e.mean(axis=0)) ** 2, axis=0))
