"""Uncertainty of output-only natural frequencies and damping ratios from the record's own scatter.

The record is cut into ``n_b`` contiguous blocks (``N_BLOCKS``, fewer for short records), each block's
estimate (the output covariances for SSI, the cross-spectral matrix for FDD) computed on its own, and
the identification repeated on recombinations of them (the block scheme of Reynders, Pintelon &
De Roeck 2008, MSSP 22:948-969, whose first-order propagation of the same block scatter through the SVD
was tried first: at flexmodal's high SSI orders it overestimated the sigma about three-fold in
Monte-Carlo, and on real records of lightly damped modes the block deviations reached 60 % of the
largest singular value, where no first-order expansion holds; re-identification instead):

``bootstrap_weights(n_blocks, n_replicates) -> ndarray``
    the bootstrap over blocks (Efron & Tibshirani 1993, ch. 6): each of ``N_BOOTSTRAP`` replicates
    re-weights the blocks by multinomial counts (blocks drawn with replacement; a fixed seed, so the
    sigma is a function of the data) and repeats the identification of each mode with the statistic
    of its estimate; the sigma is the replicates' standard deviation times ``sqrt(n_b / (n_b - 1))``
    (the bootstrap's plug-in variance of a mean of n_b blocks).  SSI (modal/ssi.py): the pole nearest
    each of the mode's stable poles at its order, and the same medians over them as the estimate
    (modal.lscf.chain_medians).  FDD (modal/fdd.py): the blocks are runs of whole Welch segments (one
    segment each for records of up to ``N_BLOCKS`` segments), and EFDD is repeated on the record's bell
    without its detection checks; its sigma is scaled by ``interval_factor`` (below).

``interval_factor(n_blocks, n_replicates) -> float``
    Student's t_0.975 over 1.96 for the degrees of freedom of a bootstrap sigma (Welch-Satterthwaite
    over the blocks' and the replicates' scatter), so that +-1.96 sigma is the 95 % interval.  SSI's
    sigma does without it (docs/diagnosis.md: it is on average larger than its scatter).

The delete-one-block jackknife (Efron & Stein 1981), used before, overestimated the SSI sigma 1.3-2x
in Monte-Carlo: at model orders well above the system's the pole moves non-smoothly with the data
(spurious poles beside it), and the jackknife, which sees perturbations 1/n_b the size of the
sampling error and extrapolates them linearly, inflates such terms (exact at the true order 4, 2.5x
too large at order 100 for one order's pole), where the bootstrap perturbs at the sampling error's
own scale.  For FDD it had only the 5 blocks of two segments a default-nfft record holds (a sigma of
4 degrees of freedom: damping intervals covered 86-90 %).

Blocks are independent samples only when a mode's correlation decays within one: a mode whose decay
time ``1 / (zeta omega_n)`` exceeds ``MAX_DECAY_FRACTION`` of a block gets NaN.  The model order, the
selection of the poles and the block count are not part of this error.

Examples
--------
>>> w = bootstrap_weights(5, 3)
>>> w.shape, w.sum(axis=1).tolist()
((3, 5), [5, 5, 5])
"""

from __future__ import annotations

import numpy as np
import scipy.stats

MAX_DECAY_FRACTION = 0.5
"""A mode whose decay time 1 / (zeta omega_n) exceeds this fraction of a block gets no sigma."""
N_BLOCKS = 20
"""Blocks the record is cut into (Reynders et al. 2008 use 20-100; fewer when the record is short)."""
N_BOOTSTRAP = 20
"""Bootstrap replicates of the SSI sigma (its relative Monte-Carlo error about 1 / sqrt(2 N_BOOTSTRAP))."""


def interval_factor(n_blocks: int, n_replicates: int) -> float:
    """Factor turning a bootstrap sigma over ``n_blocks`` blocks from ``n_replicates`` replicates into one
    whose +-1.96 sigma interval is the 95 % interval: ``t_{0.975}(nu) / z_{0.975}`` (Student, 1908; the
    coverage factor of an uncertainty of nu degrees of freedom, JCGM 100:2008 G.3-G.4).  The sigma's
    square is the data's variance times two independent chi^2 / dof terms, the blocks' scatter
    (``n_blocks - 1`` degrees of freedom) and the finite replicates' (``n_replicates - 1``), so its
    relative variance is ``a + b + a b`` with ``a = 2 / (n_b - 1)``, ``b = 2 / (B - 1)``, and
    ``nu = 2 / (a + b + a b)`` (Welch-Satterthwaite, JCGM 100:2008 G.4.1, with the product term).

    Examples
    --------
    >>> round(interval_factor(11, 10**9) * 1.959964, 3)    # t_0.975 of 10 degrees of freedom: 2.228
    2.228
    >>> round(interval_factor(10**9, 10**9), 4), round(interval_factor(14, 20), 3)
    (1.0, 1.198)
    """
    a, b = 2.0 / (n_blocks - 1), 2.0 / (n_replicates - 1)
    nu = 2.0 / (a + b + a * b)
    return float(scipy.stats.t.ppf(0.975, nu) / scipy.stats.norm.ppf(0.975))


def bootstrap_weights(n_blocks: int, n_replicates: int, seed: int = 0) -> np.ndarray:
    """Multinomial counts [n_replicates, n_blocks] (each row sums to ``n_blocks``): how often each block
    is drawn in each bootstrap replicate, from a generator of its own (``seed``)."""
    rng = np.random.default_rng(seed)
    return rng.multinomial(n_blocks, np.full(n_blocks, 1.0 / n_blocks), size=n_replicates)
