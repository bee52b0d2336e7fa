"""Mode-shape tools: MAC and AutoMAC (Allemang & Brown 1982), unit-max and mass normalisation,
complex-to-real conversion.  Shapes are columns: ``phi`` [n_points, n_modes]."""

from __future__ import annotations

import numpy as np


def mac(phi_a: np.ndarray, phi_b: np.ndarray) -> np.ndarray:
    """Modal assurance criterion [n_a, n_b] = |phi_a^H phi_b|^2 / ((phi_a^H phi_a)(phi_b^H phi_b)) [-]
    of the columns of ``phi_a`` against those of ``phi_b`` (Allemang & Brown 1982), in [0, 1].

    NaN where a column is all zero (or holds a NaN): a shape without motion at the points has no
    direction, so its MAC with anything is undefined, not 0 (0 would say "a shape unlike the other").
    A caller that ranks or gates by MAC says what undefined counts as: ``mac >= threshold`` is False
    for NaN; ``np.nan_to_num(m, nan=0.0)`` counts it as unlike.

    Examples
    --------
    >>> import numpy as np
    >>> phi = np.array([[1.0, 0.0, 0.0], [1.0, 1.0, 0.0]])
    >>> mac(phi, phi).round(3)
    array([[1. , 0.5, nan],
           [0.5, 1. , nan],
           [nan, nan, nan]])
    >>> mac(phi * 1e-200, phi * 1e150).round(3)[:2, :2]   # any scale: the squares neither under- nor overflow
    array([[1. , 0.5],
           [0.5, 1. ]])
    """
    a = np.atleast_2d(np.asarray(phi_a))
    b = np.atleast_2d(np.asarray(phi_b))
    if a.shape[0] != b.shape[0]:
        a, b = a.T, b.T
    a, b = _binary_scaled(a), _binary_scaled(b)
    num = np.abs(a.conj().T @ b) ** 2
    den = np.outer(np.sum(np.abs(a) ** 2, axis=0), np.sum(np.abs(b) ** 2, axis=0))
    return _defined_ratio(num, den)


def mac_pairs(phi_a: np.ndarray, phi_b: np.ndarray) -> np.ndarray:
    """MAC of corresponding columns [n_modes] [-] (the diagonal of ``mac`` without the rest; NaN where
    either column is all zero, as in ``mac``).

    Examples
    --------
    >>> import numpy as np
    >>> mac_pairs(np.array([[1.0, 1.0], [0.0, 0.0]]), np.array([[1.0, 0.0], [1.0, 0.0]]))
    array([0.5, nan])
    """
    phi_a, phi_b = _binary_scaled(np.asarray(phi_a)), _binary_scaled(np.asarray(phi_b))
    num = np.abs(np.einsum("ir,ir->r", phi_a.conj(), phi_b)) ** 2
    den = np.einsum("ir,ir->r", phi_a.conj(), phi_a).real * np.einsum("ir,ir->r", phi_b.conj(), phi_b).real
    return _defined_ratio(num, den)


def _binary_scaled(phi: np.ndarray) -> np.ndarray:
    """``phi`` [n_points, n_modes] with each column multiplied by the power of two that brings its
    largest magnitude into [0.5, 1): exact (only the exponents change), so the MAC of ordinary shapes
    is unchanged to the last bit, while the fourth powers of a column of 1e-100 (or 1e100), which
    underflowed to 0 (or overflowed), stay finite.  An all-zero or non-finite column is left as it is.

    Examples
    --------
    >>> _binary_scaled(np.array([[3.0, 0.0], [-1.0, 0.0]]))
    array([[ 0.75,  0.  ],
           [-0.25,  0.  ]])
    """
    exponent = np.frexp(np.max(np.abs(phi), axis=0, initial=0.0))[1]   # 0 for 0, NaN and inf
    return np.ldexp(phi.real, -exponent) + 1j * np.ldexp(phi.imag, -exponent) if np.iscomplexobj(phi) \
        else np.ldexp(phi.astype(float, copy=False), -exponent)


def _defined_ratio(num: np.ndarray, den: np.ndarray) -> np.ndarray:
    """``num / den`` where ``den`` > 0, NaN elsewhere (a zero or NaN shape: MAC undefined)."""
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where(den > 0, num / np.where(den > 0, den, 1.0), np.nan)


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
