"""FRFs stored with their run: ``/runs/<run_id>/frf/`` (docs/hdf5-format.md) holds ``H`` [n_out, n_in, n_freq]
complex, ``freq_hz`` [n_freq], ``coherence`` [n_out, n_freq] and the attributes ``estimator``,
``window``, ``nfft``, ``n_averages`` plus ``sample_rate_hz``, ``quantity``, ``outputs`` and ``inputs``
(JSON lists of channel names), ``decay_rate_per_s`` (exponential window) and ``provenance`` (JSON:
software, time, processing details such as accepted and rejected hits).  Runs are read with
``daq.store.read_run``."""

from __future__ import annotations

import json
from datetime import UTC, datetime
from pathlib import Path

import h5py
import numpy as np

from flexmodal.modal.errors import ModalError
from flexmodal.modal.frf import FrfResult
from flexmodal.valid_output import signals_deferred


def write_frf(path: str | Path, run_id: str, result: FrfResult) -> None:
    """Write (or replace) ``/runs/<run_id>/frf`` in the HDF5 file ``path``."""
    try:
        f = h5py.File(path, "a", libver="latest")
    except OSError as exc:
        raise ModalError(f"{path}: cannot open for writing FRFs ({exc})") from None
    with f, signals_deferred():  # Ctrl-C waits for the group to be whole (milliseconds)
        g = f.require_group(f"runs/{run_id}")
        if "frf" in g:
            del g["frf"]
        out = g.create_group("frf")
        out.create_dataset("H", data=np.asarray(result.H, complex))
        out.create_dataset("freq_hz", data=np.asarray(result.freq_hz, float))
        out.create_dataset("coherence", data=np.asarray(result.coherence, float))
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
    from flexmodal.daq.h5file import open_read  # fails at once on a truncated file (SWMR would wait)

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
