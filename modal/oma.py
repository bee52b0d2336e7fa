"""Output-only (operational) identification of a stored record: which method a run gets, which channels
are the outputs and references, and the call into SSI-cov (:mod:`flexmodal.modal.ssi`) or FDD
(:mod:`flexmodal.modal.fdd`).

A run is output-only when its ``excitation`` attribute is ``operational`` or it records no force
channel; it then defaults to ``ssi``, otherwise to ``lscf`` (FRF-based).  Outputs are the
acceleration channels (else every channel that is neither a force nor an encoder), as for FRFs.
References are all outputs unless named.  Without ``fmin``, SSI's Hankel matrix is sized for half the
lowest FDD mode (a quick look costing a fraction of the SSI), so low modes are not missed; when FDD
validates no mode, for the lowest peak of its spectrum (:func:`lowest_spectral_peak`).  Rows of
NaN (samples lost in acquisition, recorded as gap events) are left out of the covariances (SSI) and
of the spectral segments (FDD).  Shapes are unscaled (unit largest entry): with no force measured
there is no modal mass.  :func:`output_only_results` runs both methods on one record for display
(the report's FDD and SSI figures, reports/oma.py).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, replace

import numpy as np
import scipy.signal

from flexmodal.modal.compute import check_samples
from flexmodal.modal.errors import ModalError
from flexmodal.modal.fdd import FddResult, cross_spectra, fdd
from flexmodal.modal.identify import nyquist_note
from flexmodal.modal.oma_uncertainty import N_BLOCKS
from flexmodal.modal.registry import METHODS, output_only
from flexmodal.modal.spectra import default_nfft
from flexmodal.modal.ssi import SsiResult, ssi_cov

FROM_FDD = object()         # SSI sized for fmin, else half the lowest FDD peak (identify_output_only)
FDD_PROMINENCE_DB = 6.0     # a spectral peak stands this far out of the first singular value (FDD's)
DC_LINES = 4                # ... above the Hann main lobe (+-2 lines) of the record's mean and drift
SPECTRUM_MARGIN = 1.1       # ... up to 10 % above the highest pole drawn


@dataclass(frozen=True)
class OmaResults:
    """Both output-only identifications of one record, as a report draws them: the response channel
    names ``outputs``; the FDD and SSI-cov results (``fdd``, ``ssi``), each replaced by the reason
    (one line) when that method found nothing; and, with an SSI result, the Welch cross-spectral
    matrix ``spectrum`` [n_freq, n_outputs, n_refs] (outputs' unit squared per Hz) of the outputs with
    SSI's references on the lines ``spectrum_hz`` [Hz] from the first above 0 Hz to 1.1 times the
    highest pole of the stabilisation diagram, whose singular values the diagram is drawn over (None
    when no segment of the record is free of gaps)."""

    outputs: tuple[str, ...]
    fdd: FddResult | str
    ssi: SsiResult | str
    spectrum_hz: np.ndarray | None = None
    spectrum: np.ndarray | None = None


def default_method(kinds: Sequence[str], excitation: str = "") -> str:
    """``ssi`` for an operational run or one without a force channel, else ``lscf``."""
    return "ssi" if excitation == "operational" or "force" not in kinds else "lscf"


def output_channels(kinds: Sequence[str]) -> list[int]:
    """Indices of the response channels: accelerations, else every non-force, non-encoder channel."""
    acc = [j for j, k in enumerate(kinds) if k == "acceleration"]
    return acc or [j for j, k in enumerate(kinds) if k not in ("force", "encoder")]


def identify_output_only(samples: np.ndarray, sample_rate_hz: float, names: Sequence[str],
                         kinds: Sequence[str], *, method: str = "ssi", fmin: float | None = None,
                         fmax: float | None = None, max_order: int | None = None,
                         references: Sequence[str] | None = None, where: str = "record",
                         lowest_hz: float | None | object = FROM_FDD
                         ) -> tuple[SsiResult | FddResult, tuple[str, ...]]:
    """SSI-cov or FDD of the response channels of a record [n_samples, n_channels]; returns the
    method's result (with ``.modes``) and the output channel names.  ``references`` name output
    channels (default all); ``max_order`` is SSI's highest model order (default 100); ``lowest_hz``
    the lowest frequency SSI's Hankel matrix is sized for (None: none; default :data:`FROM_FDD`:
    ``fmin``, else half the lowest FDD mode, else the lowest spectral peak)."""
    if method not in METHODS or not output_only(method):
        raise ModalError(f"method {method!r} is not output-only "
                         f"({', '.join(m for m in METHODS if output_only(m))})")
    samples = np.asarray(samples)
    gaps = np.isnan(samples).all(axis=1) if samples.ndim == 2 else np.zeros(0, bool)
    check_samples(samples[~gaps] if gaps.size else samples, names, where)   # NaN rows: lost samples
    outputs = output_channels(kinds)
    if not outputs:
        raise ModalError(f"{where}: no response channel to identify from")
    out_names = tuple(names[j] for j in outputs)
    refs = None
    if references:
        unknown = [r for r in references if r not in out_names]
        if unknown:
            what = "reference channel {} is" if len(unknown) == 1 else "reference channels {} are"
            raise ModalError(f"{where}: {what.format(', '.join(unknown))} not among the outputs "
                             f"({', '.join(out_names)})")
        refs = [out_names.index(r) for r in references]
    if fmin is not None and fmin >= sample_rate_hz / 2:
        raise ModalError(f"{where}: fmin {fmin:g} Hz is at or above the Nyquist frequency, "
                         f"{sample_rate_hz / 2:g} Hz: no band left to identify in")
    y = samples[:, outputs].astype(float)
    try:
        result = METHODS.entry(method).runner()(
            ResponseInputs(y, sample_rate_hz, refs, fmin, fmax, max_order, lowest_hz))
    except ModalError as exc:
        raise ModalError(f"{where}: {exc}") from None
    if fmax is not None and fmax > sample_rate_hz / 2:
        note = nyquist_note(fmax, sample_rate_hz / 2)
        result = replace(result, modes=replace(result.modes, warnings=(note, *result.modes.warnings)))
    if len(outputs) == 1:   # MAC, MPC, MPD and the singular vectors of one channel are always "perfect"
        warn = "one output channel: no shape criterion can tell modes from noise peaks"
        result = replace(result, modes=replace(result.modes, warnings=(*result.modes.warnings, warn)))
    return result, out_names


@dataclass(frozen=True)
class ResponseInputs:
    """What an output-only identification method (modal.registry.METHODS, input ``response``) is given:
    the response ``samples`` [n_samples, n_outputs] at ``sample_rate_hz`` [Hz], the ``references``
    (output columns; None: all), the band ``fmin``..``fmax`` [Hz], ``max_order`` and ``lowest_hz``
    (see :func:`identify_output_only`)."""

    samples: np.ndarray
    sample_rate_hz: float
    references: Sequence[int] | None
    fmin: float | None
    fmax: float | None
    max_order: int | None
    lowest_hz: float | None | object


def run_ssi(inp: ResponseInputs) -> SsiResult:
    """SSI-cov with its stabilisation diagram (the ``ssi`` method)."""
    lowest = ((inp.fmin or _lowest_peak(inp.samples, inp.sample_rate_hz, inp.references, inp.fmax))
              if inp.lowest_hz is FROM_FDD else inp.lowest_hz)
    return ssi_cov(inp.samples, inp.sample_rate_hz, references=inp.references, fmin=inp.fmin, fmax=inp.fmax,
                   max_order=100 if inp.max_order is None else inp.max_order, lowest_hz=lowest,
                   uncertainty_blocks=N_BLOCKS)


def run_fdd(inp: ResponseInputs) -> FddResult:
    """Frequency domain decomposition (the ``fdd`` method) with its sigma (the bootstrap over runs of
    Welch segments, modal/fdd.py: about eight times FDD's own CPU, 0.2 s against 0.025 s on a
    two-channel 240 s record)."""
    return fdd(inp.samples, inp.sample_rate_hz, references=inp.references, fmin=inp.fmin, fmax=inp.fmax,
               uncertainty_blocks=N_BLOCKS)


def _lowest_peak(y: np.ndarray, sample_rate_hz: float, refs: Sequence[int] | None, fmax: float | None
                 ) -> float | None:
    """Half the frequency of the lowest FDD mode [Hz]; when FDD validates no peak, the lowest peak of
    the first singular value (:func:`lowest_spectral_peak`); None when there is no peak at all."""
    try:
        return 0.5 * float(fdd(y, sample_rate_hz, references=refs, fmax=fmax).modes.freq_hz.min())
    except ModalError:
        return lowest_spectral_peak(y, sample_rate_hz, refs, fmax)


def lowest_spectral_peak(y: np.ndarray, sample_rate_hz: float, refs: Sequence[int] | None,
                         fmax: float | None) -> float | None:
    """Frequency [Hz] of the lowest peak standing ``FDD_PROMINENCE_DB`` out of the first singular value
    of the outputs' cross-spectral matrix (FDD's spectrum, up to ``fmax``), validated or not, or None;
