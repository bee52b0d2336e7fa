"""Poly-reference least-squares complex-frequency (pLSCF, "PolyMAX") pole estimation with a
stabilisation diagram and automatic selection of stable poles (Guillaume et al. 2003, IMAC XXI;
Peeters et al. 2004, Shock Vib. 11).

Right matrix-fraction model ``H_o(z) = N_o(z) D(z)^-1`` with ``z = exp(i w dt)``, ``dt = 1/(2 f_max)``
and real matrix coefficients.

Or (``common``, FRFs of two or more references) one scalar denominator common to every FRF, in the
basis ``z = exp(-i w dt)`` (sdypy-EMA's LSCF, from OpenModal): a physical pole ``s`` is then the root
``z = exp(-s dt)``, and the roots that only fit noise come out at negative damping and are discarded.
In the ``exp(+i w dt)`` basis they are stable poles of 1.5-3 % damping that fill beam_ring_mimo_frf over
68-95 Hz at every order above 40 and hide its modes of 6.1 % and 4.4 % at 73.6 and 84.8 Hz, which the
common-denominator fit finds at every order; the poly-reference fit, in either basis, put them
0.3-0.7 % off (73.1, 85.1 Hz).  A common denominator cannot tell apart two modes closer than their
bandwidths (it has one pole for both; the poly-reference fit separates them by their participation):
:mod:`modal.identify` runs both and keeps the one that explains more.  With one reference it
keeps the ``exp(+i w dt)`` basis, on which the selection rules were tuned, unless the other explains
more and loses nothing (:mod:`modal.identify`; the ``common`` estimator of one reference is the
exp(-i w dt) fit of its FRFs).

The reduced normal equations ``M = sum_o (T_o - S_o^T R^-1 S_o)`` are Toeplitz in the lag ``k - j``; all
lag sums are formed once for the highest order by matrix products over the frequency lines, and every
order's ``M`` follows from one Cholesky factorisation of the highest order's ``R`` (the orders are
nested), so each order costs one small solve and one eigenvalue problem. With the highest denominator
coefficient fixed to the identity, the poles are the eigenvalues of the block companion matrix; a pole's
shape estimate is the numerator at the pole times the denominator's right null vector. A pole is stable
when a pole of the previous order lies within ``df`` in frequency, ``dz`` in damping and (two or more
outputs) MAC >= ``mac_min`` in shape.

The highest order adapts to the data (:func:`adaptive_stabilisation`: raised until the modes found
stop growing), and poles are grouped into chains that follow one physical pole over the orders
(:func:`pole_clusters`), so close modes are told apart by their own order-to-order scatter.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import TypeVar

import numpy as np
import scipy.linalg
import scipy.sparse
import scipy.sparse.csgraph

from flexmodal.checked_io.blas import one_blas_thread
from flexmodal.checked_io.plural import counted
from flexmodal.contract.mac import mac_pairs
from flexmodal.modal.errors import ModalError
from flexmodal.modal.stability import STABLE_DAMPING_REL, STABLE_FREQ_REL, STABLE_MAC_MIN

T = TypeVar("T")
DEFAULT_MAX_POLES = 200   # default cap of (model order x references) of the adaptive diagram
# stable_clusters: a count of stable orders within this many binomial standard deviations of the line
# is a tie.  Above about 200 poles pLSCF's reduced normal equations lose their numerical rank (condition
# 1e15-1e17 on pyfrf_impact_frf), and the poles of the same FRFs on two BLAS kernels (OpenBLAS Haswell
# and SkylakeX) differ by 0.1-10 % in damping: a chain's count of orders stable within 5 % of damping
# moved by up to 4 (1.5 standard deviations) between them
COUNT_SIGMAS = 2.0


@dataclass(frozen=True)
class Stabilisation:
    """Every physical pole of every order: ``order``, ``freq_hz``, ``damping_ratio``, ``pole`` (rad/s,
    complex), flags ``stable_freq``, ``stable_damping``, ``stable_shape`` and ``previous``, the index
    of the nearest pole of the previous order (-1 for none; all [n_poles]; found from ``order`` and
    ``freq_hz`` when not given, as for diagrams built by other methods)."""

    order: np.ndarray
    freq_hz: np.ndarray
    damping_ratio: np.ndarray
    pole: np.ndarray
    stable_freq: np.ndarray
    stable_damping: np.ndarray
    stable_shape: np.ndarray
    previous: np.ndarray | None = None

    @property
    def stable(self) -> np.ndarray:
        return self.stable_freq & self.stable_damping & self.stable_shape


def _lag_sums(freq_hz: np.ndarray, H: np.ndarray, p_max: int, dt: float, basis: float = 1.0):
    """Real parts of the sums over lines of 1, H and H^H H (summed over outputs) times z^d for lags
    d = -p_max..p_max (index p_max + d), the only parts the real-coefficient normal equations use.

    ``Re sum g z^(+-d) = sum Re(g) cos(d theta) -+ sum Im(g) sin(d theta)``: two real matrix products
    [rows x lines] @ [lines x (p_max + 1)] for every row at once, on any frequency grid (z^d by
    repeated multiplication: complex exp, cos and sin of [lines x lags] cost more than the products);
    ``basis`` -1 takes ``z = exp(-i w dt)`` instead."""
    f = np.asarray(freq_hz, float)
    n_out, n_in, nf = H.shape
    g = np.einsum("oaf,obf->abf", H.conj(), H)                      # [a, b, f]
    rows = np.concatenate([np.ones((1, nf)), H.reshape(-1, nf), g.reshape(-1, nf)])
    theta = basis * 2 * np.pi * f * dt
    z = np.cos(theta) + 1j * np.sin(theta)
    zd = np.empty((p_max + 1, nf), complex)                           # z^d [d, f]
    zd[0] = 1.0
    for d in range(1, p_max + 1):   # a loop over lags: one vector product each (error ~ d eps)
        np.multiply(zd[d - 1], z, out=zd[d])
    c, s = rows.real @ zd.real.T, rows.imag @ zd.imag.T
    full = np.concatenate([(c + s)[:, :0:-1], c - s], axis=1)      # [rows, 2p+1]
    return full[0], full[1:1 + n_out * n_in].reshape(n_out, n_in, -1), full[1 + n_out * n_in:].reshape(
        n_in, n_in, -1)


def _cholesky(R: np.ndarray) -> np.ndarray:
    """Cholesky factor of R; for a narrow band at a high order R is nearly singular, and the smallest
    diagonal loading (relative 1e-14, 1e-12, ...) that makes it factorise is added."""
    for jitter in (0.0, 1e-14, 1e-12, 1e-10, 1e-8):
        try:
            return np.linalg.cholesky(R + jitter * np.trace(R) / len(R) * np.eye(len(R)))
        except np.linalg.LinAlgError:
            continue
    raise ModalError("pLSCF: the band is too narrow for the model order (reduce --max-order)")


class _NormalEquations:
    """Reduced normal matrices of the requested orders from one factorisation of the highest order.

    The blocks are Toeplitz in the lag: ``R[j, k] = r[k - j]``, ``S_o[j, k] = -s_o[k - j]``,
    ``T[j, k] = t[k - j]``.  With ``R = L L^T`` (Cholesky, nested: the order-p factor is the leading
    block of the highest order's) and ``Y_o = L^-1 S_o``, the order-p reduced matrix is
    ``M_p = T_p - sum_o Y_o[:p+1, :n_p]^T Y_o[:p+1, :n_p]``: the rows j of Y are grouped between
    consecutive requested orders, one matrix product per group, and a cumulative sum over groups."""

    def __init__(self, orders: list[int], r, s, t) -> None:
        p_max = orders[-1]
        n_out, n_in = s.shape[:2]
        j = np.arange(p_max + 1)
        lag = p_max + j[None, :] - j[:, None]                       # [j, k] -> index of k - j
        L = _cholesky(r[lag])
        S = (-s[:, :, lag]).transpose(2, 0, 3, 1).reshape(p_max + 1, -1)        # [j, (o k i)]
        # L^-1 once (small) and one matrix product: several times faster than a triangular solve with
        # thousands of right-hand sides, to the same accuracy
        Linv = scipy.linalg.solve_triangular(L, np.eye(p_max + 1), lower=True, check_finite=False)
        self.Y = (Linv @ S).reshape(p_max + 1, n_out, -1)                       # [j, o, (k i)]
        self.T = t[:, :, lag].transpose(2, 0, 3, 1).reshape((p_max + 1) * n_in, -1)
        self.Linv_T = Linv.T
        self.n_in = n_in
        edges = [0] + [p + 1 for p in orders]
        n = self.Y.shape[-1]
        self.C = np.empty((len(orders), n, n))                                  # [order index, n, n]
        for k, (a, b) in enumerate(zip(edges, edges[1:], strict=False)):   # a loop over orders
            y = self.Y[a:b].reshape(-1, n)
            np.matmul(y.T, y, out=self.C[k])
        np.cumsum(self.C, axis=0, out=self.C)

    def reduced(self, index: int, p: int) -> np.ndarray:
        """M_p [(p+1) n_in, (p+1) n_in] of the order at position ``index`` of the requested orders."""
        n = (p + 1) * self.n_in
        return self.T[:n, :n] - self.C[index, :n, :n]

    def numerators_at(self, p: int, alpha: np.ndarray, powers: np.ndarray) -> np.ndarray:
        """N_o(lambda_r) [r, o, n_in] for ``powers`` = lambda_r^j [r, p+1], with the numerator
        coefficients beta_o = -R_p^-1 S_o alpha = -L^-T Y_o alpha."""
        b, n = p + 1, (p + 1) * self.n_in
        n_out = self.Y.shape[1]
        ya = self.Y[:b].reshape(b * n_out, -1)[:, :n] @ alpha                      # [(j o), c]
        beta = self.Linv_T[:b, :b] @ ya.reshape(b, -1)                             # [j, (o c)], real
        return -(powers @ beta).reshape(powers.shape[0], n_out, alpha.shape[1])  # r may be 0


def _poles_of_order(index: int, p: int, eqs: _NormalEquations, dt: float, fmin: float, fmax: float,
                    basis: float = 1.0) -> tuple[np.ndarray, np.ndarray]:
    """Physical continuous-time poles [n] (upper half plane, stable, in [fmin, fmax], ascending) of
    model order ``p`` and their shape estimates [n_out, n]: ``N_o(lambda) v``, the numerator at the
    pole times the right null vector of the denominator.  ``basis`` -1: the roots are ``exp(-s dt)``."""
    n_in = eqs.n_in
    M = eqs.reduced(index, p)
    k = p * n_in
    alpha = np.empty((k + n_in, n_in))                                        # [(p+1) n_in, n_in]
    try:
        alpha[:k] = np.linalg.solve(M[:k, :k], -M[:k, k:])
    except np.linalg.LinAlgError:   # data without dynamics at this order (e.g. a flat FRF): least norm
        alpha[:k] = np.linalg.lstsq(M[:k, :k], -M[:k, k:], rcond=None)[0]
    alpha[k:] = np.eye(n_in)
    if n_in == 1:
        # companion matrix in upper Hessenberg form, so LAPACK's Hessenberg reduction has nothing to do
        comp = np.eye(k, k, -1)
        comp[:, -1] = -alpha[:k, 0]
        lam, vec = np.linalg.eigvals(comp), None
    else:
        comp = np.eye(k, k, n_in)
        comp[-n_in:, :] = -alpha[:k].reshape(p, n_in, n_in).transpose(1, 0, 2).reshape(n_in, k)
        lam, vec = np.linalg.eig(comp)
    with np.errstate(divide="ignore", invalid="ignore"):
        poles = basis * np.log(lam) / dt
    f = np.abs(poles) / (2 * np.pi)
    idx = np.flatnonzero(np.isfinite(poles) & (poles.imag > 0) & (poles.real < 0) & (f >= fmin) & (f <= fmax))
    idx = idx[np.argsort(f[idx])]
    powers = np.vander(lam[idx], p + 1, increasing=True)             # lambda_r^j [r, p+1]
    num = eqs.numerators_at(p, alpha, powers)                        # [r, o, n_in]
    if vec is None:                                                  # one input: the null vector is 1
        return poles[idx], num[:, :, 0].T
    return poles[idx], np.einsum("roc,cr->or", num, vec[:n_in, idx])


class PoleEstimator:
    """pLSCF poles of FRFs ``H`` [n_out, n_in, n_freq] at any model orders up to ``p_cap``: the lag sums
    are formed once for ``p_cap``; each call to :meth:`poles` factorises the normal equations of its
    highest order only.  The order-p model does not depend on the highest order (the normal equations
    are nested), so orders may be requested in successive batches with identical results.
    ``common``: one scalar denominator over all n_out x n_in FRFs, basis ``exp(-i w dt)`` (module
    docstring); the shape estimates are then [n_out n_in, n]."""

    def __init__(self, freq_hz: np.ndarray, H: np.ndarray, p_cap: int, common: bool = False) -> None:
        f = np.asarray(freq_hz, float)
        if H.ndim != 3 or H.shape[-1] != f.size:
            raise ModalError(f"pLSCF: FRFs of shape {H.shape} do not match {f.size} frequency lines")
        if f.size < 2 * p_cap + 2:
            raise ModalError(f"pLSCF: {f.size} lines are too few for model order {p_cap}")
        self.basis = -1.0 if common else 1.0
        if common:
            H = H.reshape(-1, 1, f.size)
        self.freq_hz, self.p_cap, self.n_in = f, int(p_cap), H.shape[1]
        self.dt = 1.0 / (2 * f.max())
        scale = np.sqrt(np.vdot(H, H).real / H.size)                 # RMS of the FRFs
        if not scale > 0:
            raise ModalError(f"pLSCF: the FRFs are zero between {f.min():g} and {f.max():g} Hz")
        with one_blas_thread():
            self._sums = _lag_sums(f, H / scale, self.p_cap, self.dt, self.basis)

    def poles(self, orders: list[int]) -> list[tuple[np.ndarray, np.ndarray]]:
        """(poles [n] rad/s, shape estimates [n_out, n]) of each order in ascending ``orders``."""
        p_max = orders[-1]
        if p_max > self.p_cap:
            raise ModalError(f"pLSCF: order {p_max} is above the estimator's cap {self.p_cap}")
        lags = slice(self.p_cap - p_max, self.p_cap + p_max + 1)
        r, s, t = (x[..., lags] for x in self._sums)
        # one BLAS thread: the matrices are small, and threads spinning on a shared machine cost more
        with one_blas_thread():
            eqs = _NormalEquations(orders, r, s, t)
            band = (self.freq_hz.min(), self.freq_hz.max())
            return [_poles_of_order(i, p, eqs, self.dt, *band, self.basis) for i, p in enumerate(orders)]


def _nearest_previous(order: np.ndarray, freq_hz: np.ndarray) -> np.ndarray:
    """Index of the pole nearest in frequency among those of the previous order present (-1 for the
    first order or an empty previous one); poles are grouped by order, in ascending order."""
    previous = np.full(freq_hz.size, -1)
    orders, start = np.unique(order, return_index=True)
    bounds = list(start) + [order.size]
    for k in range(1, orders.size):   # a loop over model orders
        a, b, c = bounds[k - 1], bounds[k], bounds[k + 1]
        if b > a and c > b:
            previous[b:c] = a + np.argmin(np.abs(freq_hz[b:c, None] - freq_hz[None, a:b]), axis=1)
    return previous


def _flags(orders: list[int], found: list[tuple[np.ndarray, np.ndarray]], df: float = STABLE_FREQ_REL,
           dz: float = STABLE_DAMPING_REL, mac_min: float = STABLE_MAC_MIN) -> Stabilisation:
    """Stability flags of every pole against the nearest pole (in frequency) of the previous order.
    With one output the shape criterion is left out (a MAC over one channel is always 1)."""
    poles = [pl for pl, _ in found]
    all_poles = np.concatenate(poles) if poles else np.zeros(0, complex)
    order = np.concatenate([np.full(pl.size, p) for pl, p in zip(poles, orders, strict=True)])
    all_fn = np.abs(all_poles) / (2 * np.pi)
    all_zeta = -all_poles.real / np.where(all_fn > 0, np.abs(all_poles), 1.0)
    all_shapes = np.concatenate([sh for _, sh in found], axis=1)
    previous = _nearest_previous(order, all_fn)
    n = all_fn.size
    sf, sd, ss = np.zeros(n, bool), np.zeros(n, bool), np.zeros(n, bool)
    cur = np.flatnonzero(previous >= 0)
    prev = previous[cur]
    sf[cur] = np.abs(all_fn[cur] - all_fn[prev]) <= df * all_fn[cur]
    sd[cur] = np.abs(all_zeta[cur] - all_zeta[prev]) <= dz * all_zeta[cur]
    ss[cur] = (mac_pairs(all_shapes[:, cur], all_shapes[:, prev]) >= mac_min
               if all_shapes.shape[0] > 1 else True)
    return Stabilisation(order, all_fn, all_zeta, all_poles, sf, sd, ss, previous)


def stabilisation(freq_hz: np.ndarray, H: np.ndarray, orders: range | list[int], *,
                  df: float = STABLE_FREQ_REL, dz: float = STABLE_DAMPING_REL,
                  mac_min: float = STABLE_MAC_MIN) -> Stabilisation:
    """Poles of every model order in ``orders`` and their stability flags: a pole is stable in
    frequency within relative ``df``, in damping within relative ``dz`` and in shape with MAC >=
    ``mac_min`` (two or more outputs) against the nearest pole of the previous order."""
    orders = sorted({int(o) for o in orders})
    with one_blas_thread():
        found = PoleEstimator(freq_hz, H, orders[-1]).poles(orders)
        return _flags(orders, found, df, dz, mac_min)


@dataclass(frozen=True)
class PoleClusters:
    """Candidate modes of a stabilisation diagram, ascending in frequency: ``freq_hz``,
    ``damping_ratio``, ``pole`` (rad/s) from the median of the upper quarter of orders (damping: of all
    orders) of each cluster's fully stable poles; ``n_stable`` the number of orders holding a fully
    stable pole of the cluster, ``members`` the indices (into the Stabilisation arrays) of its poles."""

    freq_hz: np.ndarray
    damping_ratio: np.ndarray
    pole: np.ndarray
    n_stable: np.ndarray
    members: tuple[np.ndarray, ...]

    def subset(self, keep: np.ndarray) -> PoleClusters:
        idx = np.flatnonzero(keep) if np.asarray(keep).dtype == bool else np.asarray(keep, int)
        return PoleClusters(self.freq_hz[idx], self.damping_ratio[idx], self.pole[idx], self.n_stable[idx],
                            tuple(self.members[k] for k in idx))


def _pole(fn: np.ndarray, zeta: np.ndarray) -> np.ndarray:
    wn = 2 * np.pi * np.asarray(fn)
    return -zeta * wn + 1j * wn * np.sqrt(1 - np.asarray(zeta) ** 2)


def _summary(stab: Stabilisation, members: np.ndarray, stable: np.ndarray, top: float) -> tuple:
    """(fn, zeta, n_stable orders, members) of one chain: fn the median over the fully stable poles of
    its orders at or above the quantile ``top`` of them, zeta the median over all its fully stable
    poles (at a few lines per half-power band the upper orders split a leakage-broadened peak into a
    pole pair whose damping is biased high)."""
    s = members[stable[members]]
    f, z = chain_medians(stab.order[s], stab.freq_hz[s], stab.damping_ratio[s], top)
    return f, z, np.unique(stab.order[s]).size, members


def chain_medians(order: np.ndarray, freq_hz: np.ndarray, damping_ratio: np.ndarray, top: float = 0.5
                  ) -> tuple[float, float]:
    """A mode's natural frequency [Hz] and damping ratio from its stable poles (their model ``order``,
    ``freq_hz``, ``damping_ratio``): the median frequency over the poles at orders at or above the
    quantile ``top`` of them, the median damping over all (:func:`_summary`; modal/ssi.py repeats it
    on each bootstrap replicate of the same poles).

    Examples
    --------
    >>> import numpy as np
    >>> f, z = chain_medians(np.array([2, 4, 6, 8]), np.array([9.0, 10.0, 10.2, 10.1]),
    ...                      np.array([0.01, 0.02, 0.03, 0.04]))
    >>> round(float(f), 6), round(float(z), 6)
    (10.15, 0.025)
    """
    ranked = np.sort(order)
    upper = order >= ranked[int(np.ceil(top * (ranked.size - 1)))]   # the quantile, without its overhead
    return np.median(freq_hz[upper]), np.median(damping_ratio)


def _merge_fragments(rows: list[tuple], stab: Stabilisation, stable: np.ndarray, top: float,
                     df: float = 0.01, overlap: float = 0.2) -> list[tuple]:
    """Join neighbouring chains (within relative ``df``) that hardly share an order (at most
    ``overlap`` of the shorter one's stable orders): pieces of one pole whose chain was broken, not two
    modes (two modes show up side by side at the same orders)."""
    out = rows[:1]
    for row in rows[1:]:   # a loop over candidate modes
        last = out[-1]
        oa = np.unique(stab.order[last[3][stable[last[3]]]])
        ob = np.unique(stab.order[row[3][stable[row[3]]]])
        shared = np.intersect1d(oa, ob).size
        if abs(row[0] - last[0]) <= df * row[0] and shared <= overlap * min(oa.size, ob.size):
            out[-1] = _summary(stab, np.concatenate([last[3], row[3]]), stable, top)
        else:
            out.append(row)
    return out


def pole_clusters(stab: Stabilisation, top: float = 0.5) -> PoleClusters:
    """Group the poles of a stabilisation diagram into chains that follow one physical pole over the
    orders, so each cluster is separated by its own order-to-order scatter rather than by a fixed
    frequency tolerance (two modes 0.5 % apart stay apart once the order resolves both).

    Each pole stable in frequency is linked to its nearest pole of the previous order; a pole of the
    previous order keeps only its nearest successor (when two modes separate at a higher order the
    second starts a chain of its own).  Clusters are the connected chains holding two or more fully
    stable poles; each one's pole is the median over its stable orders at or above the quantile
    ``top`` of them (0.5: the upper half; pLSCF identification takes the upper quarter, whose high
    orders absorb the noise best)."""
    n = stab.freq_hz.size
    previous = stab.previous if stab.previous is not None else _nearest_previous(stab.order, stab.freq_hz)
    cur = np.flatnonzero((previous >= 0) & stab.stable_freq)
    prev = previous[cur]
    dist = np.abs(stab.freq_hz[cur] - stab.freq_hz[prev]) / stab.freq_hz[cur]
    first = np.argsort(dist, kind="stable")
    _, keep = np.unique(prev[first], return_index=True)
    cur, prev = cur[first[keep]], prev[first[keep]]
    graph = scipy.sparse.coo_matrix((np.ones(cur.size), (cur, prev)), shape=(n, n))
    n_comp, label = scipy.sparse.csgraph.connected_components(graph, directed=False)
    stable = stab.stable
    counts = np.bincount(label[stable], minlength=n_comp)
    rows = []
    for c in np.flatnonzero(counts >= 2):   # a loop over chains holding stable poles (candidate modes)
        rows.append(_summary(stab, np.flatnonzero(label == c), stable, top))
    rows.sort(key=lambda r: r[0])
    rows = _merge_fragments(rows, stab, stable, top)
    fn = np.array([r[0] for r in rows])
    zeta = np.array([r[1] for r in rows])
    return PoleClusters(fn, zeta, _pole(fn, zeta), np.array([r[2] for r in rows], int),
                        tuple(r[3] for r in rows))


def stable_clusters(stab: Stabilisation, *, min_fraction: float = 0.5, min_orders: int = 5,
                    top: float = 0.5,
                    tie_break: Callable[[PoleClusters, np.ndarray], np.ndarray] | None = None
                    ) -> PoleClusters:
    """The clusters stable over at least ``min_orders`` orders and over ``min_fraction`` of the
    diagram's orders from the one where the cluster first appears (a mode that needs a high order to
    show up is not penalised; a pole that flickers is).  This is the automatic selection before the
    validation by the synthesis.

    ``tie_break`` may keep a cluster whose count of stable orders falls short of that line by less than
    its own uncertainty: COUNT_SIGMAS binomial standard deviations of a count over ``span`` orders at
    even odds, sqrt(span) / 2 each.  Whether a pole of a high order is stable is decided by rounding
    (:data:`COUNT_SIGMAS`), so a count that close to the line passes on one machine and fails on
    another.  ``tie_break(clusters, kept)`` ([n] True for the clusters to keep; ``kept`` [n] those the
    line keeps) is asked about those clusters only; None: the line alone decides.

    Examples
    --------
    Three chains over 20 orders, stable at all of them, at 12 and at 7: the line is 10 orders, its
    uncertainty 2 sqrt(20) / 2 = 4.5 orders, so the tie-break may keep the last one.

    >>> order = np.repeat(np.arange(1, 21), 3)
    >>> freq = np.tile([10.0, 20.0, 30.0], 20)
    >>> zeta = np.full(60, 0.01)
    >>> steady = (freq < 15) | ((freq < 25) & (order <= 12)) | ((freq > 25) & (order > 13))
    >>> stab = Stabilisation(order, freq, zeta, _pole(freq, zeta), np.ones(60, bool), steady,
    ...                      np.ones(60, bool))
    >>> stable_clusters(stab).n_stable.tolist()
    [20, 12]
    >>> stable_clusters(stab, tie_break=lambda c, kept: c.freq_hz > 15).n_stable.tolist()
    [20, 12, 7]
    """
    clusters = pole_clusters(stab, top)
    orders = np.unique(stab.order)
    first = np.array([stab.order[m].min() for m in clusters.members], int)
    span = orders.size - np.searchsorted(orders, first)
    line = np.maximum(min_orders, min_fraction * span)
    keep = clusters.n_stable >= line
    if tie_break is not None:
        margin = COUNT_SIGMAS * np.sqrt(span) / 2
        tied = ~keep & (clusters.n_stable > line - margin) & (clusters.n_stable >= min_orders)
        keep |= tied & np.asarray(tie_break(clusters, keep), bool)
    return clusters.subset(keep)


def select_stable(stab: Stabilisation, *, min_fraction: float = 0.5, min_orders: int = 5
                  ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Automatic pole selection (:func:`stable_clusters`): (fn_hz, zeta, poles) ascending."""
    c = stable_clusters(stab, min_fraction=min_fraction, min_orders=min_orders)
    return c.freq_hz, c.damping_ratio, c.pole


