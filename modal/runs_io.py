"""FRFs stored with their run: ``/runs/<run_id>/frf/`` (docs/hdf5-format.md) holds ``H`` [n_out, n_in, n_freq]
complex, ``freq_hz`` [n_freq], ``coherence`` [n_out, n_freq] and the attributes ``estimator``,
``window``, ``nfft``, ``n_averages`` plus ``sample_rate_hz``, ``quantity``, ``outputs`` and ``inputs``
(JSON lists of channel names), ``decay_rate_per_s`` (exponential window) and ``provenance`` (JSON:
software, time, processing details such as accepted and rejected hits).  Runs are read with
``daq.store.read_run``."""

from __future__ import annotations

import json
import os
import secrets
import shutil
from datetime import UTC, datetime
from pathlib import Path

import h5py
import numpy as np

from flexmodal.checked_io.data_range import range_fault
from flexmodal.checked_io.output import signals_deferred
from flexmodal.checked_io.text import loads_json, nfc, one_line, shown_value
from flexmodal.daq.run_schema import MAX_EVENT_SAMPLES
from flexmodal.modal.errors import ModalError
from flexmodal.modal.frf import FrfResult, check_coherence, check_freq_axis

MAX_AVERAGES = 1 << 40   # averages of a stored FRF group: more than a record of 10^12 samples gives
#: the whole-number attributes of a stored FRF group and their ranges, checked on write and on read (one
#: bound for both sides).  ``nfft`` is bounded by the record length, not by frf --nfft's MAX_NFFT: an
#: impact record or a sweep segment is one FFT as long as the hit or the sweep (modal.compute)
WHOLE_NUMBERS = {"nfft": (1, MAX_EVENT_SAMPLES), "n_averages": (1, MAX_AVERAGES)}

FRF_GROUP = "frf"
PARTIAL_PREFIX = ".frf-partial-"   # the group an FRF set is written into before it is renamed ``frf``
METADATA_BYTES = 1 << 18          # room kept for HDF5 object headers and attributes beyond the arrays


def write_frf(path: str | Path, run_id: str, result: FrfResult) -> None:
    """Write (or replace) ``/runs/<run_id>/frf`` in the HDF5 file ``path``: complete or not at all.

    The arrays go into a hidden group that is renamed ``frf`` (replacing the old one) only once whole,
    so a full disk, an I/O error or a signal leaves the previous FRFs (or none) and never half a group;
    a device without room for the arrays is refused before the file is opened (the file stays
    byte-identical).  Failures raise :class:`ModalError` naming the file and run."""
    H = np.asarray(result.H, complex)
    freq_hz = np.asarray(result.freq_hz, float)
    coherence = np.asarray(result.coherence, float)
    where = f"{path}: run {run_id!r}"
    for key, (lo, hi) in WHOLE_NUMBERS.items():
        value = getattr(result, key)
        if isinstance(value, bool) or not isinstance(value, int | np.integer) or not lo <= value <= hi:
            raise ModalError(f"{where}: frf group: attribute {key} = {shown_value(value, 60)} is not "
                             f"{_whole(lo, hi)}; nothing written")
    need = H.nbytes + freq_hz.nbytes + coherence.nbytes + METADATA_BYTES
    target = Path(os.path.realpath(path))
    free = shutil.disk_usage(target.parent if target.parent.is_dir() else Path(".")).free
    if free < need:
        raise ModalError(f"{where}: no space left on the device for the FRFs ({need / 1e6:.2f} MB needed, "
                         f"{free / 1e6:.2f} MB free); the file is unchanged")
    created = not target.exists()
    try:
        # Ctrl-C waits for the group to be whole (milliseconds); the open is inside the deferral too, so a
        # signal can never fall between opening the file and entering ``with f`` (it would stay open)
        with signals_deferred(), _open_append(path) as f:
            g = f.require_group(f"runs/{run_id}")
            for stale in [k for k in g if k.startswith(PARTIAL_PREFIX)]:  # left by a killed writer
                del g[stale]
            partial = PARTIAL_PREFIX + secrets.token_hex(4)
            try:
                _fill(g.create_group(partial), H, freq_hz, coherence, result)
                if FRF_GROUP in g:
                    del g[FRF_GROUP]
                g.move(partial, FRF_GROUP)
            except BaseException:
                if partial in g:
                    del g[partial]
                raise
    except OSError as exc:
        if created:
            target.unlink(missing_ok=True)
        raise ModalError(f"{where}: cannot write the FRFs ({one_line(exc)}); the run keeps its previous "
                         "FRFs, if any") from None


