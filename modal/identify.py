"""Modal identification from FRFs to natural frequencies, damping ratios and shapes, and on to the
modal table (docs/formats.md).  Methods: ``lscf`` (pLSCF poles with automatic stable-pole selection,
shapes by LSFD with residuals) and ``peak`` (CMIF peak picking, half-power damping, quadrature
shapes).  Damping added by an exponential window is removed from the identified poles."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np

from flexmodal.modal.damping import half_power
from flexmodal.modal.errors import ModalError
from flexmodal.modal.frf import convert
from flexmodal.modal.lscf import select_stable, stabilisation
from flexmodal.modal.lsfd import lsfd
from flexmodal.modal.mac import mass_normalised, to_real, unit_max
from flexmodal.modal.peaks import cmif, pick_peaks, quadrature_shapes
from flexmodal.modal.table import ModalTable
from flexmodal.modal.windows import remove_added_damping

METHODS = ("lscf", "peak")
MIN_LINES_PER_BANDWIDTH = 8   # below this the Hann-window leakage bias on damping exceeds a few %


@dataclass(frozen=True)
class Modes:
    """Identified modes: ``freq_hz``, ``damping_ratio`` [n_modes]; ``shapes`` [n_out, n_modes] real
    (mass-normalised when a driving point was given, else unit maximum); ``complex_shapes`` the
    modal constants of the reference column before conversion; warnings met on the way."""

    freq_hz: np.ndarray
    damping_ratio: np.ndarray
    shapes: np.ndarray
    complex_shapes: np.ndarray
    method: str
    mass_normalised: bool
    warnings: tuple[str, ...] = ()


def _band(freq_hz: np.ndarray, fmin: float | None, fmax: float | None) -> np.ndarray:
    f = np.asarray(freq_hz, float)
    lo = fmin if fmin is not None else (f[f > 0].min() if np.any(f > 0) else 0.0)
    hi = fmax if fmax is not None else f.max()
    band = (f >= lo) & (f <= hi) & (f > 0)
    if band.sum() < 8:
        raise ModalError(f"identify: only {int(band.sum())} frequency lines between {lo:g} and {hi:g} Hz")
    return band


def _shapes(constants: np.ndarray, driving_point: int | None) -> tuple[np.ndarray, bool]:
    if driving_point is not None:
        return to_real(mass_normalised(constants, driving_point)), True
    return to_real(unit_max(constants)), False


def identify(freq_hz: np.ndarray, H: np.ndarray, *, method: str = "lscf", fmin: float | None = None,
             fmax: float | None = None, coherence: np.ndarray | None = None,
             quantity: str = "accelerance", decay_rate_per_s: float = 0.0, reference: int = 0,
             driving_point: int | None = None, max_order: int = 40) -> Modes:
    """Identify the modes of FRFs ``H`` [n_out, n_in, n_freq] in [fmin, fmax] Hz.

    ``quantity`` of H (accelerance, mobility, receptance); ``decay_rate_per_s`` of an exponential
    window to remove; ``reference`` the input column whose shapes are reported; ``driving_point`` the
    output row measured at that input (mass-normalised shapes); ``max_order`` the highest pLSCF order
    of the stabilisation diagram (orders 2..max_order).
    """
    if method not in METHODS:
        raise ModalError(f"method {method!r}: use one of {', '.join(METHODS)}")
    H = np.asarray(H)
    if H.ndim != 3 or H.shape[-1] != len(freq_hz):
        raise ModalError(f"identify: FRFs of shape {H.shape} do not match {len(freq_hz)} lines")
    if not np.all(np.isfinite(H[..., np.asarray(freq_hz) > 0])):
        raise ModalError("identify: the FRFs contain NaN or infinite values")
    band = _band(freq_hz, fmin, fmax)
    f, Hb = np.asarray(freq_hz, float)[band], H[..., band]
    warnings: list[str] = []
    if method == "lscf":
        top = int(min(max_order, (f.size - 2) // 2))
        stab = stabilisation(f, Hb, range(2, top + 1))
        fn, zeta, poles = select_stable(stab)
        if fn.size == 0:
            raise ModalError(f"identify: no stable poles between {f.min():g} and {f.max():g} Hz")
        constants = lsfd(f, Hb, poles, quantity=quantity).modal_constants(poles)[:, reference]
    else:
        coh = coherence[:, band] if coherence is not None else None
        lines = pick_peaks(f, Hb, coherence=coh)
        if lines.size == 0:
            raise ModalError(f"identify: no resonance peak between {f.min():g} and {f.max():g} Hz")
        rec = convert(Hb, f, quantity, "receptance")
        indicator = cmif(rec)[0]
        fits = []
        for k in lines:   # a loop over peaks (modes)
            try:
                fits.append(half_power(f, indicator, int(k)))
            except ModalError as exc:
                warnings.append(str(exc))
        if not fits:
            raise ModalError("identify: no peak had two half-power points (" + "; ".join(warnings) + ")")
        warnings += [w for h in fits for w in h.warnings]
        fn = np.array([h.fn_hz for h in fits])
        zeta = np.array([h.damping_ratio for h in fits])
        used = np.array([int(np.argmin(np.abs(f - h.fn_hz))) for h in fits])
        constants = quadrature_shapes(rec, used, reference).astype(complex)
    df = float(np.median(np.diff(f)))
    for fr, z in zip(fn, zeta, strict=True):   # leakage biases damping when the band holds few lines
        if 2 * z * fr < MIN_LINES_PER_BANDWIDTH * df:
            warnings.append(f"mode at {fr:.4g} Hz: {2 * z * fr / df:.1f} lines in its half-power band "
                            f"(< {MIN_LINES_PER_BANDWIDTH}); damping may be biased high, use a longer nfft")
    if decay_rate_per_s:
        fn, zeta = remove_added_damping(fn, zeta, decay_rate_per_s)
        spurious = zeta <= 0  # less damping than the window itself added: not a structural mode
        warnings += [f"dropped a pole at {fr:.4g} Hz: its damping is below the exponential window's "
                     f"(a spurious or aliased pole)" for fr in fn[spurious]]
        fn, zeta, constants = fn[~spurious], zeta[~spurious], constants[:, ~spurious]
        if fn.size == 0:
            raise ModalError("identify: every pole had less damping than the exponential window added")
    shapes, massn = _shapes(constants, driving_point if method == "lscf" else None)
    order = np.argsort(fn)
    return Modes(fn[order], zeta[order], shapes[:, order], constants[:, order], method, massn,
                 tuple(warnings))


def modes_table(modes: Modes, outputs: Sequence[str], *, config: str = "run",
                pose: Mapping[str, float] | None = None, source: str = "experiment") -> ModalTable:
    """The modal table of one configuration: config, mode, freq_hz, damping_ratio, source, pose.*,
    shape.<output>."""
    records = []
    for r in range(modes.freq_hz.size):
        row: dict[str, object] = {"config": config, "mode": r + 1, "freq_hz": float(modes.freq_hz[r]),
                                  "damping_ratio": float(modes.damping_ratio[r]), "source": source}
        row.update({f"pose.{k}": v for k, v in (pose or {}).items()})
        row.update({f"shape.{name}": float(modes.shapes[j, r]) for j, name in enumerate(outputs)})
        records.append(row)
    return ModalTable.from_records(records, source=f"identified ({modes.method})")


def identify_modes(freq_hz: np.ndarray, H: np.ndarray, *, outputs: Sequence[str] | None = None,
                   config: str = "run", pose: Mapping[str, float] | None = None, **options) -> ModalTable:
    """:func:`identify` then :func:`modes_table` (outputs default to ``o1``, ``o2``, ...)."""
    modes = identify(freq_hz, H, **options)
    names = list(outputs) if outputs is not None else [f"o{j + 1}" for j in range(np.shape(H)[0])]
    return modes_table(modes, names, config=config, pose=pose)
