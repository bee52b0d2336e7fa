"""FRF estimators and coherence from averaged spectra (Bendat & Piersol 2010 §9; Maia & Silva 1997 §3.8).

``H1 = G_xf G_ff^-1`` (noise on outputs), ``H2 = G_xx / G_fx`` (noise on the input; single reference),
``Hv`` the total-least-squares estimate between them (single reference, equal noise ratio).  Ordinary
coherence for one reference, multiple coherence ``G_xf G_ff^-1 G_fx / G_xx`` for several.  FRF
quantities convert by powers of ``i omega``: accelerance = i omega mobility = (i omega)^2 receptance.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from flexmodal.modal.errors import ModalError
from flexmodal.modal.registry import ESTIMATORS
from flexmodal.modal.spectra import Spectra

QUANTITIES = {"receptance": 0, "mobility": 1, "accelerance": 2}
COHERENCE_SLACK = 1e-6  # rounding above 1 that a computed coherence may carry


def check_coherence(coherence: np.ndarray, where: str) -> None:
    """Raise ModalError when a coherence holds a value outside [0, 1] or an infinity (NaN, a line
    with no power, is allowed): FRFs of another tool whose coherence is 2 or -1 are not what the
    file or arrays claim, and the band choice trusts them.

    Examples
    --------
    >>> check_coherence(np.array([[0.0, 0.5, 1.0, np.nan]]), "x")
    >>> check_coherence(np.array([[0.5, 2.0]]), "run.h5: run 'r1': frf group")
    Traceback (most recent call last):
    ...
    flexmodal.modal.errors.ModalError: run.h5: run 'r1': frf group: 'coherence' holds 2, outside [0, 1]
    """
    bad = np.isinf(coherence) | (coherence < 0) | (coherence > 1 + COHERENCE_SLACK)
    if bad.any():
        raise ModalError(f"{where}: 'coherence' holds {coherence[bad].flat[0]:g}, outside [0, 1]")


MAX_LINE_HZ = 1e9          # contract.table.MAX_FREQ_HZ: no structural mode is above 1 GHz
MIN_LINE_SPACING_HZ = 1e-9  # the resolution of a 1e9 s record (acquire's --duration bound, 31.7 years)


def check_freq_axis(freq_hz: np.ndarray, where: str, name: str = "freq_hz") -> None:
    """Raise ModalError unless ``freq_hz`` [Hz] is 1-D, finite, >= 0, increasing by at least
    :data:`MIN_LINE_SPACING_HZ` and at most :data:`MAX_LINE_HZ`: the one check of every frequency
    axis given to flexmodal (a stored FRF group, a UFF file, :func:`flexmodal.api.frf_from_arrays`).
    An axis in other units (lines 1e-300 Hz apart, or at 1e12 Hz) made the identification fail
    inside (NaN in a factorisation) or name its result instead of the input.

    Parameters
    ----------
    freq_hz : numpy.ndarray
        The frequency lines [Hz].
    where : str
        The file or function the axis came from, first in the message.
    name : str
        The axis' name in the message (``freq_hz``, ``abscissa``).

    Returns
    -------
    None
        It returns only when the axis is fit for use.

    Raises
    ------
    flexmodal.modal.errors.ModalError
        One line naming ``where``, ``name`` and what is wrong.

    Examples
    --------
    >>> check_freq_axis(np.array([0.0, 0.5, 1.0]), "x")
    >>> check_freq_axis(np.array([0.0, 1e-300, 2e-300]), "u.uff", "abscissa")  # doctest: +ELLIPSIS
    Traceback (most recent call last):
    ...
    flexmodal.modal.errors.ModalError: u.uff: abscissa lines 1e-300 Hz apart: closer than 1e-09 Hz ...
    """
    f = np.asarray(freq_hz)
    if f.ndim != 1 or f.dtype.kind not in "fiu":
        raise ModalError(f"{where}: {name} must be a 1-D array of frequencies [Hz] (shape {f.shape}, type "
                         f"{f.dtype})")
    f = f.astype(float)
    if not np.isfinite(f).all() or (f.size and f[0] < 0) or (f.size > 1 and not (np.diff(f) > 0).all()):
        raise ModalError(f"{where}: {name} must be finite, >= 0 and increasing")
    step = float(np.diff(f).min()) if f.size > 1 else MIN_LINE_SPACING_HZ
    if step < MIN_LINE_SPACING_HZ:
        raise ModalError(f"{where}: {name} lines {step:.3g} Hz apart: closer than {MIN_LINE_SPACING_HZ:g} Hz "
                         "(a record longer than 1e9 s); is the axis in Hz?")
    if f.size and f[-1] > MAX_LINE_HZ:
        raise ModalError(f"{where}: {name} reaches {f[-1]:.3g} Hz, above {MAX_LINE_HZ:g} Hz; is the axis in "
                         "Hz?")


@dataclass(frozen=True)
class FrfResult:
    """FRFs of one test, with the processing that produced them (what ``/runs/<id>/frf`` stores,
    docs/hdf5-format.md).

    Parameters
    ----------
    freq_hz : ndarray [n_freq]
        Frequency lines [Hz].
    H : ndarray [n_out, n_in, n_freq]
        Complex FRFs in ``quantity`` per input unit (accelerance: (m/s²)/N).
    coherence : ndarray [n_out, n_freq]
        Ordinary coherence [-] of each output (multiple coherence with several inputs).
    estimator : str
        The FRF estimator (``H1``, ``H2``, ``Hv``, or a registered one).
    window : str
        The window of each segment (``hann``; impact records ``force:0.05,exponential:1``).
    nfft : int
        Segment length [samples].
    n_averages : int
        Segments (or accepted hits) averaged [count].
    sample_rate_hz : float
        Sample rate of the records [Hz].
    quantity : {"accelerance", "mobility", "receptance"}
        What ``H`` is: (m/s²)/N, (m/s)/N or m/N.
    outputs, inputs : tuple of str
        Channel names of the rows and columns of ``H``.
    decay_rate_per_s : float
        Decay rate [1/s] an exponential window added (0: none); identification removes it from the
        damping.
    provenance : dict
        Processing details (overlap, segments skipped, accepted and rejected hits, excitation), stored
        as JSON with the FRFs.
    """

    freq_hz: np.ndarray
    H: np.ndarray
    coherence: np.ndarray
    estimator: str
    window: str
    nfft: int
    n_averages: int
    sample_rate_hz: float
    quantity: str = "accelerance"
    outputs: tuple[str, ...] = ()
    inputs: tuple[str, ...] = ()
    decay_rate_per_s: float = 0.0
    provenance: dict = field(default_factory=dict)


def _solve_inputs(g_xf: np.ndarray, g_ff: np.ndarray) -> np.ndarray:
    """G_xf G_ff^-1 for every line: [n_out, n_in, f] (batched solve, no loop over lines)."""
    a = np.moveaxis(g_ff, -1, 0)                      # [f, i, j]
    b = np.moveaxis(g_xf, -1, 0)                      # [f, o, i]
    try:   # H G_ff = G_xf  <=>  G_ff^T H^T = G_xf^T
        x = np.swapaxes(np.linalg.solve(np.swapaxes(a, 1, 2), np.swapaxes(b, 1, 2)), 1, 2)
    except np.linalg.LinAlgError:
        # a line where the inputs are not independent (no energy there, or fewer averages than inputs
        # at that line): the minimum-norm solution, G_xf pinv(G_ff) (Bendat & Piersol 2010 §7.3)
        x = b @ np.linalg.pinv(a, hermitian=True)
    return np.moveaxis(x, 0, -1)


def h1(s: Spectra) -> np.ndarray:
    """H1 estimator [n_out, n_in, f]; 0 at lines where the inputs carry no energy (the minimum-norm
    solution, G_xf pinv(G_ff), as for several inputs; their coherence is 0)."""
    if s.g_ff.shape[0] == 1:
        gff = s.g_ff[0, 0].real
        return np.divide(s.g_xf, gff, out=np.zeros_like(s.g_xf), where=gff > 0)
    return _solve_inputs(s.g_xf, s.g_ff)


def _single_input(s: Spectra, name: str) -> None:
    if s.g_ff.shape[0] != 1:
        raise ModalError(f"estimator {name}: needs a single reference (this test has {s.g_ff.shape[0]})")


def h2(s: Spectra) -> np.ndarray:
    """H2 estimator G_xx / G_fx [n_out, 1, f] (single reference)."""
    _single_input(s, "H2")
    with np.errstate(divide="ignore", invalid="ignore"):
        return (s.g_xx / s.g_xf[:, 0].conj())[:, None, :]


def hv(s: Spectra) -> np.ndarray:
    """Hv estimator (total least squares, equal input/output noise ratio) [n_out, 1, f]."""
    _single_input(s, "Hv")
    gff = s.g_ff[0, 0].real
    gxf = s.g_xf[:, 0]
    diff = s.g_xx - gff
    g2 = np.abs(gxf) ** 2
    root = np.sqrt(diff ** 2 + 4 * g2)
    with np.errstate(divide="ignore", invalid="ignore"):
        # diff + root, written without cancellation where diff < 0
        num = np.where(diff >= 0, diff + root, 4 * g2 / (root - diff))
        return (num / (2 * gxf.conj()))[:, None, :]


def coherence(s: Spectra) -> np.ndarray:
    """Ordinary (one reference) or multiple (several references) coherence [n_out, f], in [0, 1]."""
    with np.errstate(divide="ignore", invalid="ignore"):
        if s.g_ff.shape[0] == 1:
            c = np.abs(s.g_xf[:, 0]) ** 2 / (s.g_ff[0, 0].real * s.g_xx)
        else:
            h = _solve_inputs(s.g_xf, s.g_ff)
            c = np.einsum("oif,oif->of", h, s.g_xf.conj()).real / s.g_xx
    return np.clip(np.nan_to_num(c), 0.0, 1.0)


Estimator = Callable[[Spectra], np.ndarray]


def estimator_name(estimator: str) -> str:
    """The registered spelling of ``estimator`` (``h1`` -> ``H1``; modal.registry.ESTIMATORS);
    ModalError naming the choices."""
    return ESTIMATORS.name(estimator)


def estimate(s: Spectra, estimator: str) -> np.ndarray:
    """FRFs [n_out, n_in, n_freq] of spectra ``s`` by the registered ``estimator`` (H1, H2, Hv, ...)."""
    return ESTIMATORS.entry(estimator)(s)


def convert(H: np.ndarray, freq_hz: np.ndarray, source: str, target: str) -> np.ndarray:
    """Convert an FRF between receptance, mobility and accelerance (multiply by (i omega)^k).

    Lines at 0 Hz become 0 (to a higher power) or NaN (to a lower power)."""
    for q in (source, target):
        if q not in QUANTITIES:
            raise ModalError(f"FRF quantity {q!r}: use one of {', '.join(QUANTITIES)}")
    power = QUANTITIES[target] - QUANTITIES[source]
    with np.errstate(divide="ignore", invalid="ignore"):
        factor = (2j * np.pi * np.asarray(freq_hz)) ** power
    if power < 0:
        factor = np.where(np.asarray(freq_hz) == 0, np.nan, factor)
    return H * factor