def _open_append(path: str | Path) -> h5py.File:
    try:
        return h5py.File(path, "a", libver="latest")
    except OSError as exc:
        from flexmodal.daq.h5file import LOCKED, locked
        from flexmodal.daq.lock import holder

        pid = holder(path)
        if pid is not None:   # HDF5's own words suggested h5clear, which would damage the live run
            raise ModalError(f"{path}: being written by a running acquire (pid {pid or '?'}); compute its "
                             "FRFs when it has finished") from None
        if locked(exc):
            raise ModalError(f"{path}: cannot write the FRFs: {LOCKED}") from None
        raise ModalError(f"{path}: cannot open for writing FRFs ({one_line(exc)})") from None


def _fill(out: h5py.Group, H: np.ndarray, freq_hz: np.ndarray, coherence: np.ndarray,
          result: FrfResult) -> None:
    out.create_dataset("H", data=H)
    out.create_dataset("freq_hz", data=freq_hz)
    out.create_dataset("coherence", data=coherence)
    prov = {"software": "flexmodal.modal", "created": datetime.now(UTC).isoformat(timespec="seconds"),
            **result.provenance}
    out.attrs.update({"estimator": result.estimator, "window": result.window, "nfft": int(result.nfft),
                      "n_averages": int(result.n_averages),
                      "sample_rate_hz": float(result.sample_rate_hz),
                      "quantity": result.quantity, "outputs": json.dumps(list(result.outputs)),
                      "inputs": json.dumps(list(result.inputs)),
                      "decay_rate_per_s": float(result.decay_rate_per_s),
                      "provenance": json.dumps(prov)})


def read_frf(path: str | Path, run_id: str) -> FrfResult | None:
    """The stored FRFs of a run, or None when the run has no ``frf`` group.  The group is checked as
    the run group is (``daq.run_schema``): its type, links and filters, every dataset's rank, length
    and type, every attribute's type and range; ModalError names the file, run and item."""
    from flexmodal.daq.h5file import open_read  # fails at once on a truncated file (SWMR would wait)
    from flexmodal.daq.run_schema import check_dataset, member

    where = f"{path}: run {run_id!r}: frf group"
    with open_read(path) as f:
        runs = member(f, "runs", str(path), ModalError)
        run = member(runs, run_id, f"{path}: run {run_id!r}", ModalError) if isinstance(runs, h5py.Group) \
            else None
        g = member(run, FRF_GROUP, where, ModalError) if isinstance(run, h5py.Group) else None
        if g is None:
            return None
        if not isinstance(g, h5py.Group):
            raise ModalError(f"{where}: is not a group (it is {type(g).__name__})")
        data = {}
        for name in ("freq_hz", "H", "coherence"):
            d = member(g, name, where, ModalError)
            if not isinstance(d, h5py.Dataset):
                raise ModalError(f"{where}: lacks the dataset {name!r}")
            check_dataset(d, where, ModalError)
            data[name] = d
        freq_hz, H, coherence = _checked_arrays(data, where)
        a = _Attrs(g.attrs, where)
        outputs, inputs = a.names("outputs", H.shape[0]), a.names("inputs", H.shape[1])
        _check_names_are_channels(run, outputs, inputs, where)
        rate = a.number("sample_rate_hz", np.nan, positive=True)
        _check_rate(run, rate, freq_hz, where)
        return FrfResult(freq_hz, H, coherence, a.text("estimator"), a.text("window"),
                         a.integer("nfft", *WHOLE_NUMBERS["nfft"]),
                         a.integer("n_averages", *WHOLE_NUMBERS["n_averages"]), rate,
                         a.text("quantity", "accelerance"), outputs, inputs,
                         a.number("decay_rate_per_s", 0.0), a.json("provenance", {}, dict))