def _batch(lo: int, hi: int, n_in: int) -> list[int]:
    """Orders lo..hi of the adaptive diagram: every order up to 64 / n_in, then every second up to
    128 / n_in, every fourth up to 160 / n_in, every eighth up to 320 / n_in, every sixteenth up to
    640 / n_in, then every thirty-second, so the cost of the high orders (an eigenvalue problem of size
    order x n_in each, cubic in it) stays bounded: 2.5-5 % apart in order above 160 poles."""
    o = np.arange(lo, hi + 1)
    step = np.select([o * n_in <= 64, o * n_in <= 128, o * n_in <= 160, o * n_in <= 320, o * n_in <= 640],
                     [1, 2, 4, 8, 16], 32)
    return [int(k) for k in o[(o % step == 0) | (o == hi)]]


def default_caps(n_in: int, floor: int = 0, first_order: int = 24) -> tuple[int, int]:
    """Default caps of the adaptive model order: ``DEFAULT_MAX_POLES`` poles shared among the ``n_in``
    references, raised to 30 poles per mode the data show (``floor``: clear CMIF peaks; pLSCF needs
    spare poles for the noise, more the more modes share the band) while some of those peaks are
    still unexplained."""
    base = max(first_order, DEFAULT_MAX_POLES // n_in)
    return base, max(base, 30 * int(floor) // n_in)


def _order_note(counts: list[tuple[int, int, int]], best: int, why: str, floor: int) -> str:
    """The sentence saying which order was used and why, true to the counts (order, modes found, clear
    CMIF peaks they explain)."""
    order, n, shown = counts[best]
    history = ", ".join(f"{c} at {'order ' if k == 0 else ''}{o}" for k, (o, c, _) in enumerate(counts))
    peaks = (f"; {'it explains' if n == 1 else 'they explain'} {shown} of {counted(floor, 'clear CMIF peak')}"
             if floor else "")
    return f"model order {order}: {counted(n, 'mode')}, {why} ({history}){peaks}"


def adaptive_stabilisation(freq_hz: np.ndarray, H: np.ndarray, *, max_order: int | None = None,
                           evaluate: Callable[[Stabilisation], tuple[int, int, T]] | None = None,
                           first_order: int = 24, growth: float = 1.5, patience: int = 2, floor: int = 0,
                           common: bool = False, **criteria) -> tuple[Stabilisation, str, T | None]:
    """Stabilisation diagram whose highest order is raised (by ``growth``, from ``first_order`` poles
    per reference) until the number of modes ``evaluate(diagram)`` finds has not grown for ``patience``
    steps, once at least one mode is found and the modes have explained all ``floor`` clear CMIF
    peaks (:func:`modal.peaks.clear_peaks`), or until the cap: ``max_order`` when
    given, else :func:`default_caps` (the higher one while clear peaks are unexplained), never more than
    the band's lines allow.  ``evaluate`` returns
    (number of modes, number of clear peaks they explain, anything) and defaults to the number of
    :func:`stable_clusters` (explaining none).  Above the default cap the order is raised only while
    that explains more clear peaks.  Returns the diagram of the highest order whose modes explain the
    most clear peaks (above the default cap: only if they explain more than below it), a sentence
    saying which order was used and why (true to the counts), and ``evaluate``'s result at that
    order.  ``common``: one scalar denominator (:class:`PoleEstimator`), whose poles count as those of
    one reference."""
    f = np.asarray(freq_hz, float)
    n_in = 1 if common else H.shape[1]
    line_cap = (f.size - 2) // 2
    base, far = (max_order, max_order) if max_order is not None else default_caps(n_in, floor, first_order)
    cap = min(line_cap, far)
    if cap < 2:
        raise ModalError(f"pLSCF: {f.size} lines are too few for a model")
    if evaluate is None:
        def evaluate(stab: Stabilisation) -> tuple[int, int, None]:
            return stable_clusters(stab).freq_hz.size, 0, None
    estimator = PoleEstimator(f, H, cap, common)
    top = min(cap, max(4, -(-first_order // n_in)))
    orders = _batch(2, top, n_in)
    found = estimator.poles(orders)
    counts: list[tuple[int, int, int]] = []
    best = (-1, None, None)   # (index into counts, diagram, evaluate's value)
    while True:   # a loop over a few growing orders
        stab = _flags(orders, found, **criteria)
        n, shown, value = evaluate(stab)
        counts.append((top, n, shown))
        before = max((s for _, _, s in counts[:-1]), default=-1)
        if shown > before or (shown == before and top <= base):   # above the base cap: only for more
            best = (len(counts) - 1, stab, value)
        most = max(c for _, c, _ in counts)
        held = [c for _, c, _ in counts[-patience - 1:]]
        if (len(counts) > patience and most >= 1 and counts[best[0]][2] >= floor
                and max(held[1:]) <= held[0]):
            why = (f"the modes found fell from {held[0]} to {held[-1]}" if held[-1] < held[0]
                   else "the modes found stopped growing")
            break
        if top > base and len(counts) > patience and counts[-patience - 1][2] >= shown:
            why = "raising the order above the default cap explained no more clear CMIF peaks"
            break
        limit = cap if counts[best[0]][2] < floor or most < 1 else min(cap, base)
        if top >= limit:
            why = ("the band's lines cap the order" if top >= line_cap
                   else "--max-order caps the order" if max_order is not None
                   else "the default cap (a higher one: --max-order)")
            break
        nxt = min(limit, max(top + 2, int(round(top * growth))))
        more = _batch(top + 1, nxt, n_in)
        found += estimator.poles(more)
        orders, top = orders + more, nxt
    return best[1], _order_note(counts, best[0], why, floor), best[2]
