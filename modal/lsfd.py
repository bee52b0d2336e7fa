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
