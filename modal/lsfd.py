"""Least-squares frequency-domain estimation of residues with lower and upper residual terms
(Peeters, Van der Auweraer, Guillaume & Leuridan 2004, "The PolyMAX frequency-domain method", §3.3).

For fixed poles ``lambda_r`` every FRF is fitted (in its own quantity, ``(i w)^q`` times receptance,
q = 0, 1, 2) by
``H(w) = (i w)^q [ sum_r ( R_r/(i w - lambda_r) + conj(R_r)/(i w - conj(lambda_r)) ) + LR/(i w)^2 + UR ]``
with complex residues ``R_r`` and real residuals LR (modes below the band) and UR (modes above).  The
design matrix is the same for every FRF, so all FRFs are solved in one real least-squares problem.
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
    ``synthesis`` [n_out, n_in, n_freq] the fitted FRFs (same quantity as the data)."""

    residues: np.ndarray
    lower: np.ndarray
    upper: np.ndarray
    synthesis: np.ndarray

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
        x = scipy.linalg.cho_solve(scipy.linalg.cho_factor(gram), proj)
    except np.linalg.LinAlgError:
        x, *_ = np.linalg.lstsq(np.vstack([An.real, An.imag]), np.vstack([rhs.real, rhs.imag]), rcond=None)
    x = x / norm[:, None]
    synth = (A @ x).T.reshape(n_out, n_in, nf)
    res = (x[:m] + 1j * x[m:2 * m]).T.reshape(n_out, n_in, m)
    lower = x[2 * m].reshape(n_out, n_in) if residuals else np.zeros((n_out, n_in))
    upper = x[2 * m + 1].reshape(n_out, n_in) if residuals else np.zeros((n_out, n_in))
    return LsfdResult(res, lower, upper, synth)
