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

import numpy as np
import scipy.linalg

from modal.errors import ModalError
from modal.mac import mac_pairs


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


def _uniform_grid(f: np.ndarray) -> int | None:
    """N = 2 f_max / df when the lines are k df with integer k (an FFT grid), else None."""
    df = (f[-1] - f[0]) / (f.size - 1)
    k = f / df
    if df > 0 and np.allclose(np.diff(f), df, rtol=1e-9, atol=0) and np.allclose(k, np.round(k), atol=1e-6):
        return int(round(2 * f[-1] / df))
    return None


def _lag_sums(freq_hz: np.ndarray, H: np.ndarray, p_max: int, dt: float):
    """Sums over lines of 1, H and H^H H times z^d for lags d = -p_max..p_max (index p_max + d).

    On an FFT grid (lines k df) with dt = 1/(2 f_max), z = exp(2 pi i k / N): the sums are one
    inverse and one forward FFT of the zero-padded line data; otherwise explicit matrix products."""
    f = np.asarray(freq_hz, float)
    n_out, n_in, nf = H.shape
    n_fft = _uniform_grid(f)
    if n_fft is not None:
        first = int(round(f[0] / (f[1] - f[0])))

        def both(g: np.ndarray) -> np.ndarray:                    # g [..., nf] -> [..., 2p+1]
            pad = np.zeros((*g.shape[:-1], n_fft), complex)
            pad[..., first:first + nf] = g
            plus = np.fft.ifft(pad, axis=-1)[..., :p_max + 1] * n_fft
            minus = np.fft.fft(pad, axis=-1)[..., :p_max + 1]
            return np.concatenate([minus[..., :0:-1], plus], axis=-1)
    else:
        zk = np.exp(1j * np.outer(2 * np.pi * f * dt, np.arange(p_max + 1)))   # [nf, p+1]

        def both(g: np.ndarray) -> np.ndarray:
            flat = g.reshape(-1, nf)
            plus, minus = flat @ zk, flat @ zk.conj()
            return np.concatenate([minus[:, :0:-1], plus], axis=-1).reshape(*g.shape[:-1], -1)

    r = both(np.ones((1, nf)))[0].real
    s = both(H)                                                    # [o, i, 2p+1]
    g = np.einsum("oaf,obf->abf", H.conj(), H)                      # sum over outputs of H^H H
    t = both(g)                                                    # [a, b, 2p+1]
    return r, s, t


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
    """Reduced normal matrices of every order from one factorisation of the highest order.

    With ``R = L L^T`` (Cholesky, nested: the order-p factor is the leading block of the highest
    order's) and ``Y_o = L^-1 S_o``, the order-p reduced matrix is
    ``M_p = T_p - sum_o Y_o[:p+1, :n_p]^T Y_o[:p+1, :n_p]``: a cumulative sum over the rows j."""

    def __init__(self, p_max: int, r, s, t) -> None:
        n_out, n_in = s.shape[:2]
        j = np.arange(p_max + 1)
        lag = p_max + j[None, :] - j[:, None]                       # [j, k] -> index of k - j
        L = _cholesky(r[lag])
        S = -s[:, :, lag].real.transpose(1, 0, 2, 3)                 # [i, o, j, k]
        S = S.transpose(1, 2, 3, 0).reshape(n_out, p_max + 1, (p_max + 1) * n_in)   # [o, j, (k i)]
        self.Y = scipy.linalg.solve_triangular(L, S.transpose(1, 0, 2).reshape(p_max + 1, -1),
                                               lower=True).reshape(p_max + 1, n_out, -1)   # [j, o, (k i)]
        self.T = t[:, :, lag].real.transpose(2, 0, 3, 1).reshape((p_max + 1) * n_in, -1)
        self.Linv_T = scipy.linalg.solve_triangular(L, np.eye(p_max + 1), lower=True).T
        self.n_in = n_in
        self.C = np.cumsum(np.matmul(self.Y.transpose(0, 2, 1), self.Y), axis=0)   # [p + 1, n, n]

    def reduced(self, p: int) -> np.ndarray:
        """M_p [(p+1) n_in, (p+1) n_in]."""
        n = (p + 1) * self.n_in
        return self.T[:n, :n] - self.C[p, :n, :n]

    def numerators_at(self, p: int, alpha: np.ndarray, powers: np.ndarray) -> np.ndarray:
        """N_o(lambda_r) [o, r, n_in] for ``powers`` = lambda_r^j [r, p+1], with the numerator
        coefficients beta_o = -R_p^-1 S_o alpha = -L^-T Y_o alpha."""
        b, n = p + 1, (p + 1) * self.n_in
        ya = np.einsum("jon,nc->joc", self.Y[:b, :, :n], alpha)                  # [j, o, c]
        pl = powers @ self.Linv_T[:b, :b]                                          # [r, j]
        return -np.einsum("rj,joc->orc", pl, ya)


