"""FRFs of one stored run (or any record with the same fields): checks the record, picks the inputs
(force channels) and outputs, and runs Welch averaging or impact-hit processing by excitation."""

from __future__ import annotations

import numbers
from collections.abc import Sequence

import numpy as np

from flexmodal.checked_io.data_range import MAX_DATA, range_fault
from flexmodal.checked_io.text import naming
from flexmodal.modal.errors import ModalError
from flexmodal.modal.frf import FrfResult, coherence, estimate, estimator_name
from flexmodal.modal.spectra import Spectra, default_nfft, spectra_of_segments, welch_spectra
from flexmodal.modal.windows import added_decay_rate_per_s, impact_windows, parse_window

MIN_SEGMENTS = 8
SKIPPED_EVENTS = ("gap", "corrupt")


def welch_window(spec: str, excitation: str, where: str) -> None:
    """ModalError unless ``spec`` is one Welch window (rect, hann, flattop): a force or exponential
    window over every segment of a random record kept its first 5 % or weighted it away (the FRFs were
    computed from it without a word)."""
    name, _ = parse_window(spec)
    if "," in spec or name not in ("rect", "hann", "flattop"):
        raise ModalError(f"{where}: window {spec!r} is for impact hits; a {excitation or 'random'} run is "
                         "Welch-averaged with rect, hann or flattop")


def check_samples(samples: np.ndarray, names: Sequence[str], where: str, allow_nan: bool = False) -> None:
    """Raise ModalError naming the first channel with NaN/inf samples (only inf with ``allow_nan``:
    NaN rows of lost frames that the caller handles), values out of the range of
    checked_io.data_range, or a constant value."""
    _check_shape(samples, names, where)
    bad = np.isinf(samples) if allow_nan else ~np.isfinite(samples)
    if bad.any():
        i, c = np.argwhere(bad)[0]
        raise ModalError(f"{where}: channel {names[c]!r} holds {samples[i, c]} at sample {i}")
    for c, name in enumerate(names):   # a loop over channels
        fault = range_fault(np.nan_to_num(samples[:, c], nan=0.0))
        if fault:
            at, words = fault
            raise ModalError(f"{where}: channel {name!r}{f' at sample {at[0]}' if at else ''} {words}")
    with np.errstate(invalid="ignore"):
        flat = np.nanmax(samples, axis=0) == np.nanmin(samples, axis=0)
    if flat.any():
        raise ModalError(f"{where}: channel {names[int(np.argmax(flat))]!r} is constant "
                         f"({samples[0, int(np.argmax(flat))]:g} throughout)")


def _check_shape(samples, names: Sequence[str], where: str) -> None:
    if len(samples.shape) != 2 or samples.shape[1] != len(names):
        raise ModalError(f"{where}: samples of shape {samples.shape} do not match {len(names)} channels")
    if samples.shape[0] < 2:
        raise ModalError(f"{where}: record of {samples.shape[0]} samples is shorter than one segment")