def _check_names_are_channels(run: h5py.Group, outputs: tuple[str, ...], inputs: tuple[str, ...],
                              where: str) -> None:
    """The FRFs' output and input names must be channels of their run, each named once per side (a
    stored group naming another channel, or one twice, gave mode shapes at sensors the run lacks)."""
    table = run.get("channels") if isinstance(run.get("channels", getlink=True), h5py.HardLink) else None
    fields = getattr(getattr(table, "dtype", None), "names", None) or ()
    if not isinstance(table, h5py.Dataset) or "name" not in fields or table.ndim != 1:
        return   # the run's own check names what is wrong with its channel table
    channels = {nfc(v.decode(errors="replace") if isinstance(v, bytes) else str(v)) for v in table["name"]}
    for key, names in (("outputs", outputs), ("inputs", inputs)):
        for i, name in enumerate(names):
            if name in names[:i]:
                raise ModalError(f"{where}: attribute {key} names {name!r} twice")
            if nfc(name) not in channels:
                raise ModalError(f"{where}: attribute {key} names {name!r}, not a channel of the run "
                                 f"(channels: {', '.join(sorted(channels))})")


def _check_rate(run: h5py.Group, rate_hz: float, freq_hz: np.ndarray, where: str) -> None:
    """The group's sample rate is its run's, and its lines end at or below that rate's Nyquist frequency
    (a group from another run, or with its lines scaled, gave modes at frequencies the run cannot hold)."""
    from flexmodal.daq.run_schema import attribute_number

    own = attribute_number(run.attrs, "sample_rate_hz") if "sample_rate_hz" in run.attrs else None
    run_rate = np.nan if own is None else float(own)   # not a number: the run's own check names it
    if np.isfinite(rate_hz) and np.isfinite(run_rate) and not np.isclose(rate_hz, run_rate, rtol=1e-9):
        raise ModalError(f"{where}: attribute sample_rate_hz = {rate_hz:g} Hz is not its run's "
                         f"({run_rate:g} Hz)")
    rate = rate_hz if np.isfinite(rate_hz) else run_rate
    if np.isfinite(rate) and freq_hz[-1] > rate / 2 * (1 + 1e-9):
        raise ModalError(f"{where}: 'freq_hz' reaches {freq_hz[-1]:g} Hz, above the Nyquist frequency "
                         f"{rate / 2:g} Hz of the run's {rate:g} Hz sampling")


def _checked_arrays(data: dict[str, h5py.Dataset], where: str) -> tuple[np.ndarray, ...]:
    """freq_hz [n] finite and increasing, H [n_out, n_in, n] and coherence [n_out, n], all numeric (an
    HDF5 enum is not: daq.run_schema.numeric_dtype), H within the range of checked_io.data_range."""
    from flexmodal.daq.run_schema import dtype_words, numeric_dtype

    shapes = {k: d.shape for k, d in data.items()}
    kinds = {k: d.dtype.kind for k, d in data.items()}
    n = shapes["freq_hz"][0] if len(shapes["freq_hz"]) == 1 else -1
    if n < 1 or not numeric_dtype(data["freq_hz"].dtype):
        raise ModalError(f"{where}: 'freq_hz' must be a 1-D numeric dataset (shape {shapes['freq_hz']}, "
                         f"type {dtype_words(data['freq_hz'].dtype)})")
    if len(shapes["H"]) != 3 or shapes["H"][2] != n or kinds["H"] != "c" or 0 in shapes["H"]:
        raise ModalError(f"{where}: 'H' must be [outputs, inputs, {n} lines] of complex numbers (shape "
                         f"{shapes['H']}, type {data['H'].dtype})")
    if shapes["coherence"] != (shapes["H"][0], n) or not numeric_dtype(data["coherence"].dtype):
        raise ModalError(f"{where}: 'coherence' must be [{shapes['H'][0]} outputs, {n} lines] of numbers "
                         f"(shape {shapes['coherence']}, type {dtype_words(data['coherence'].dtype)})")
    try:
        freq_hz, H, coherence = (np.asarray(data[k][()], t) for k, t in
                                 (("freq_hz", float), ("H", complex), ("coherence", float)))
    except OSError as exc:  # a damaged chunk
        raise ModalError(f"{where}: cannot read ({one_line(exc)})") from None
    check_freq_axis(freq_hz, where, "'freq_hz'")
    check_coherence(coherence, where)
    fault = range_fault(np.where(np.isfinite(H), H, 0))   # NaN, inf: identify names them
    if fault:
        at, words = fault
        place = f" [{at[0]}, {at[1]}] at {freq_hz[at[2]]:g} Hz" if at else ""
        raise ModalError(f"{where}: 'H'{place} {words}")
    return freq_hz, H, coherence