def _poles_of_order(p: int, eqs: _NormalEquations, dt: float, fmin: float, fmax: float
                    ) -> tuple[np.ndarray, np.ndarray]:
    """Physical continuous-time poles [n] (upper half plane, stable, in [fmin, fmax], ascending) of
    model order ``p`` and their shape estimates [n_out, n]: ``N_o(lambda) v``, the numerator at the
    pole times the right null vector of the denominator."""
    n_in = eqs.n_in
    M = eqs.reduced(p)
    k = p * n_in
    alpha = np.vstack([np.linalg.solve(M[:k, :k], -M[:k, k:]), np.eye(n_in)])   # [(p+1) n_in, n_in]
    comp = np.zeros((k, k))
    comp[:-n_in, n_in:] = np.eye(k - n_in)
    comp[-n_in:, :] = -alpha[:k].reshape(p, n_in, n_in).transpose(1, 0, 2).reshape(n_in, k)
    if n_in == 1:
        lam, vec = np.linalg.eigvals(comp), np.ones((1, k))
    else:
        lam, vec = np.linalg.eig(comp)
    with np.errstate(divide="ignore", invalid="ignore"):
        poles = np.log(lam) / dt
    f = np.abs(poles) / (2 * np.pi)
    idx = np.flatnonzero(np.isfinite(poles) & (poles.imag > 0) & (poles.real < 0) & (f >= fmin) & (f <= fmax))
    idx = idx[np.argsort(f[idx])]
    powers = lam[idx, None] ** np.arange(p + 1)[None, :]             # [r, p+1]
    num = eqs.numerators_at(p, alpha, powers)                        # [o, r, n_in]
    return poles[idx], np.einsum("orc,cr->or", num, vec[:n_in, idx])


def stabilisation(freq_hz: np.ndarray, H: np.ndarray, orders: range | list[int], *, df: float = 0.01,
                  dz: float = 0.05,
                  mac_min: float = 0.98) -> Stabilisation:
    """Poles of every model order in ``orders`` and their stability flags (see module docstring)."""
    f = np.asarray(freq_hz, float)
    if H.ndim != 3 or H.shape[-1] != f.size:
        raise ModalError(f"pLSCF: FRFs of shape {H.shape} do not match {f.size} frequency lines")
    orders = sorted(int(o) for o in orders)
    if f.size < 2 * orders[-1] + 2:
        raise ModalError(f"pLSCF: {f.size} lines are too few for model order {orders[-1]}")
    dt = 1.0 / (2 * f.max())
    scale = np.sqrt(np.mean(np.abs(H) ** 2))
    Hn = H / scale
    eqs = _NormalEquations(orders[-1], *_lag_sums(f, Hn, orders[-1], dt))
    rows = []
    prev = None
    for p in orders:   # a loop over model orders, each a small dense solve
        poles, shapes = _poles_of_order(p, eqs, dt, f.min(), f.max())
        fn = np.abs(poles) / (2 * np.pi)
        zeta = -poles.real / np.abs(poles)
        sf = np.zeros(poles.size, bool)
        sd = np.zeros(poles.size, bool)
        ss = np.zeros(poles.size, bool)
        if prev is not None and prev[0].size and poles.size:
            pf, pz, psh = prev
            near = np.argmin(np.abs(fn[:, None] - pf[None, :]), axis=1)
            sf = np.abs(fn - pf[near]) <= df * fn
            sd = np.abs(zeta - pz[near]) <= dz * zeta
            ss = mac_pairs(shapes, psh[:, near]) >= mac_min
        rows.append((np.full(poles.size, p), fn, zeta, poles, sf, sd, ss))
        prev = (fn, zeta, shapes)
    cols = [np.concatenate(c) for c in zip(*rows, strict=True)]
    return Stabilisation(*cols)


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