def min_segments(n_segments: int) -> int:
    """Usable Welch segments a record of ``n_segments`` must keep after skipping NaN rows and gap or
    corrupt events: MIN_SEGMENTS, or half of them (rounded up) when the record has fewer than twice
    that many (so a clean record is never refused)."""
    return min(MIN_SEGMENTS, -(-n_segments // 2))


def _first_nonfinite(samples, chans: Sequence[int]) -> tuple[int, int, float] | None:
    """(sample, channel, value) of the first NaN/inf, or value above checked_io.data_range.MAX_DATA in
    magnitude, among channels ``chans``, read block by block."""
    step = 1 << 16
    for r in range(0, samples.shape[0], step):
        block = np.asarray(samples[r:r + step])[:, chans]
        with np.errstate(invalid="ignore"):
            bad = np.argwhere(~(np.abs(block, dtype=float) <= MAX_DATA))   # float32: 1e100 is no float32
        if bad.size:
            i, c = bad[0]
            return r + int(i), int(chans[c]), float(block[i, c])
    return None


def _check_welch(spectra: Spectra, samples, names: Sequence[str], chans: Sequence[int], where: str,
                 n_skip_events: int) -> None:
    """Refuse too few usable segments (naming the first NaN sample) and constant channels: a channel
    is constant when the standard deviation its spectrum holds (Parseval) is below 100 ulp of its
    mean, or zero."""
    n_seg = spectra.n_averages + spectra.n_skipped
    need = min_segments(n_seg)
    if spectra.n_averages < need:
        bad = _first_nonfinite(samples, chans)
        beyond = f", above {MAX_DATA:g} in magnitude" if bad and np.isfinite(bad[2]) else ""
        cause = [f"channel {names[bad[1]]!r} holds {bad[2]:g} at sample {bad[0]}{beyond}"] if bad else []
        cause += [f"{n_skip_events} gap/corrupt events"] if n_skip_events else []
        raise ModalError(f"{where}: only {spectra.n_averages} of {n_seg} segments usable, {need} needed "
                         f"({'; '.join(cause) or 'no cause found'})")
    df = spectra.freq_hz[1] - spectra.freq_hz[0]
    power = np.concatenate([np.einsum("iif->if", spectra.g_ff).real, spectra.g_xx]).sum(axis=1) * df
    tol = 100 * np.finfo(np.float32 if samples.dtype == np.float32 else np.float64).eps
    flat = np.sqrt(power) <= tol * np.abs(spectra.mean)
    if flat.any():
        k = int(np.argmax(flat))
        step = 1 << 16   # a channel of values below MIN_PEAK looks constant: its squares underflow to 0
        peak = max(float(np.max(np.abs(np.asarray(samples[r:r + step])[:, chans[k]])))
                   for r in range(0, samples.shape[0], step))
        fault = range_fault(np.array([peak]))
        raise ModalError(f"{where}: channel {names[chans[k]]!r} " + (fault[1] if fault else
                         f"is constant ({spectra.mean[k]:g} throughout)"))


def _sweeps_of(samples, inputs: Sequence[int]) -> np.ndarray | None:
    """Sweep starts of a record labelled a sweep (:func:`modal.sweep.sweep_plan` on its forces), or None
    (Welch) when its forces show no sweep, fewer sweeps than forces, or it holds lost (NaN) samples."""
    from flexmodal.modal.sweep import sweep_plan

    data = np.asarray(samples[()])
    return sweep_plan(data[:, list(inputs)]) if np.isfinite(data).all() else None


def frf_of_record(samples, sample_rate_hz: float, names: Sequence[str], kinds: Sequence[str],
                  *, excitation: str = "random", estimator: str = "H1", nfft: int | None = None,
                  window: str | None = None, overlap: float = 0.5, where: str = "record",
                  triggers: Sequence[int] | None = None, overloads: Sequence[tuple[int, int]] = (),
                  averaging: str = "linear", skip: Sequence[tuple[int, int]] = (),
                  pretrigger_s: float = 0.02, workers: int | None = None,
                  sweeps: Sequence[int] | None = None) -> FrfResult:
    """FRFs of a record [n_samples, n_channels] (an array, or an h5py dataset read block by block) with
    channel ``names`` and ``kinds`` (force channels are the inputs; acceleration channels, or else every
    other non-encoder channel, the outputs).

    Impact records (``excitation == "impact"``) are read whole, cut into hits (``triggers`` or
    detected), windowed ``window`` = "force:W,exponential:E" (default force:0.05 and no window on the
    responses, :func:`modal.windows.impact_windows`) and averaged, each record starting
    ``pretrigger_s`` before its trigger, hits touching NaN rows or a ``skip`` interval rejected one by
    one.  Swept-sine records with the sample indices ``sweeps`` where each sweep starts (found by
    :func:`modal.sweep.sweep_plan` on the forces of an ``excitation == "sweep"`` record given no
    ``nfft``, ``window`` or ``skip``) are cut into one segment per sweep, each transformed whole with
    a rectangular window (zero-padded to the longest), and averaged.  Other records are
    streamed through Welch averaging with ``window`` (default hann), ``nfft``, ``overlap`` and
    ``workers`` FFT threads, leaving out segments that hold NaN/inf samples or touch a ``skip``
    interval (first sample, count: gap and corrupt events); fewer usable segments than
    :func:`min_segments` is an error, and so is a constant channel.
    """
    if not np.isfinite(sample_rate_hz) or sample_rate_hz <= 0:
        raise ModalError(f"{where}: sample rate {sample_rate_hz} Hz is not positive")
    if nfft is not None and (isinstance(nfft, bool) or not isinstance(nfft, numbers.Integral)):
        raise TypeError(f"nfft must be a whole number of samples, got {nfft!r}")   # 1024.5 was cut to 1024
    if isinstance(overlap, bool) or not isinstance(overlap, numbers.Real):
        raise TypeError(f"overlap must be a fraction, got {overlap!r}")
    if not hasattr(samples, "shape"):
        samples = np.asarray(samples)
    _check_shape(samples, names, where)
    if averaging not in ("linear", "exponential"):   # Welch took any other word as linear
        raise ModalError(f"averaging {averaging!r}: use linear or exponential")
    inputs = [j for j, k in enumerate(kinds) if k == "force"]
    if not inputs:
        raise ModalError(f"{where}: no force channel to use as the FRF reference")
    outputs = [j for j, k in enumerate(kinds) if k == "acceleration"]
    quantity = "accelerance"
    if not outputs:
        outputs = [j for j, k in enumerate(kinds) if k not in ("force", "encoder")]
        quantity = "response/force"
    if not outputs:
        raise ModalError(f"{where}: no response channel besides the force")
    decay = 0.0
    if excitation == "sweep" and sweeps is None and nfft is None and window is None and not skip:
        sweeps = _sweeps_of(samples, inputs)
    if excitation == "impact":
        if len(inputs) != 1:
            raise ModalError(f"{where}: impact processing needs exactly one force channel")
        from flexmodal.modal.impact import impact_spectra  # only impact runs need it

        samples = np.asarray(samples[()])
        check_samples(samples, names, where, allow_nan=True)
        fw, ew = impact_windows(window)
        spectra, hits = impact_spectra(samples, sample_rate_hz, inputs[0], outputs, triggers=triggers,
                                       force_window=fw, exp_window=ew, overloads=overloads,
                                       averaging=averaging, gaps=skip, pretrigger_s=pretrigger_s)
        record = 2 * (spectra.freq_hz.size - 1)
        decay = added_decay_rate_per_s(ew, record, sample_rate_hz)
        used_window, used_nfft = f"{fw},{ew}", record
        extra = {"hits": [{"trigger": h.trigger, "accepted": h.accepted, "reason": h.reason} for h in hits],
                 "averaging": averaging}
    elif sweeps is not None:
        from flexmodal.modal.sweep import sweep_segments

        samples = np.asarray(samples[()])
        check_samples(samples, names, where)
        segments = sweep_segments(samples, np.asarray(sweeps, np.int64), inputs + outputs)
        used_window, used_nfft = "rect", segments.shape[-1]
        spectra = spectra_of_segments(segments, len(inputs), sample_rate_hz, np.ones(used_nfft))
        extra = {"excitation": "sweep", "sweeps": [int(k) for k in sweeps]}
    else:
        used_nfft = default_nfft(samples.shape[0]) if nfft is None else int(nfft)
        used_window = window or "hann"
        welch_window(used_window, excitation, where)
        try:
            spectra = welch_spectra(samples, sample_rate_hz, inputs, outputs, used_nfft, overlap=overlap,
                                    window_spec=used_window, workers=workers, skip=skip, min_segments=0)
        except ModalError as exc:
            raise ModalError(f"{where}: {exc}") from None
        _check_welch(spectra, samples, names, inputs + outputs, where, len(skip))
        extra = {"overlap": overlap, "averaging": "linear", "segments_used": spectra.n_averages,
                 "segments_skipped": spectra.n_skipped}
    H = estimate(spectra, estimator)
    return FrfResult(spectra.freq_hz, H, coherence(spectra), estimator_name(estimator), used_window,
                     used_nfft, spectra.n_averages, float(sample_rate_hz), quantity,
                     tuple(names[j] for j in outputs), tuple(names[j] for j in inputs), decay, extra)


def compute_frf(run, *, estimator: str = "H1", nfft: int | None = None, window: str | None = None,
                overlap: float = 0.5, averaging: str = "linear", workers: int | None = None) -> FrfResult:
    """FRFs of a stored run (a ``daq.store.Run``, its samples in memory or on disk as given by
    ``daq.store.open_run``): uses its excitation, trigger, overload, gap and corrupt events."""
    skip = [(e.sample_index, e.count) for e in run.events if e.kind in SKIPPED_EVENTS]
    triggers = [e.sample_index for e in run.events if e.kind == "trigger"] or None
    # (first sample, count) as stored: a count of 10^9 (or one past the run's end) was a Python list of
    # that many sample indices (frf hung); the hits test the intervals
    overloads = [(e.sample_index, e.count) for e in run.events if e.kind == "overload"]
    where = f"{run.path}:{run.run_id}"
    with naming(where, ModalError):  # messages from the spectra layer name the run too
        return frf_of_record(run.samples, run.sample_rate_hz, [c.name for c in run.channels],
                             [c.kind for c in run.channels], excitation=run.excitation, estimator=estimator,
                             nfft=nfft, window=window, overlap=overlap, where=where, triggers=triggers,
                             overloads=overloads, averaging=averaging, skip=skip, workers=workers)
