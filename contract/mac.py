"""Mode-shape tools: MAC and AutoMAC (Allemang & Brown 1982), unit-max and mass normalisation,
complex-to-real conversion.  Shapes are columns: ``phi`` [n_points, n_modes]."""

from __future__ import annotations

import numpy as np


def mac(phi_a: np.ndarray, phi_b: np.ndarray) -> np.ndarray:
    """Modal assurance criterion [n_a, n_b] = |phi_a^H phi_b|^2 / ((phi_a^H phi_a)(phi_b^H phi_b))."""
    a = np.atleast_2d(np.asarray(phi_a))
    b = np.atleast_2d(np.asarray(phi_b))
    if a.shape[0] != b.shape[0]:
        a, b = a.T, b.T
    num = np.abs(a.conj().T @ b) ** 2
    den = np.outer(np.sum(np.abs(a) ** 2, axis=0), np.sum(np.abs(b) ** 2, axis=0))
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.nan_to_num(num / den)


def mac_pairs(phi_a: np.ndarray, phi_b: np.ndarray) -> np.ndarray:
    """MAC of corresponding columns [n_modes] (the diagonal of ``mac`` without the rest)."""
    num = np.abs(np.einsum("ir,ir->r", phi_a.conj(), phi_b)) ** 2
    den = np.einsum("ir,ir->r", phi_a.conj(), phi_a).real * np.einsum("ir,ir->r", phi_b.conj(), phi_b).real
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.nan_to_num(num / den)


def automac(phi: np.ndarray) -> np.ndarray:
    """MAC of a shape set with itself [n_modes, n_modes] (off-diagonal terms reveal spatial aliasing)."""
    return mac(phi, phi)


def to_real(phi: np.ndarray) -> np.ndarray:
    """Real shapes: rotate each complex column onto the line that best fits it in the complex plane
    (angle 0.5 arg(sum phi^2)), take the real part, and make the largest entry positive."""
    p = np.atleast_2d(np.asarray(phi, complex))
    theta = 0.5 * np.angle(np.sum(p ** 2, axis=0))
    real = (p * np.exp(-1j * theta)[None, :]).real
    return real * largest_positive(real)


def largest_positive(ref: np.ndarray) -> np.ndarray:
    """Sign per column [n_modes] (+1 or -1) that makes the entry of largest magnitude of each column of
    the real ``ref`` [n_points, n_modes] positive: the one sign convention of every shape in flexmodal
    (an all-zero column, or a ``ref`` with no rows, keeps +1)."""
    ref = np.asarray(ref, float)
    if ref.shape[0] == 0:
        return np.ones(ref.shape[1])
    sign = np.sign(ref[np.argmax(np.abs(ref), axis=0), np.arange(ref.shape[1])])
    return np.where(sign == 0, 1.0, sign)


def unit_max(phi: np.ndarray) -> np.ndarray:
    """Scale each column so that its entry of largest magnitude is exactly 1 (phase and amplitude)."""
    p = np.atleast_2d(np.asarray(phi))
    return p / p[np.argmax(np.abs(p), axis=0), np.arange(p.shape[1])][None, :]


def mass_normalised(modal_constants: np.ndarray, driving_index: int) -> np.ndarray:
    """Mass-normalised shapes from modal constants A_jk,r = phi_j phi_k (one reference k whose
    response is row ``driving_index``): phi_j = A_jk / sqrt(A_kk)  (Ewins 2000 §5.4)."""
    a = np.atleast_2d(np.asarray(modal_constants, complex))
    return a / np.sqrt(a[driving_index])[None, :]
