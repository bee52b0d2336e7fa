"""Least-squares frequency-domain estimation of residues with lower and upper residual terms
(Peeters, Van der Auweraer, Guillaume & Leuridan 2004, "The PolyMAX frequency-domain method", §3.3).

For fixed poles ``lambda_r`` every FRF is fitted (in its own quantity, ``(i w)^q`` times receptance,
q = 0, 1, 2) by
``H(w) = (i w)^q [ sum_r ( R_r/(i w - lambda_r) + conj(R_r)/(i w - conj(lambda_r)) ) + LR/(i w)^2 + UR ]``
with complex residues ``R_r`` and real residuals LR (modes below the band) and UR (modes above).  The
design matrix is the same for every FRF, so all FRFs are solved in one real least-squares problem.

Whether the FRFs need mode r is an F test of the nested models with and without it: removing the
columns K = {Re R_r, Im R_r} raises the residual sum of squares by ``x_K^T [(G^-1)_KK]^-1 x_K`` per
FRF (G the Gram matrix, x the solution; Seber & Lee 2003, *Linear Regression Analysis* §4.3), so every
mode's test comes from the one fit.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.linalg

from flexmodal.modal.errors import ModalError
from flexmodal.modal.frf import QUANTITIES


@dataclass(frozen=True)
class LsfdResult:
    """``residues`` [n_out, n_in, n_modes] complex (receptance form), ``lower``/``upper`` [n_out, n_in],
    ``synthesis`` [n_out, n_in, n_freq] the fitted FRFs (same quantity as the data); ``need``
    [n_modes] the F statistic of each mode: the rise of the residual when the mode is left out, per
    parameter removed, over the residual variance of the full fit (about 1 for a mode that only fits
    noise)."""

    residues: np.ndarray
    lower: np.ndarray
    upper: np.ndarray
    synthesis: np.ndarray
    need: np.ndarray

    def modal_constants(self, poles: np.ndarray) -> np.ndarray:
        """A_r = 2 i omega_d R_r [n_out, n_in, n_modes]: phi_j phi_k for mass-normalised real modes."""
        return self.residues * (2j * np.asarray(poles).imag)[None, None, :]


def _basis(freq_hz: np.ndarray, poles: np.ndarray, quantity: str, residuals: bool) -> np.ndarray:
    iw = 2j * np.pi * np.asarray(freq_hz, float)[:, None]
    lam = np.asarray(poles, complex)[None, :]
    a, b = 1 / (iw - lam), 1 / (iw - lam.conj())
    cols = [a + b, 1j * (a - b)]
    if residuals:
        cols += [1 / iw ** 2, np.ones_like(iw)]
    return np.hstack(cols) * iw ** QUANTITIES[quantity]


def synthesis_of(freq_hz: np.ndarray, poles: np.ndarray, residues: np.ndarray, quantity: str = "accelerance"
                 ) -> np.ndarray:
    """[n_out, n_in, n_freq] the FRFs of modes with ``poles`` [n_modes] (upper half) and ``residues``
    [n_out, n_in, n_modes] (receptance form, as :class:`LsfdResult`), without residual terms, in
    ``quantity``."""
    m, (n_out, n_in) = len(poles), np.shape(residues)[:2]
    if m == 0:
        return np.zeros((n_out, n_in, np.size(freq_hz)), complex)
    A = _basis(np.asarray(freq_hz, float), np.asarray(poles, complex), quantity, False)   # [nf, 2m]
    R = np.asarray(residues).reshape(-1, m)
    return (A @ np.concatenate([R.real, R.imag], axis=1).T).T.reshape(n_out, n_in, -1)


def lsfd(freq_hz: np.ndarray, H: np.ndarray, poles: np.ndarray, *, quantity: str = "accelerance",
         residuals: bool = True) -> LsfdResult:
    """Residues of ``H`` [n_out, n_in, n_freq] for continuous-time ``poles`` [n_modes] (upper half)."""
    f = np.asarray(freq_hz, float)
    if np.any(f <= 0):
        raise ModalError("LSFD: the frequency band must exclude 0 Hz")
    m = len(poles)
    A = _basis(f, poles, quantity, residuals)                       # [nf, n_par] complex
    n_out, n_in, nf = H.shape
    rhs = H.reshape(n_out * n_in, nf).T                             # [nf, n_frf]
    # real normal equations of the column-scaled problem (Cholesky; SVD least squares if singular)
    norm = np.sqrt(np.sum(np.abs(A) ** 2, axis=0))
    An = A / norm
    gram = (An.conj().T @ An).real
    proj = (An.conj().T @ rhs).real
    try:
        ginv = scipy.linalg.cho_solve(scipy.linalg.cho_factor(gram), np.eye(len(gram)))
    except np.linalg.LinAlgError:
        ginv = np.linalg.pinv(gram)
    xn = ginv @ proj
    x = xn / norm[:, None]
    synth = (A @ x).T.reshape(n_out, n_in, nf)
    rss = float(np.sum(np.abs(rhs.T.reshape(n_out, n_in, nf) - synth) ** 2))
    dof = max(1, (2 * nf - A.shape[1]) * rhs.shape[1])
    k = np.stack([np.arange(m), np.arange(m) + m], axis=1)                   # [mode, 2] columns
    block = ginv[k[:, :, None], k[:, None, :]]                               # [mode, 2, 2]
    xk = xn[k]                                                               # [mode, 2, n_frf]
    rise = np.einsum("mif,mij,mjf->m", xk, np.linalg.pinv(block), xk)
    with np.errstate(divide="ignore", invalid="ignore"):
        need = rise / (2 * rhs.shape[1]) / (rss / dof) if rss > 0 else np.full(m, np.inf)
    res = (x[:m] + 1j * x[m:2 * m]).T.reshape(n_out, n_in, m)
    lower = x[2 * m].reshape(n_out, n_in) if residuals else np.zeros((n_out, n_in))
    upper = x[2 * m + 1].reshape(n_out, n_in) if residuals else np.zeros((n_out, n_in))
    return LsfdResult(res, lower, upper, synth, need)


def refine_pole(freq_hz: np.ndarray, H: np.ndarray, pole: complex, *, quantity: str = "accelerance",
                half_widths: float = 3.0, min_lines: int = 7) -> complex:
    """The one pole (rad/s, upper half plane) that best fits all FRFs ``H`` [n_out, n_in, n_freq] near
    ``pole`` in the least-squares sense, starting from ``pole``: residues per FRF and constant and
    1/w^2 residuals (the LSFD model above) projected out (variable projection, Golub & Pereyra 1973),
    on the lines within ``half_widths`` half-power bandwidths of the start (at least ``min_lines``).
    For one resonance that a pole pair straddles (a split mode): the pair's weighted average is biased
    towards the broader pole's damping, the single-pole fit is not.  Returns ``pole`` unchanged when
    the fit leaves the start's half-power band or has no damping.

    Examples
    --------
    >>> f = np.arange(90.0, 110.0, 0.25)
    >>> lam = 2 * np.pi * 100 * complex(-0.002, np.sqrt(1 - 0.002 ** 2))
    >>> iw = 2j * np.pi * f
    >>> H = (1 / (iw - lam) + 1 / (iw - lam.conjugate()))[None, None, :] * iw ** 2
    >>> p = refine_pole(f, H, complex(-2 * np.pi * 100 * 0.003, 2 * np.pi * 100.1))
    >>> round(abs(p) / (2 * np.pi), 6), round(-p.real / abs(p), 6)
    (100.0, 0.002)
    """
    import scipy.optimize

    f = np.asarray(freq_hz, float)
    wn, zeta = abs(pole), -pole.real / abs(pole)
    fn = wn / (2 * np.pi)
    step = float(np.median(np.diff(f)))
    near = np.abs(f - fn) <= max(half_widths * 2 * zeta * fn, 0.5 * min_lines * step)
    if near.sum() < min_lines or np.any(f[near] <= 0):
        return pole
    rhs = H[..., near].reshape(-1, near.sum()).T                                    # [nf, n_frf]
    rhs_r = np.vstack([rhs.real, rhs.imag])

    def misfit(x: np.ndarray) -> np.ndarray:
        lam = complex(-x[1] * x[0], x[0] * np.sqrt(max(1 - x[1] ** 2, 0.0)))
        A = _basis(f[near], np.array([lam]), quantity, True)
        A_r = np.vstack([A.real, A.imag])
        return (rhs_r - A_r @ np.linalg.lstsq(A_r, rhs_r, rcond=None)[0]).ravel()

    sol = scipy.optimize.least_squares(misfit, [wn, zeta], x_scale=[max(zeta, 1e-6) * wn, max(zeta, 1e-6)],
                                       method="lm")
    w_new, z_new = sol.x
    if not (sol.success and 0 < z_new < 1 and abs(w_new - wn) <= zeta * wn):
        return pole
    return complex(-z_new * w_new, w_new * np.sqrt(1 - z_new ** 2))