def _whole(lo: int, hi: int) -> str:
    """What a whole-number attribute must be, in words for an error line."""
    return f"a whole number from {lo} to {hi}"


_JSON_WORDS = {dict: "object", list: "array"}   # JSON's own names of the types an attribute must hold


class _Attrs:
    """Typed getters over the attributes of a stored FRF group; ModalError names the attribute."""

    def __init__(self, attrs: h5py.AttributeManager, where: str) -> None:
        self.attrs, self.where = attrs, where

    def _get(self, key: str, default: object) -> object:
        if key in self.attrs:
            return self.attrs[key]
        if default is ...:
            raise ModalError(f"{self.where}: lacks the attribute {key!r}")
        return default

    def _bad(self, key: str, value: object, expected: str) -> ModalError:
        return ModalError(f"{self.where}: attribute {key} = {shown_value(value, 60)} is not {expected}")

    def text(self, key: str, default: object = ...) -> str:
        value = self._get(key, default)
        if isinstance(value, bytes):
            try:
                value = value.decode()
            except UnicodeDecodeError:
                raise self._bad(key, value, "UTF-8 text") from None
        if not isinstance(value, str):
            raise self._bad(key, value, "a text")
        return value

    def _number(self, key: str, expected: str) -> int | float:
        """The attribute as one HDF5 number (never an enum or bool: daq.run_schema.attribute_number)."""
        from flexmodal.daq.run_schema import attribute_number, stored_as

        self._get(key, ...)
        value = attribute_number(self.attrs, key)
        if value is None:
            raise self._bad(key, self.attrs[key], expected + stored_as(self.attrs, key))
        return value

    def integer(self, key: str, lo: int, hi: int) -> int:
        expected = _whole(lo, hi)
        value = self._number(key, expected)
        if not isinstance(value, int) or not lo <= value <= hi:
            raise self._bad(key, value, expected)
        return value

    def number(self, key: str, default: float, *, positive: bool = False) -> float:
        expected = f"a finite number {'> 0' if positive else '>= 0'}"
        if key not in self.attrs:
            return default
        value = self._number(key, expected)
        if not (np.isfinite(value) and (value > 0 if positive else value >= 0)):
            raise self._bad(key, value, expected)
        return float(value)

    def json(self, key: str, default: object, kind: type) -> object:
        if key not in self.attrs:
            return default
        doc = loads_json(self.text(key), f"{self.where}: attribute {key}", ModalError)
        if not isinstance(doc, kind):
            raise self._bad(key, doc, f"a JSON {_JSON_WORDS.get(kind, kind.__name__)}")
        return doc

    def names(self, key: str, count: int) -> tuple[str, ...]:
        names = self.json(key, [], list)
        if names and (len(names) != count or not all(isinstance(n, str) for n in names)):
            raise self._bad(key, names, f"a JSON list of {count} channel names")
        return tuple(names)
