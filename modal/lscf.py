"""Poly-reference least-squares complex-frequency (pLSCF, "PolyMAX") pole estimation with a
stabilisation diagram and automatic selection of stable poles (Guillaume et al. 2003, IMAC XXI;
Peeters et al. 2004, Shock Vib. 11).

Right matrix-fraction model ``H_o(z) = N_o(z) D(z)^-1`` with ``z = exp(i w dt)``, ``dt = 1/(2 f_max)``
and real matrix coefficients.  The reduced normal equations ``M = sum_o (T_o - S_o^T R^-1 S_o)`` are
Toeplitz in the lag ``k - j``; all lag sums are formed once for the highest order by matrix products
over the frequency lines, and every order's ``M`` follows from one Cholesky factorisation of the
highest order's ``R`` (the orders are nested), so each order costs one small solve and one
eigenvalue problem.  With the
highest denominator coefficient fixed to the identity, the poles are the eigenvalues of the block
companion matrix; a pole's shape estimate is the numerator at the pole times the denominator's right
null vector.  A pole is stable when a pole of the previous order lies within ``df`` in frequency,
``dz`` in damping and MAC >= ``mac_min`` in shape.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cache

import numpy as np
import scipy.linalg
from threadpoolctl import ThreadpoolController

from flexmodal.modal.errors import ModalError
from flexmodal.modal.mac import mac_pairs


@dataclass(frozen=True)
class Stabilisation:
    """Every physical pole of every order: ``order``, ``freq_hz``, ``damping_ratio``, ``pole`` (rad/s,
    complex) and flags ``stable_freq``, ``stable_damping``, ``stable_shape`` (all [n_poles])."""

    order: np.ndarray
    freq_hz: np.ndarray
    damping_ratio: np.ndarray
    pole: np.ndarray
    stable_freq: np.ndarray
    stable_damping: np.ndarray
    stable_shape: np.ndarray

    @property
    def stable(self) -> np.ndarray:
        return self.stable_freq & self.stable_damping & self.stable_shape


@cache
def _blas() -> ThreadpoolController:
    """The BLAS thread pools, found once (a fresh ``threadpool_limits`` costs ~1 ms per call)."""
    return ThreadpoolController()


def _lag_sums(freq_hz: np.ndarray, H: np.ndarray, p_max: int, dt: float):
    """Real parts of the sums over lines of 1, H and H^H H (summed over outputs) times z^d for lags
    d = -p_max..p_max (index p_max + d), the only parts the real-coefficient normal equations use.

    ``Re sum g z^(+-d) = sum Re(g) cos(d theta) -+ sum Im(g) sin(d theta)``: two real matrix products
    [rows x lines] @ [lines x (p_max + 1)] for every row at once, on any frequency grid (z^d by
    repeated multiplication: complex exp, cos and sin of [lines x lags] cost more than the products)."""
    f = np.asarray(freq_hz, float)
    n_out, n_in, nf = H.shape
    g = np.einsum("oaf,obf->abf", H.conj(), H)                      # [a, b, f]
    rows = np.concatenate([np.ones((1, nf)), H.reshape(-1, nf), g.reshape(-1, nf)])
    theta = 2 * np.pi * f * dt
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


def _poles_of_order(index: int, p: int, eqs: _NormalEquations, dt: float, fmin: float, fmax: float
                    ) -> tuple[np.ndarray, np.ndarray]:
    """Physical continuous-time poles [n] (upper half plane, stable, in [fmin, fmax], ascending) of
    model order ``p`` and their shape estimates [n_out, n]: ``N_o(lambda) v``, the numerator at the
    pole times the right null vector of the denominator."""
    n_in = eqs.n_in
    M = eqs.reduced(index, p)
    k = p * n_in
    alpha = np.empty((k + n_in, n_in))                                        # [(p+1) n_in, n_in]
    alpha[:k] = np.linalg.solve(M[:k, :k], -M[:k, k:])
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
        poles = np.log(lam) / dt
    f = np.abs(poles) / (2 * np.pi)
    idx = np.flatnonzero(np.isfinite(poles) & (poles.imag > 0) & (poles.real < 0) & (f >= fmin) & (f <= fmax))
    idx = idx[np.argsort(f[idx])]
    powers = np.vander(lam[idx], p + 1, increasing=True)             # lambda_r^j [r, p+1]
    num = eqs.numerators_at(p, alpha, powers)                        # [r, o, n_in]
    if vec is None:                                                  # one input: the null vector is 1
        return poles[idx], num[:, :, 0].T
    return poles[idx], np.einsum("roc,cr->or", num, vec[:n_in, idx])


def stabilisation(freq_hz: np.ndarray, H: np.ndarray, orders: range | list[int], *, df: float = 0.01,
                  dz: float = 0.05,
                  mac_min: float = 0.98) -> Stabilisation:
    """Poles of every model order in ``orders`` and their stability flags (see module docstring)."""
    f = np.asarray(freq_hz, float)
    if H.ndim != 3 or H.shape[-1] != f.size:
        raise ModalError(f"pLSCF: FRFs of shape {H.shape} do not match {f.size} frequency lines")
    orders = sorted({int(o) for o in orders})
    if f.size < 2 * orders[-1] + 2:
        raise ModalError(f"pLSCF: {f.size} lines are too few for model order {orders[-1]}")
    dt = 1.0 / (2 * f.max())
    scale = np.sqrt(np.vdot(H, H).real / H.size)                     # RMS of the FRFs
    # one BLAS thread: the matrices are small, and threads spinning on a shared machine cost more
    with _blas().limit(limits=1, user_api="blas"):
        eqs = _NormalEquations(orders, *_lag_sums(f, H / scale, orders[-1], dt))
        band = (f.min(), f.max())
        found = [_poles_of_order(i, p, eqs, dt, *band) for i, p in enumerate(orders)]
    poles = [pl for pl, _ in found]
    fn = [np.abs(pl) / (2 * np.pi) for pl in poles]
    zeta = [-pl.real / np.abs(pl) for pl in poles]
    # every pole against the nearest pole of the previous order, all orders at once
    start = np.cumsum([0] + [x.size for x in fn])
    near, cur = [], []
    for k in range(1, len(orders)):   # a loop over model orders
        if fn[k].size and fn[k - 1].size:
            near.append(np.argmin(np.abs(fn[k][:, None] - fn[k - 1][None, :]), axis=1) + start[k - 1])
            cur.append(np.arange(start[k], start[k + 1]))
    all_fn, all_zeta = np.concatenate(fn), np.concatenate(zeta)
    all_shapes = np.concatenate([sh for _, sh in found], axis=1)
    sf = np.zeros(all_fn.size, bool)
    sd = np.zeros(all_fn.size, bool)
    ss = np.zeros(all_fn.size, bool)
    if cur:
        cur, prev = np.concatenate(cur), np.concatenate(near)
        sf[cur] = np.abs(all_fn[cur] - all_fn[prev]) <= df * all_fn[cur]
        sd[cur] = np.abs(all_zeta[cur] - all_zeta[prev]) <= dz * all_zeta[cur]
        ss[cur] = mac_pairs(all_shapes[:, cur], all_shapes[:, prev]) >= mac_min
    order = np.concatenate([np.full(pl.size, p) for pl, p in zip(poles, orders, strict=True)])
    return Stabilisation(order, all_fn, all_zeta, np.concatenate(poles), sf, sd, ss)


def select_stable(stab: Stabilisation, *, min_fraction: float = 0.3, cluster_tol: float = 0.005
                  ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Automatic pole selection: cluster fully stable poles by frequency (gaps above ``cluster_tol``
    relative split clusters); keep clusters holding poles of at least ``min_fraction`` of the orders;
    each mode is the median pole of its cluster's upper half of orders.  Returns (fn_hz, zeta, poles)."""
    keep = stab.stable
    n_orders = np.unique(stab.order).size
    f, z, o, p = stab.freq_hz[keep], stab.damping_ratio[keep], stab.order[keep], stab.pole[keep]
    idx = np.argsort(f)
    f, z, o, p = f[idx], z[idx], o[idx], p[idx]
    if f.size == 0:
        return np.zeros(0), np.zeros(0), np.zeros(0, complex)
    breaks = np.flatnonzero(np.diff(f) > cluster_tol * f[1:]) + 1
    out = []
    for grp in np.split(np.arange(f.size), breaks):   # a loop over clusters (modes)
        if np.unique(o[grp]).size < min_fraction * n_orders:
            continue
        top = grp[o[grp] >= np.median(o[grp])]
        k = top[np.argsort(f[top])[top.size // 2]]
        out.append((np.median(f[top]), np.median(z[top]), p[k]))
    if not out:
        return np.zeros(0), np.zeros(0), np.zeros(0, complex)
    fn, zeta, poles = (np.array(v) for v in zip(*out, strict=True))
    # the pole itself rebuilt from the medians, so fn, zeta and pole agree
    wn = 2 * np.pi * fn
    return fn, zeta, -zeta * wn + 1j * wn * np.sqrt(1 - zeta ** 2)