peaks below line ``DC_LINES`` are the leakage of the mean and of drift (a measurement system's record
peaked at its first line, 0.1 Hz), not modes.

    The lowest frequency of interest when FDD validates no mode (operating machines: harmonics and
    non-white loads break its single-degree-of-freedom bell test, as on an operating wind turbine whose
    tower mode sits beside the rotor's 1P).  SSI's time lags are then sized by the rule of Rainieri &
    Fabbrocino (*Operational Modal Analysis of Civil Engineering Structures*, 2014, §4.5.2), block rows
    ``i >= f_s / (2 f_0)`` for the lowest frequency of interest ``f_0``: without it the Hankel matrix,
    sized for the model order only, spans less than one period of a slow mode (Peeters & De Roeck 1999).
    """
    y = np.asarray(y, float)
    refs = list(range(y.shape[1])) if refs is None else list(refs)
    try:
        f, G = cross_spectra(y, sample_rate_hz, refs, default_nfft(y.shape[0]))
    except ModalError:
        return None
    level = 10 * np.log10(np.linalg.svd(G, compute_uv=False)[:, 0] + 1e-300)
    band = (f > 0) & (f <= (fmax if fmax is not None else f[-1]))
    peaks, _ = scipy.signal.find_peaks(np.where(band, level, level[band].min()), prominence=FDD_PROMINENCE_DB)
    peaks = peaks[band[peaks] & (peaks >= DC_LINES)]
    return float(f[peaks[0]]) if peaks.size else None


def output_only_results(samples: np.ndarray, sample_rate_hz: float, names: Sequence[str],
                        kinds: Sequence[str], *, fmin: float | None = None, fmax: float | None = None,
                        where: str = "record") -> OmaResults:
    """FDD and SSI-cov (:func:`identify_output_only` with the band ``fmin``..``fmax`` [Hz], default the
    whole record, and its other options at their defaults) of a record [n_samples, n_channels] sampled
    at ``sample_rate_hz`` [Hz], each method's failure kept as its message, and the
    cross-spectral matrix under SSI's stabilisation diagram.  One Welch spectrum serves all three:
    FDD's (every output against every output, :func:`flexmodal.modal.spectra.default_nfft`), whose
    lowest peak also sizes SSI's Hankel matrix when ``fmin`` is not given; it is computed apart only
    when FDD fails."""
    outputs = tuple(names[j] for j in output_channels(kinds))

    def run(method: str, lowest_hz) -> SsiResult | FddResult | str:
        nonlocal outputs
        try:
            result, outputs = identify_output_only(samples, sample_rate_hz, names, kinds, method=method,
                                                   fmin=fmin, fmax=fmax, where=where, lowest_hz=lowest_hz)
        except ModalError as exc:
            return str(exc)
        return result

    found = {"fdd": run("fdd", None)}
    lowest = fmin or (0.5 * float(found["fdd"].modes.freq_hz.min())     # what _lowest_peak finds
                      if isinstance(found["fdd"], FddResult) else FROM_FDD)
    found["ssi"] = run("ssi", lowest)
    fdd_res, ssi_res = found["fdd"], found["ssi"]
    if not isinstance(ssi_res, SsiResult):
        return OmaResults(outputs, fdd_res, ssi_res)
    if isinstance(fdd_res, FddResult) and fdd_res.spectrum.shape[2] == len(ssi_res.references):
        f, G = fdd_res.freq_hz, fdd_res.spectrum          # every output is a reference of both
    else:
        y = np.asarray(samples)[:, [list(names).index(o) for o in outputs]].astype(float)
        try:
            f, G = cross_spectra(y, sample_rate_hz, ssi_res.references, default_nfft(y.shape[0]))
        except ModalError:   # no segment free of gaps: SSI's modes without the spectrum
            return OmaResults(outputs, fdd_res, ssi_res)
    top = SPECTRUM_MARGIN * ssi_res.stabilisation.freq_hz.max(initial=f[-1] / SPECTRUM_MARGIN)
    band = (f > 0) & (f <= max(top, f[1]))
    return OmaResults(outputs, fdd_res, ssi_res, f[band], G[band])
