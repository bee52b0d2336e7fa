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

from flexmodal.modal.errors import ModalError
from flexmodal.modal.frf import FrfResult
from flexmodal.valid_output import signals_deferred
from flexmodal.valid_text import one_line

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
    need = H.nbytes + freq_hz.nbytes + coherence.nbytes + METADATA_BYTES
    target = Path(os.path.realpath(path))
    free = shutil.disk_usage(target.parent if target.parent.is_dir() else Path(".")).free
    if free < need:
        raise ModalError(f"{where}: no space left on the device for the FRFs ({need / 1e6:.2f} MB needed, "
                         f"{free / 1e6:.2f} MB free); the file is unchanged")
    created = not target.exists()
    try:
        f = h5py.File(path, "a", libver="latest")
    except OSError as exc:
        raise ModalError(f"{path}: cannot open for writing FRFs ({one_line(exc)})") from None
    try:
        with f, signals_deferred():  # Ctrl-C waits for the group to be whole (milliseconds)
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
    """The stored FRFs of a run, or None when the run has no ``frf`` group."""
    from flexmodal.daq.store import open_read  # fails at once on a truncated file (SWMR would wait)

    with open_read(path) as f:
        key = f"runs/{run_id}/frf"
        if key not in f:
            return None
        g = f[key]
        a = dict(g.attrs)

        def text(v) -> str:
            return v.decode() if isinstance(v, bytes) else str(v)

        try:
            return FrfResult(g["freq_hz"][()], g["H"][()], g["coherence"][()], text(a["estimator"]),
                             text(a["window"]), int(a["nfft"]), int(a["n_averages"]),
                             float(a.get("sample_rate_hz", np.nan)), text(a.get("quantity", "accelerance")),
                             tuple(json.loads(text(a.get("outputs", "[]")))),
                             tuple(json.loads(text(a.get("inputs", "[]")))),
                             float(a.get("decay_rate_per_s", 0.0)),
                             json.loads(text(a.get("provenance", "{}"))))
        except KeyError as exc:
            raise ModalError(f"{path}: run {run_id!r}: frf group lacks {exc.args[0]!r}") from None
