"""flexmodal's public Python API: the functions the command line is a thin shell over.

Read a run, compute FRFs, identify modes, predict them with a model, compare, diagnose the gap, and get
matplotlib figures back instead of files.  Every function takes paths or the objects the previous step
returned, raises the package's own error type (``DaqError``, ``ModalError``, ``ModelError``,
``CompareError``, ``ReportError``: one line naming the file, field or value) on bad input, and imports
its heavy dependencies only when called, so ``import flexmodal`` stays cheap.  Worked example:
docs/python-api.md.  Units: frequencies Hz, damping ratios as fractions, poses in degrees and kg.
"""

from __future__ import annotations

import html
import math
import numbers
import os
import re
from collections.abc import Callable, Iterable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

# light at import: the registries whose names the command line offers, the fault options of a simulator,
# and the error family (one type per package), so the shell needs nothing past this module
from flexmodal.checked_io import options as opt
from flexmodal.checked_io.errors import FlexmodalError
from flexmodal.checked_io.plural import counted
from flexmodal.compare.errors import CompareError
from flexmodal.daq.errors import DaqError
from flexmodal.daq.faults import Faults, fault_flag
from flexmodal.fixtures.errors import FixtureError
from flexmodal.fixtures.simulators import SIMULATORS
from flexmodal.modal.errors import ModalError
from flexmodal.modal.registry import ESTIMATORS, METHODS
from flexmodal.models.errors import ModelError
from flexmodal.models.registry import MODELS
from flexmodal.models.rig_schema import MAX_ELEMENTS
from flexmodal.reports.errors import ReportError

if TYPE_CHECKING:
    from matplotlib.figure import Figure

    from flexmodal.compare.result import Diagnosis
    from flexmodal.compare.tables import Comparison
    from flexmodal.contract.table import ModalTable
    from flexmodal.daq.acquire import Summary, WriteFailed
    from flexmodal.daq.session import Session
    from flexmodal.daq.store import Run
    from flexmodal.modal.frf import FrfResult
    from flexmodal.modal.identify import Modes, Thresholds
    from flexmodal.modal.skipped import RunsFailed
    from flexmodal.models.rig import Rig

__all__ = [
    "CompareError", "DaqError", "ESTIMATORS", "Faults", "FixtureError", "FlexmodalError", "FrfResult",
    "Identification", "MAX_ELEMENTS", "METHODS", "MODELS", "ModalError", "ModelError", "ReportError",
    "RunsFailed", "SIMULATORS", "SelfCheck", "Thresholds", "WriteFailed", "acquire", "animate_mode",
    "compare_modes", "compute_frf", "compute_frfs", "demo", "diagnose", "fault_flag", "format_comparison",
    "format_diagnosis", "frf_from_arrays", "identify", "list_runs", "load_rig", "plot_comparison",
    "plot_frf", "plot_gap", "plot_mode_shapes", "plot_stabilisation", "predict", "read_diagnosis",
    "read_poses", "read_run", "read_table", "report", "report_pdf", "selftest", "serve_simulator", "track",
    "write_comparison", "write_diagnosis",
]


def __getattr__(name: str):
    """Types exported here, loaded on first use (``fm.FrfResult``, ``fm.Thresholds``,
    ``fm.WriteFailed``, ``fm.RunsFailed``) so importing the API stays cheap."""
    if name == "FrfResult":
        from flexmodal.modal.frf import FrfResult

        return FrfResult
    if name == "Thresholds":
        from flexmodal.modal.identify import Thresholds

        return Thresholds
    if name == "RunsFailed":
        from flexmodal.modal.skipped import RunsFailed

        return RunsFailed
    if name == "WriteFailed":
        from flexmodal.daq.acquire import WriteFailed

        return WriteFailed
    raise AttributeError(f"module 'flexmodal.api' has no attribute {name!r}")

SHAPE_CONFIGS = 2              # configurations whose mode shapes a report draws on the arm (first, last)

PathLike = str | Path


# -- runs ------------------------------------------------------------------------------------------

def _path_arg(value: object, where: str) -> None:
    """TypeError naming ``where`` unless ``value`` is a file path (str or os.PathLike): bytes or a
    number gave pathlib's or h5py's own TypeError, which names no argument."""
    if not isinstance(value, str | os.PathLike):
        raise TypeError(f"{where} must be a file path (str or Path), got {type(value).__name__} "
                        f"{value!r:.60}")


def list_runs(path: PathLike) -> list[str]:
    """Run ids stored in an HDF5 run file (docs/hdf5-format.md), in natural order (theta30 before theta120).

    Parameters
    ----------
    path : str or Path
        The run file.

    Returns
    -------
    list of str
        The run ids.

    Examples
    --------
    >>> import tempfile
    >>> import flexmodal as fm
    >>> from flexmodal.fixtures.examples import impact_run
    >>> path = impact_run(tempfile.mkdtemp())    # a simulated impact test of the demo arm
    >>> fm.list_runs(path)
    ['theta30']
    """
    _path_arg(path, "list_runs: path")
    from flexmodal.daq.store import list_runs as _list

    return _list(path)


def read_run(path: PathLike, run_id: str | None = None) -> Run:
    """One stored run read into memory.

    Parameters
    ----------
    path : str or Path
        The HDF5 run file (docs/hdf5-format.md).
    run_id : str, optional
        The run to read; may be left out when the file holds one run.

    Returns
    -------
    daq.store.Run
        ``samples`` [n_samples, n_channels] in physical units, ``channels``, ``events``, ``pose``
        (degrees, kg), ``sample_rate_hz`` [Hz].

    Raises
    ------
    DaqError
        The file holds several runs and none is named, or the run is not a valid one.

    Examples
    --------
    >>> import tempfile
    >>> import flexmodal as fm
    >>> from flexmodal.fixtures.examples import impact_run
    >>> path = impact_run(tempfile.mkdtemp())    # a simulated impact test of the demo arm
    >>> run = fm.read_run(path)
    >>> run.samples.shape, [c.name for c in run.channels], run.pose
    ((4096, 6), ['F', 'a1', 'a2', 'a3', 'a4', 'a5'], {'theta_deg': 30.0})
    """
    _path_arg(path, "read_run: path")
    from flexmodal.daq.errors import DaqError
    from flexmodal.daq.store import read_run as _read
    if run_id is not None and not isinstance(run_id, str):
        raise TypeError(f"read_run: run_id must be a run id (str) or None, got {run_id!r}")

    if run_id is None:
        ids = list_runs(path)
        if len(ids) != 1:
            raise DaqError(f"{path}: holds {len(ids)} runs ({', '.join(ids) or 'none'}); name one")
        run_id = ids[0]
    return _read(path, run_id)


def acquire(session: PathLike | Session, out: PathLike, *, duration_s: float | None = None,
            run_id: str | None = None, recover: bool = False, quiet: bool = True) -> Summary:
    """Record the devices of a session config into a run of an HDF5 file.

    Parameters
    ----------
    session : str, Path or daq.session.Session
        The session config (TOML, docs/acquisition.md); a ``[simulator]`` table starts the simulated
        device it names (serial over a pty, CAN over slcan, Modbus TCP on 127.0.0.1).
    out : str or Path
        The HDF5 run file to append the run to (docs/hdf5-format.md).
    duration_s : float, optional
        Stop after this many seconds of samples [s] (default: until Ctrl-C or the session's own end).
    run_id : str, optional
        Id of the new run (default: from the start time).
    recover : bool
        First clear the open-for-writing flags a killed writer left in ``out``.
    quiet : bool
        No live display on stderr.

    Returns
    -------
    daq.acquire.Summary
        What was stored: ``run_id``, ``n_samples``, ``n_channels``, ``sample_rate_hz`` [Hz], ``events``;
        ``signal``/``error`` when it ended early, ``exit_code`` the command's.

    Raises
    ------
    DaqError
        Bad session, run id or output file (one line naming it).
    WriteFailed
        The run file could not be written (disk full, I/O error): its open-for-writing flags are
        cleared, it holds the last flush.  HDF5 is left unusable for that file in this process: leave
        it without closing (``os._exit``), as the ``acquire`` command does.

    Examples
    --------
    >>> import tempfile
    >>> import flexmodal as fm
    >>> out = tempfile.mkdtemp() + "/run.h5"
    >>> summary = fm.acquire("examples/sessions/serial-sim.toml", out, duration_s=1.0)
    >>> summary.n_samples, summary.n_channels, summary.sample_rate_hz
    (2048, 7, 2048.0)
    """
    from flexmodal.checked_io.output import hdf5_output
    from flexmodal.daq.acquire import WriteFailed
    from flexmodal.daq.acquire import acquire as _acquire
    from flexmodal.daq.errors import DaqError
    from flexmodal.daq.session import load_session

    if isinstance(session, str | Path):
        session = load_session(session)
    hdf5_output(out, DaqError, "run file (--out)")
    if run_id is not None:
        from flexmodal.daq.run_schema import check_run_id

        check_run_id(run_id, "--run-id")
    if duration_s is not None and (isinstance(duration_s, bool) or not isinstance(duration_s, numbers.Real)
                                   or not 0 < duration_s <= 1e9):  # NaN fails the comparison too
        raise DaqError(f"--duration {duration_s!r}: must be a number of seconds > 0 and <= 1e9")
    if recover and Path(out).exists():
        from flexmodal.daq.h5file import recover as _recover

        _recover(out)
    try:
        return _acquire(session, out, duration_s=duration_s, quiet=quiet, run_id=run_id)
    except WriteFailed:
        from flexmodal.daq.h5file import recover as _recover

        _recover(out)   # clear the open-for-writing flags (in place) so plain h5py opens the file
        raise


# -- FRFs ------------------------------------------------------------------------------------------

def compute_frf(run: Run | PathLike, *, estimator: str = "H1", nfft: int | None = None,
                window: str | None = None, overlap: float = 0.5, averaging: str = "linear",
                store: bool = False) -> FrfResult:
    """FRFs and coherence of one run (docs/modal.md: estimators, windows, impact processing).

    Parameters
    ----------
    run : daq.store.Run, str or Path
        A run read by :func:`read_run`, or the path of a file holding one run.
    estimator : str
        A registered FRF estimator (``H1``, ``H2``, ``Hv``; modal.registry.ESTIMATORS).
    nfft : int, optional
        Segment length [samples] of random and sweep runs (default: a power of two <= 8192 giving at
        least 8 segments); impact runs use one record per hit.
    window : str, optional
        ``rect``, ``hann`` (default) or ``flattop`` for random runs; ``force:W,exponential:E``
        (fractions of the record) for impact runs.
    overlap : float
        Segment overlap, a fraction in [0, 1).
    averaging : {"linear", "exponential"}
        Averaging of the impact hits.
    store : bool
        Also write the result under ``/runs/<id>/frf`` of the run's file.

    Returns
    -------
    modal.frf.FrfResult
        ``H`` [n_out, n_in, n_freq] in the response unit per force unit (e.g. (m/s²)/N), ``coherence``
        [n_out, n_freq] [-], ``freq_hz`` [Hz], ``outputs``.

    References
    ----------
    J. S. Bendat and A. G. Piersol, *Random Data*, 4th ed., Wiley, 2010, ch. 9 (H1, H2).

    Examples
    --------
    >>> import tempfile
    >>> import flexmodal as fm
    >>> from flexmodal.fixtures.examples import impact_run
    >>> path = impact_run(tempfile.mkdtemp())    # a simulated impact test of the demo arm
    >>> frf = fm.compute_frf(path)
    >>> frf.H.shape, frf.estimator, frf.outputs
    ((5, 1, 983), 'H1', ('a1', 'a2', 'a3', 'a4', 'a5'))
    """
    from flexmodal.modal.compute import compute_frf as _compute

    _check_window(window)
    if isinstance(run, str | Path):
        run = read_run(run)
    if store:
        from flexmodal.checked_io.output import hdf5_output
        from flexmodal.modal.errors import ModalError

        hdf5_output(run.path, ModalError, "run file (store=True)")
    result = _compute(run, estimator=estimator, nfft=nfft, window=window, overlap=overlap,
                      averaging=averaging)
    if store:
        from flexmodal.modal.runs_io import write_frf

        write_frf(run.path, run.run_id, result)
    return result


def _numbers_of(values, complex_ok: bool):
    """An object array (a pandas object column, Python numbers, Decimals) as the numeric array its
    items make: complex only when an item is complex, so a real ``H`` held as objects stays real (and
    is refused for holding no phase, as a float64 one is)."""
    import numpy as np

    inferred = np.array(values.tolist())
    if inferred.dtype.kind == "O":   # Decimal, Fraction, None: float unless an item is complex
        is_complex = complex_ok and any(isinstance(x, complex | np.complexfloating) for x in inferred.flat)
        inferred = inferred.astype(complex if is_complex else float)
    return inferred


def frf_from_arrays(freq_hz, H, *, coherence=None, quantity: str = "accelerance",
                    outputs: Sequence[str] = (), inputs: Sequence[str] = (),
                    decay_rate_per_s: float = 0.0) -> FrfResult:
    """FRFs you already have (another tool's, a UFF file's, a simulation's) as the :class:`FrfResult`
    every flexmodal function takes (:func:`identify`, :func:`plot_frf`, :func:`plot_stabilisation`).

    Parameters
    ----------
    freq_hz : array_like [n_freq]
        Frequency lines [Hz], finite, increasing, non-negative.
    H : array_like [n_out, n_in, n_freq], [n_out, n_freq] or [n_freq]
        Complex FRFs in ``quantity`` per input unit (one input when 2-D, one output too when 1-D).
    coherence : array_like [n_out, n_freq], optional
        Coherence [-] of each output (default: none).
    quantity : {"accelerance", "mobility", "receptance"}
        What H is: (m/s²)/N, (m/s)/N or m/N.
    outputs, inputs : sequence of str
        Channel names (default ``out 1``.. and ``in 1``..).
    decay_rate_per_s : float
        Decay rate [1/s] of an exponential window applied to the records (0: none), removed from the
        identified damping.

    Returns
    -------
    FrfResult
        ``H`` [n_out, n_in, n_freq] complex in ``quantity`` per input unit, ``coherence``
        [n_out, n_freq] [-] (None when not given), ``freq_hz`` [Hz], ``outputs``, ``inputs``.

    Examples
    --------
    >>> import numpy as np
    >>> import flexmodal as fm
    >>> f = np.linspace(0.0, 100.0, 201)
    >>> s, w0 = 2j * np.pi * f, 2 * np.pi * 40.0                    # one mode at 40 Hz, 2 % damping
    >>> H = s**2 / (s**2 + 2 * 0.02 * w0 * s + w0**2)
    >>> frf = fm.frf_from_arrays(f, H, outputs=["tip"])
    >>> frf.H.shape, frf.outputs, frf.inputs
    ((1, 1, 201), ('tip',), ('in 1',))
    """
    import numpy as np

    from flexmodal.modal.errors import ModalError
    from flexmodal.modal.frf import QUANTITIES, FrfResult, check_coherence, check_freq_axis

    arrays = {}
    for name, value in (("freq_hz", freq_hz), ("H", H), ("coherence", coherence)):
        if value is None and name == "coherence":
            continue
        try:   # a ragged list of lists, or objects: numpy's ValueError named here
            if value is None or isinstance(value, str | bytes | Mapping):
                raise TypeError
            arrays[name] = np.asarray(value)
            if arrays[name].dtype.kind == "O":   # numbers held as objects: their own kind decides
                arrays[name] = _numbers_of(arrays[name], complex_ok=name == "H")
            if arrays[name].dtype.kind not in "biufc":
                raise TypeError
        except (TypeError, ValueError):
            raise TypeError(f"frf_from_arrays: {name} must be an array of numbers, got "
                            f"{type(value).__name__} {value!r:.60}") from None
    f = arrays["freq_hz"].astype(float)
    if not np.iscomplexobj(arrays["H"]):
        raise ModalError(f"frf_from_arrays: H of type {arrays['H'].dtype} holds no phase: FRFs are complex "
                         "(H = X / F)")
    h = arrays["H"].astype(complex)
    h = h[None, None, :] if h.ndim == 1 else h[:, None, :] if h.ndim == 2 else h
    if f.ndim != 1 or f.size < 2:
        raise ModalError(f"frf_from_arrays: freq_hz of shape {f.shape} must be one axis of at least 2 "
                         "lines [Hz]")
    check_freq_axis(f, "frf_from_arrays")
    if h.ndim != 3 or h.shape[-1] != f.size:
        raise ModalError(f"frf_from_arrays: H {np.shape(H)} must be [n_out, n_in, n_freq], [n_out, n_freq] "
                         f"with n_freq = {f.size}")
    if quantity not in QUANTITIES:
        raise ModalError(f"frf_from_arrays: quantity {quantity!r}: use one of {', '.join(QUANTITIES)}")
    coh = None if coherence is None else arrays["coherence"].astype(float)
    if coh is not None and coh.shape != (h.shape[0], f.size):
        raise ModalError(f"frf_from_arrays: coherence {coh.shape} must be [n_out, n_freq] = "
                         f"{(h.shape[0], f.size)}")
    if coh is not None:
        check_coherence(coh, "frf_from_arrays")
    outs = tuple(outputs) or tuple(f"out {k + 1}" for k in range(h.shape[0]))
    ins = tuple(inputs) or tuple(f"in {k + 1}" for k in range(h.shape[1]))
    if len(outs) != h.shape[0] or len(ins) != h.shape[1]:
        raise ModalError(f"frf_from_arrays: {len(outs)} output and {len(ins)} input names for H {h.shape}")
    decay = opt.given(decay_rate_per_s, opt.nonnegative, "frf_from_arrays: decay_rate_per_s", ModalError)
    return FrfResult(f, h, coh, "given", "", 2 * (f.size - 1), 0, float("nan"), quantity, outs, ins, decay,
                     {"source": "frf_from_arrays"})


def compute_frfs(runs: Sequence[PathLike | tuple[PathLike, str]], *, estimator: str = "H1",
                 nfft: int | None = None, window: str | None = None, overlap: float = 0.5,
                 averaging: str = "linear", workers: int | None = 0, scheduler: str | None = None,
                 out: PathLike | None = None, quiet: bool = True) -> list[tuple[str, str]]:
    """Batch FRFs of stored runs, written back into each file or into ``out``.

    Parameters
    ----------
    runs : sequence of str, Path or (path, run id)
        A file means all its runs, ``FILE::RUN_ID`` or ``(file, id)`` one run.
    estimator : str
        A registered FRF estimator (``H1``, ``H2``, ``Hv``), as :func:`compute_frf`.
    nfft : int, optional
        Segment length [samples] of random and sweep runs, as :func:`compute_frf`.
    window : str, optional
        Window of random runs, or ``force:W,exponential:E`` (fractions of the record) of impact runs,
        as :func:`compute_frf`.
    overlap : float
        Segment overlap, a fraction in [0, 1).
    averaging : {"linear", "exponential"}
        Averaging of the impact hits.
    workers : int or None
        0 (the default) computes the runs here one after the other; None chooses as the ``frf``
        command does (here, with a helper process forked from this one once the measured cost of
        the runs done predicts that it pays and a CPU is idle, see ``modal.batch.run_batch``); N
        forces a pool of N processes.
    scheduler : str, optional
        Send the runs to the dask.distributed scheduler at this address (the extra
        ``flexmodal[cluster]``).
    out : str or Path, optional
        Write the FRFs into this file instead of the inputs.
    quiet : bool
        No progress bar on stderr.

    Returns
    -------
    list of (str, str)
        The (file written, run id) pairs, in input order.

    Raises
    ------
    RunsFailed
        Some runs (or files) were bad: every good run was computed and written first; ``.written``
        holds their (file, run id) pairs, ``.failed`` each bad run's name and error (one bad run and
        nothing else: its own ModalError or DaqError).

    Notes
    -----
    Pool workers start from a fork server that imports the calling script again as ``__mp_main__`` (as
    ``multiprocessing`` does), so a script passing ``workers`` N keeps its own work under
    ``if __name__ == "__main__":``.  Estimators registered in this process
    (``modal.registry.register_estimator``) reach pool workers only if they register them too; the
    helpers of ``workers`` None are forked from this process and have them.  A program running
    threads of its own gets no helpers (a lock held by one of them at a fork would stay held).

    References
    ----------
    J. S. Bendat and A. G. Piersol, *Random Data*, 4th ed., Wiley, 2010, ch. 9 (H1, H2).

    Examples
    --------
    >>> import tempfile
    >>> import flexmodal as fm
    >>> from flexmodal.fixtures.examples import impact_run
    >>> path = impact_run(tempfile.mkdtemp())    # a simulated impact test of the demo arm
    >>> [run_id for _, run_id in fm.compute_frfs([path])]
    ['theta30']
    >>> from flexmodal.modal.runs_io import read_frf
    >>> read_frf(path, "theta30").H.shape      # stored under /runs/theta30/frf
    (5, 1, 983)
    """
    from flexmodal.modal.batch import frf_batch

    _check_window(window)
    if workers is not None and (isinstance(workers, bool) or not isinstance(workers, numbers.Integral)
                                or workers < 0):
        raise TypeError(f"workers must be None or a whole number >= 0 (got {workers!r})")
    if workers:
        _check_workers(int(workers))
    if out is not None:
        from flexmodal.checked_io.output import hdf5_output
        from flexmodal.modal.errors import ModalError

        hdf5_output(out, ModalError, "FRF file (--out)")
    options = {"estimator": estimator, "nfft": nfft, "window": window, "overlap": overlap,
               "averaging": averaging}
    return frf_batch(runs, options, workers=workers, scheduler=scheduler, out=out, quiet=quiet)


# -- modes -----------------------------------------------------------------------------------------

@dataclass(frozen=True)
class Identification:
    """Identified modes: the modal table and, per configuration, the modes and their outputs.

    Parameters
    ----------
    table : contract.table.ModalTable
        The modal table (docs/formats.md, modal table CSV): ``freq_hz`` [Hz], damping ratio [-],
        uncertainties, shapes at the outputs.
    modes : mapping of str to modal.identify.Modes
        Per configuration, the identification's full result (poles, residues, stabilisation, warnings).
    outputs : mapping of str to tuple of str
        Per configuration, the channels the shapes are given at.
    """

    table: ModalTable
    modes: Mapping[str, Modes]
    outputs: Mapping[str, tuple[str, ...]]

    @property
    def warnings(self) -> list[str]:
        """``config: message`` for every warning met on the way."""
        return [f"{c}: {w}" for c, m in self.modes.items() for w in m.warnings]

    def warning_summary(self) -> list[str]:
        """One line per kind of warning, not one per configuration (:func:`_summarise_warnings`)."""
        return _summarise_warnings([(c, w) for c, m in self.modes.items() for w in m.warnings])

    def to_frame(self):
        """The modal table as a pandas DataFrame (:meth:`ModalTable.to_frame`)."""
        return self.table.to_frame()

    def __repr__(self) -> str:
        n = len(self.warnings)
        return (f"Identification({len(self.modes)} configurations, {len(self.table.frame)} modes, "
                f"{n} warning{'s' if n != 1 else ''}; .table, .modes[config], .warnings, "
                f".warning_summary())")

    def _repr_html_(self) -> str:
        warned = "".join(f"<li>{html.escape(w)}</li>" for w in self.warning_summary())
        return self.table._repr_html_() + (f"<p>Warnings (one line per kind; every one in "
                                           f"<code>.warnings</code>):</p><ul>{warned}</ul>" if warned else "")


    def write(self, out: PathLike, *, uff: PathLike | None = None) -> Path:
        """Write the modal table CSV ``out`` (docs/formats.md) and, beside it, ``MODES.synthesis.csv``
        (the FRAC of every measured and synthesised FRF) and, for pLSCF, ``MODES.diagram.npz`` (the
        stabilisation diagrams ``identify --poles`` re-picks from, modal.diagrams), all or none
        (SIGINT/SIGTERM held); with ``uff``, also the modes of the first configuration as UFF dataset
        55.  Returns ``out``.

        Examples
        --------
        >>> import tempfile
        >>> from pathlib import Path
        >>> import flexmodal as fm
        >>> from flexmodal.fixtures.examples import impact_run
        >>> folder = Path(tempfile.mkdtemp())
        >>> ident = fm.identify(impact_run(folder), fmax=400.0)
        >>> ident.write(folder / "modes.csv", uff=folder / "modes.uff").name
        'modes.csv'
        >>> sorted(p.name for p in folder.iterdir() if p.suffix != ".h5")
        ['modes.csv', 'modes.diagram.npz', 'modes.synthesis.csv', 'modes.uff']
        """
        from flexmodal.checked_io.output import atomic_group, output_file, sidecar_file, signals_deferred
        from flexmodal.modal.diagrams import StoredDiagram, check_replaceable, diagram_path, write_diagrams
        from flexmodal.modal.errors import ModalError
        from flexmodal.modal.identify import SYNTHESIS_HEADER, synthesis_path, write_synthesis_csv

        output_file(out, ModalError, "modal table (--out)", inputs=())  # identify checked the run/UFF
        output_file(synthesis_path(out), ModalError, "FRF synthesis table (next to --out)", inputs=(out, uff))
        sidecar_file(synthesis_path(out), ModalError, "FRF synthesis table", SYNTHESIS_HEADER)
        diagrams = [StoredDiagram(m.diagram_key, c, m.stabilisation, m.order_note)
                    for c, m in self.modes.items() if m.stabilisation is not None and m.diagram_key]
        if diagrams:
            output_file(diagram_path(out), ModalError, "stabilisation diagrams (next to --out)",
                        inputs=(out, uff))
            check_replaceable(diagram_path(out))
        if uff is not None:
            output_file(uff, ModalError, "UFF file (--uff)", inputs=(out,))
        modes_by_config = {c: (m, self.outputs[c]) for c, m in self.modes.items()}
        with signals_deferred(), atomic_group():   # the table, its synthesis, diagrams, UFF: all, or none
            self.table.to_csv(out)
            write_synthesis_csv(out, modes_by_config)
            if diagrams:
                write_diagrams(diagram_path(out), diagrams)
            if uff is not None:
                from flexmodal.modal.uff import write_modes

                modes, outputs = next(iter(modes_by_config.values()))
                write_modes(uff, modes.freq_hz, modes.damping_ratio, modes.shapes, outputs)
        return Path(out)


def _summarise_warnings(found: Sequence[tuple[str, str]], named: int = 4) -> list[str]:
    """One line per kind of warning among ``(where, message)`` pairs, in order of first appearance.

    Two messages are of one kind when they differ only in their numbers (frequencies, counts); the line
    quotes the first and names where it was met (up to ``named`` places, then how many more), so ten
    runs with the same advice give one line instead of ten.

    Examples
    --------
    A list or range of numbers counts as one number and the singular as the plural, so "1 of 3 modes
    (29.5 Hz) has 2.6 lines in its" is of the kind of "2 of 3 modes (28.9, 100 Hz) have 1.7-2.2 lines
    in their".

    >>> for line in _summarise_warnings([("run1", "2 of 3 modes (28.9, 100 Hz) have 1.7-2.2 lines in their"),
    ...                                 ("run2", "2 of 3 modes (37.5, 72.1 Hz) have 1.8-3 lines in their"),
    ...                                 ("run2", "merged the poles at 29.01 and 29.04 Hz"),
    ...                                 ("run3", "1 of 3 modes (29.5 Hz) has 2.6 lines in its")]):
    ...     print(line)
    3 configurations (run1, run2, run3), e.g. run1: 2 of 3 modes (28.9, 100 Hz) have 1.7-2.2 lines in their
    run2: merged the poles at 29.01 and 29.04 Hz
    """
    import re

    kinds: dict[str, list[tuple[str, str]]] = {}
    for where, message in found:
        key = re.sub(r"\d+(?:\.\d+)?(?:e[-+]?\d+)?", "#", message)
        key = re.sub(r"#(?:(?:, | and |-|\.\.)#)*(?:, \.\.\.)?", "#", key)   # lists and ranges of numbers
        key = re.sub(r"\b(?:modes?|has|have|its|their)\b", "_", key)        # singular or plural
        kinds.setdefault(key, []).append((where, message))
    lines = []
    for same in kinds.values():
        places = list(dict.fromkeys(where for where, _ in same))
        first_where, first = same[0]
        if len(places) == 1:
            lines.append(f"{first_where}: {first}" + (f" ({len(same)} times)" if len(same) > 1 else ""))
            continue
        more = f" and {len(places) - named} more" if len(places) > named else ""
        listed = ", ".join(places[:named]) + more
        lines.append(f"{len(places)} configurations ({listed}), e.g. {first_where}: {first}")
    return lines


WORKER_BYTES = 250 << 20   # memory of one pool worker: its interpreter, numpy/scipy/h5py and a run's blocks
WORKERS_PER_CPU = 4        # processes beyond this per usable CPU only wait for one (the FFTs are CPU-bound)


def _check_window(window: object) -> None:
    """TypeError unless ``window`` is None or a text (``frf --window``): a number reached the window
    parser as an AttributeError ('int' object has no attribute 'strip')."""
    if window is not None and not isinstance(window, str):
        raise TypeError(f"window must be a window text such as 'hann' or 'force:0.05,exponential:0.01', "
                        f"got {window!r}")


def _check_workers(workers: int) -> None:
    """ModalError when ``workers`` pool processes exceed what this machine can run: more than
    :data:`WORKERS_PER_CPU` per usable CPU, or more than the available memory holds at
    :data:`WORKER_BYTES` each (256 workers on 2 CPUs started 256 interpreters, 20+ GB)."""
    from flexmodal.checked_io.text import available_memory_bytes
    from flexmodal.modal.errors import ModalError
    from flexmodal.modal.spectra import usable_cpus

    cpus, room = usable_cpus(), available_memory_bytes()
    most = max(1, min(WORKERS_PER_CPU * cpus, room // WORKER_BYTES))
    if workers > most:
        raise ModalError(f"--workers {workers}: more worker processes than this machine can run "
                         f"(at most {most}: {cpus} usable CPUs, {room / 2**30:.1f} GiB of memory available, "
                         f"about {WORKER_BYTES >> 20} MiB per worker)")


def identify(source: PathLike | FrfResult, *, method: str | None = None, fmin: float | None = None,
             fmax: float | None = None, max_order: int | None = None, run_id: str | None = None,
             config: str | None = None, pose: Mapping[str, float] | None = None,
             poles_hz: Sequence[float] | None = None, thresholds: Thresholds | None = None,
             decay_rate_per_s: float | None = None, references: Sequence[str] | None = None,
             out: PathLike | None = None, uff: PathLike | None = None,
             from_diagram: bool = False, quiet: bool = True) -> Identification:
    """Natural frequencies, damping ratios and mode shapes (docs/modal.md, docs/oma.md).

    Parameters
    ----------
    source : str, Path or FrfResult
        An HDF5 run file (each run one configuration; its stored FRFs, else computed), a UFF file
        (dataset 58 FRFs, or time histories with a force reference), or FRFs in memory
        (:func:`compute_frf`, :func:`frf_from_arrays`; then named ``config`` at ``pose``).
    method : str, optional
        A registered identification method (modal.registry.METHODS): ``lscf`` (pLSCF + stabilisation
        + LSFD), ``peak`` (CMIF peaks, half-power damping), output-only ``ssi`` (SSI-cov) or ``fdd``.
        Default: the data decide, ``lscf`` where a force channel exists, else ``ssi``.
    fmin, fmax : float, optional
        Band edges [Hz] (default: the first line above 0 Hz; Nyquist, or the last line before a top
        stretch where the FRFs' coherence stays below 0.9: modal.identify.coherent_top); ``fmin`` <
        ``fmax``.  ``Modes.band_note`` says which band was fitted and why.
    max_order : int, optional
        Cap of the pLSCF model order (default: it adapts to the data); ssi: highest model order.
    run_id : str, optional
        Only this run of an HDF5 file.
    config : str, optional
        Configuration name of FRFs given in memory (default ``run``; a file's are its run ids).
    pose : mapping, optional
        Their pose {variable: value} (degrees, kg; a file's runs store their own).
    poles_hz : sequence of float, optional
        Pick the stable poles nearest these frequencies [Hz] (exactly these modes, no automatic
        selection).  With ``out``, they are picked from the stabilisation diagram an earlier
        identification stored beside it (``MODES.diagram.npz``) when that diagram was computed from the
        same FRFs and options: the stabilisation runs once, the poles are picked many times.
    thresholds : modal.identify.Thresholds, optional
        Limits of the automatic selection (``need_min`` F statistic [-], ``mpc_min`` [0, 1]).
    decay_rate_per_s : float, optional
        Decay rate [1/s] of an exponential window the FRFs were measured with, its added damping
        removed (default: the rate the FRFs record).
    references : sequence of str, optional
        ssi/fdd: reference output channels (default all outputs).
    out : str or Path, optional
        Also write the modal table CSV here and ``MODES.synthesis.csv`` beside it
        (:meth:`Identification.write`); the outputs are checked before any work.
    uff : str or Path, optional
        With ``out``: also the modes of the first configuration as UFF dataset 55.
    from_diagram : bool
        With ``poles_hz``: pick only from the stored diagram beside ``out`` (ModalError when it is
        missing or was computed from other FRFs or options) instead of falling back to a new
        stabilisation.
    quiet : bool
        No progress bar on stderr (an HDF5 file of several runs, on a terminal).

    Returns
    -------
    Identification
        ``table`` (modal table: ``freq_hz`` [Hz], ``damping_ratio`` [-], ``shape.<output>``, ``mpc``,
        ``mpd_deg``, ``synthesis_corr``), ``modes[config]`` and ``warnings``.  Output-only shapes
        are unscaled (unit largest entry).

    Raises
    ------
    ModalError
        Bad input or output (one line naming the file, option or value).
    RunsFailed
        Some runs of an HDF5 file were bad: the good ones were identified (and written to ``out``)
        first; ``.result`` is their Identification, ``.failed`` each bad run's name and error (every
        run bad: the first one's own error).

    References
    ----------
    B. Peeters, H. Van der Auweraer, P. Guillaume, J. Leuridan, "The PolyMAX frequency-domain method",
    Shock and Vibration 11 (2004) 395-409 (pLSCF).  B. Peeters, G. De Roeck, "Reference-based
    stochastic subspace identification for output-only modal analysis", Mechanical Systems and Signal
    Processing 13 (1999) 855-878 (SSI-cov).

    Examples
    --------
    One mode at 40 Hz with 2 % damping (closed form), identified back:

    >>> import numpy as np
    >>> import flexmodal as fm
    >>> f = np.linspace(0.0, 100.0, 401)
    >>> s, w0 = 2j * np.pi * f, 2 * np.pi * 40.0
    >>> H = s**2 / (s**2 + 2 * 0.02 * w0 * s + w0**2)
    >>> ident = fm.identify(fm.frf_from_arrays(f, H, outputs=["tip"]))
    >>> ident.table.frame[["freq_hz", "damping_ratio"]].round(4).values.tolist()
    [[40.0, 0.02]]
    """
    from flexmodal.modal.errors import ModalError

    _check_band(fmin, fmax)
    _check_identify_options(max_order, poles_hz, references)
    _check_source_options(source, run_id=run_id, references=references, config=config, pose=pose)
    config = "run" if config is None else config   # an FrfResult's (a file's configurations are its runs)
    if decay_rate_per_s is not None:
        opt.given(decay_rate_per_s, opt.nonnegative, "identify: decay_rate_per_s", ModalError)
    if pose is not None:
        pose = _pose_numbers(config, pose, "identify", ModalError)
    poles_hz = None if poles_hz is None else list(poles_hz)   # a set or a generator: the methods index it
    if out is not None:
        _identification_outputs(out, uff, source)
    elif uff is not None or from_diagram:
        raise ModalError(f"identify: {'uff' if uff is not None else 'from_diagram'} needs out (the modal "
                         "table it goes with)")
    if from_diagram and not poles_hz:
        raise ModalError("identify --from-diagram: give the poles to pick (--poles F1,F2,...)")
    from flexmodal.checked_io.text import natural_order
    from flexmodal.modal.identify import modes_table
    from flexmodal.modal.sources import by_reciprocity, identify_frf, identify_input

    options = {"method": method, "fmin": fmin, "fmax": fmax, "max_order": max_order, "poles_hz": poles_hz,
               "thresholds": thresholds, "decay_rate_per_s": decay_rate_per_s,
               "diagrams": _stored_diagrams(out, from_diagram) if poles_hz and out is not None else None}
    failed: list = []
    if isinstance(source, str | os.PathLike):
        table, found = identify_input(source, run_id=run_id, references=references, failed=failed,
                                      quiet=quiet, **options)
        order = natural_order(found)   # theta30 before theta120, as in the table
        result = Identification(table, {c: found[c][0] for c in order},
                                {c: tuple(found[c][1]) for c in order})
    else:
        from flexmodal.modal.frf import FrfResult

        if not isinstance(source, FrfResult):   # bytes, a list: said here, not as an AttributeError
            raise TypeError(f"identify: source must be an HDF5 or UFF path or an FrfResult, got "
                            f"{type(source).__name__}")
        source = by_reciprocity(source)   # a roving-hammer set: the hammer points are the shapes' points
        modes = identify_frf(source, **{**options, "method": method or "lscf"})
        table = modes_table(modes, source.outputs, config=config, pose=pose)
        result = Identification(table, {config: modes}, {config: tuple(source.outputs)})
    if out is not None:
        result.write(out, uff=uff)
    if failed:
        from flexmodal.modal.skipped import RunsFailed

        raise RunsFailed(list(result.modes), failed, result=result)
    return result


def _stored_diagrams(out: PathLike, required: bool):
    """The stabilisation diagrams stored beside ``out`` (modal.diagrams.DiagramStore), or None when
    there are none to use: no file, or one that does not read (it is replaced by this run's) unless
    ``required``."""
    from flexmodal.modal.diagrams import DiagramStore, diagram_path, read_diagrams
    from flexmodal.modal.errors import ModalError

    path = diagram_path(out)
    if not path.is_file():
        if required:
            raise ModalError(f"{path}: no stored stabilisation diagram (identify without --poles stores it "
                             "beside --out)")
        return None
    try:
        return DiagramStore(read_diagrams(path), str(path), required)
    except ModalError:
        if required:
            raise
        return None


def _identification_outputs(out: PathLike, uff: PathLike | None, source: object) -> None:
    """Check the files identification writes (the modal table, its synthesis table, the UFF file)
    before any work: none of them an input, each replaceable (ModalError naming it)."""
    from flexmodal.checked_io.output import output_file, sidecar_file
    from flexmodal.modal.errors import ModalError

    inputs = _paths([source])
    output_file(out, ModalError, "modal table (--out)", inputs=inputs)
    if uff is not None:
        output_file(uff, ModalError, "UFF file (--uff)", inputs=(*inputs, out))
    from flexmodal.modal.diagrams import check_replaceable, diagram_path
    from flexmodal.modal.identify import SYNTHESIS_HEADER, synthesis_path

    output_file(synthesis_path(out), ModalError, "FRF synthesis table (next to --out)",
                inputs=(*inputs, out, uff))
    sidecar_file(synthesis_path(out), ModalError, "FRF synthesis table", SYNTHESIS_HEADER)
    output_file(diagram_path(out), ModalError, "stabilisation diagrams (next to --out)",
                inputs=(*inputs, out, uff))
    check_replaceable(diagram_path(out))   # a file of the user's own there is not replaced


def track(source: PathLike, *, pose_from: Mapping[str, str] | None = None, run_id: str | None = None,
          fmin: float | None = None, fmax: float | None = None, window_s: float | None = None,
          hop_s: float | None = None, bin_deg: float = 5.0, max_spread_deg: float = 5.0,
          orders: Sequence[float] = (), max_order: int = 40, out: PathLike | None = None):
    """Modes of an arm while it moves (docs/oma.md, tracking; ``identify --track``).

    SSI-cov in sliding windows of an HDF5 run or UFF time histories, each window tagged with the pose
    of its encoder channels; modes followed by frequency and MAC, motor/gear harmonics set apart.

    Parameters
    ----------
    source : str or Path
        An HDF5 run file or a UFF file of time histories with encoder channels.
    pose_from : mapping, optional
        Pose variable -> encoder channel [deg] (default: the record's one encoder).
    run_id : str, optional
        Only this run of an HDF5 file.
    fmin, fmax : float, optional
        Band edges [Hz].
    window_s, hop_s : float, optional
        Window length and step [s] (default: 80 periods of the slowest mode; a quarter pose bin at
        the 90th percentile pose rate).
    bin_deg : float
        Pose bin width [deg] of the modal map.
    max_spread_deg : float
        Windows whose pose standard deviation exceeds this [deg] are skipped.
    orders : sequence of float
        Harmonic orders per joint revolution (default: found from the data).
    max_order : int
        Highest SSI model order.
    out : str or Path, optional
        Also write the modal map CSV here and ``MODES.harmonics.csv`` beside it, both or neither
        (checked before any work).

    Returns
    -------
    modal.track.TrackResult
        ``table`` the modal map (one configuration per ``bin_deg`` pose bin), ``tracks``,
        ``harmonics``, ``orders``, ``windows``, ``window_s``/``hop_s`` [s] and ``warnings``.

    References
    ----------
    B. Peeters, G. De Roeck, "Reference-based stochastic subspace identification for output-only
    modal analysis", Mechanical Systems and Signal Processing 13 (1999) 855-878.

    Examples
    --------
    >>> import tempfile
    >>> import flexmodal as fm
    >>> from flexmodal.fixtures.examples import moving_run
    >>> path = moving_run(tempfile.mkdtemp())   # 8 s of the demo arm's elbow sweep from 0 deg
    >>> result = fm.track(path, fmax=400.0, window_s=2.0, hop_s=1.0)
    >>> sorted(set(result.table.frame["mode"])), result.warnings
    ([1, 2, 3], ())
    >>> round(float(result.table.freq_hz("theta_deg=0")[0]))     # first bending mode at 0 deg [Hz]
    32
    """
    _check_band(fmin, fmax)
    if pose_from is not None and (not isinstance(pose_from, Mapping) or not all(
            isinstance(k, str) and isinstance(v, str) for k, v in pose_from.items())):
        raise TypeError(f"track: pose_from must map pose variables to encoder channel names, e.g. "
                        f"{{'theta_deg': 'enc_elbow'}}, got {pose_from!r}")
    for what, value in (("window_s", window_s), ("hop_s", hop_s)):
        if value is not None:
            opt.given(value, opt.seconds, f"track: {what}", ModalError)
    opt.given(bin_deg, opt.positive, "track: bin_deg", ModalError)
    opt.given(max_spread_deg, opt.nonnegative, "track: max_spread_deg", ModalError)
    if isinstance(orders, str | bytes) or not isinstance(orders, Iterable):
        raise TypeError(f"track: orders must be a list of orders per revolution, got {orders!r}")
    for order in orders:
        opt.given(order, opt.positive, "track: orders", ModalError)
    if out is not None:
        from flexmodal.checked_io.output import output_file, sidecar_file

        output_file(out, ModalError, "modal table (--out)", inputs=(source,))
        output_file(_harmonics_path(out), ModalError, "harmonics table", inputs=(source, out))
        sidecar_file(_harmonics_path(out), ModalError, "harmonics table", b"t_s,freq_hz,joint,order")
    from flexmodal.modal.track import TrackOptions, track_input

    opt.given(max_order, opt.model_order, "track: max_order", ModalError)
    options = TrackOptions(window_s=window_s, hop_s=hop_s, fmin=fmin, fmax=fmax, max_order=max_order,
                           max_spread_deg=max_spread_deg, bin_deg=bin_deg, orders=tuple(orders))
    result = track_input(str(source), pose_from=pose_from, run_id=run_id, options=options)
    if out is not None:
        from flexmodal.checked_io.output import signals_deferred
        from flexmodal.modal.track import write_harmonics_csv

        with signals_deferred():   # the map and its harmonics: both written, or neither
            result.table.to_csv(out)
            write_harmonics_csv(str(_harmonics_path(out)), result.harmonics)
    return result


def _harmonics_path(out: PathLike) -> Path:
    """``MODES.harmonics.csv`` beside the modal map ``MODES.csv``."""
    out = Path(out)
    return out.with_name(out.stem + ".harmonics.csv")


def _check_identify_options(max_order: object, poles_hz: object, references: object) -> None:
    """``max_order``, ``poles_hz`` and ``references`` as ``identify --max-order/--poles/--references``
    take them (from the API: 1.5 said "lines are too few for a model", 'a' among the poles was a
    ValueError, NaN ran, and a string of references was taken letter by letter)."""
    if max_order is not None:
        opt.given(max_order, opt.model_order, "identify: max_order", ModalError)
    if poles_hz is not None:
        if isinstance(poles_hz, str | bytes) or not isinstance(poles_hz, Iterable):
            raise TypeError(f"identify: poles_hz must be a list of frequencies [Hz], got {poles_hz!r}")
        for f in poles_hz:
            opt.given(f, opt.positive_hz, "identify: poles_hz", ModalError)
    if isinstance(references, str | bytes):
        raise TypeError(f"identify: references must be a list of channel names, got {references!r}: "
                        f"for one channel write [{references!r}]")


def _check_source_options(source: object, **given: object) -> None:
    """ModalError naming an option ``source`` has no use for, which was ignored in silence: ``run_id``
    and ``references`` pick a run of a file and the outputs of its output-only identification (FRFs in
    memory are one record, identified from their inputs); ``config`` and ``pose`` name FRFs in memory
    (a file's configurations are its run ids, each with the pose it stores)."""
    if isinstance(source, str | os.PathLike):
        unused, why = ("config", "pose"), f"{source}: its runs are named by their ids, with their poses"
    else:
        unused, why = ("run_id", "references"), "FRFs given in memory, one record identified from its inputs"
    for name in unused:
        if given[name] is not None:
            raise ModalError(f"identify: {name} = {given[name]!r} has no use with {why} (leave it out)")


def _check_band(fmin: float | None, fmax: float | None) -> None:
    """ModalError when a band edge [Hz] is not a finite number >= 0, or both are given and ``fmin`` is
    not below ``fmax``."""
    for name, edge in (("fmin", fmin), ("fmax", fmax)):
        if edge is not None and (isinstance(edge, bool) or not isinstance(edge, numbers.Real)
                                 or not math.isfinite(edge) or edge < 0):
            raise ModalError(f"--{name} {edge!r}: not a frequency (a finite number of Hz >= 0)")
    if fmin is not None and fmax is not None and fmin >= fmax:
        raise ModalError(f"--fmin {fmin:g} Hz must lie below --fmax {fmax:g} Hz")


def read_table(path: PathLike) -> ModalTable:
    """A modal table CSV (docs/formats.md): one row per (configuration, mode).

    Parameters
    ----------
    path : str or Path
        The CSV file: ``config``, ``mode``, ``freq_hz`` [Hz], optional ``damping_ratio``, ``source``,
        ``pose.<var>`` and ``shape.<sensor>`` columns.

    Returns
    -------
    contract.table.ModalTable
        One row per (configuration, mode): ``freq_hz`` [Hz], damping ratio [-], poses and shapes.

    Examples
    --------
    >>> import flexmodal as fm
    >>> table = fm.read_table("examples/measured/seed003_table3_f1f2.csv")   # seed 003, Table 3
    >>> table.configs[:3], len(table.frame)
    (['theta0', 'theta30', 'theta60'], 12)
    """
    _path_arg(path, "read_table: path")
    from flexmodal.contract.table import ModalTable

    return ModalTable.read_csv(path)


def read_poses(path: PathLike) -> dict[str, dict[str, float]]:
    """A POSES.csv (docs/formats.md): one row per configuration.

    Parameters
    ----------
    path : str or Path
        A CSV with a ``config`` column and ``pose.<var>`` columns (angles in degrees, masses in kg);
        a modal table CSV works too.

    Returns
    -------
    dict of str to dict of str to float
        ``{config: {pose variable: value}}``.

    Examples
    --------
    >>> import flexmodal as fm
    >>> fm.read_poses("examples/measured/seed003_table3_f1f2.csv")["theta30"]
    {'theta_deg': 30.0}
    """
    _path_arg(path, "read_poses: path")
    from flexmodal.contract.table import poses_from_csv

    return poses_from_csv(path)


def _table(table: ModalTable | PathLike) -> ModalTable:
    from flexmodal.contract.table import ModalTable

    if isinstance(table, str | os.PathLike):
        return read_table(table)
    if not isinstance(table, ModalTable):   # a list of tables, None: said here, not as an AttributeError
        raise TypeError(f"expected a modal table or the path of its CSV file, got {type(table).__name__}")
    return table


def _config_of(table: ModalTable, config: str, error: type[Exception]) -> str:
    """``config`` when ``table`` has it, else ``error`` naming the table's configurations."""
    if not table.has_config(config):
        raise error(f"{table.source}: no configuration {config!r} (have {', '.join(table.configs)})")
    return config


# -- models ----------------------------------------------------------------------------------------

def load_rig(path: PathLike) -> Rig:
    """A rig description (TOML, docs/formats.md), validated.

    Parameters
    ----------
    path : str or Path
        The rig TOML: links with sections and materials (SI units), joints, masses, sensors, pose
        variables.

    Returns
    -------
    models.rig.Rig
        The validated rig: links, joints, masses and sensors (SI units) and its pose variables.

    Raises
    ------
    ModelError
        One line naming the file, table and field that is wrong.

    Examples
    --------
    >>> import flexmodal as fm
    >>> rig = fm.load_rig("examples/rigs/seed003_two_link.toml")
    >>> rig.name, rig.pose_variables, [s.name for s in rig.sensors]
    ('seed003-two-link', ('theta_deg',), ['a1', 'a2', 'a3'])
    """
    _path_arg(path, "load_rig: path")
    from flexmodal.models.rig import load_rig as _load

    return _load(path)


def _rig(rig: Rig | PathLike) -> Rig:
    return load_rig(rig) if isinstance(rig, str | Path) else rig


def predict(rig: Rig | PathLike, poses: Mapping[str, Mapping[str, float]] | ModalTable | PathLike,
            model: str = "fe", n_modes: int = 4, *, source: str | None = None,
            progress: Callable[[str], None] | None = None, out: PathLike | None = None,
            **options: object) -> ModalTable:
    """Predicted modes of a rig for every configuration by one of the registered models.

    Parameters
    ----------
    rig : models.rig.Rig, str or Path
        The rig, or its TOML file.
    poses : mapping, contract.table.ModalTable, str or Path
        ``{config: {pose variable: value}}`` (degrees, kg), a POSES.csv path, or a modal table whose
        configurations and poses are taken.
    model : str
        A registered model (models.registry.MODELS): ``fe``, ``assumed-modes``, ``lumped-mass``,
        ``blevins``.
    n_modes : int
        Elastic modes per configuration (rigid-body modes are left out).
    source : str, optional
        Value of the ``source`` column (default: the model name).
    progress : callable, optional
        Called with each configuration once it is solved.
    out : str or Path, optional
        Also write the table as a modal table CSV here (checked before any work; never an input).
    **options
        Model options (docs/models.md): ``elements_per_link``, ``lumped_mass`` (fe);
        ``masses_per_link``, ``coordinates`` (lumped-mass).

    Returns
    -------
    contract.table.ModalTable
        Natural frequencies [Hz] and mass-normalised shapes [kg^-1/2] at the rig's sensors.

    References
    ----------
    A. E. Abdelraheim, M. Nejlaoui, N. A. Alqahtani, "Bioinspired Computation for Identifying Joint
    Compliance in Biomimetic Flexible Manipulators", Biomimetics 11(7), 474 (2026): Table 6 (rigid-joint
    FE, 25.33 and 158.45 Hz at 0 deg).

    Examples
    --------
    >>> import flexmodal as fm
    >>> fe = fm.predict("examples/rigs/seed003_two_link.toml", {"theta0": {"theta_deg": 0.0}}, "fe", 2)
    >>> fe.frame["freq_hz"].round(1).tolist()
    [25.3, 158.4]
    """
    from flexmodal.models.errors import ModelError

    if out is not None:
        from flexmodal.checked_io.output import output_file

        output_file(out, ModelError, "prediction table (--out)", inputs=_paths([rig, poses]))
    from flexmodal.models.predict import predict as _predict

    rig = _rig(rig)
    if isinstance(poses, str | Path):
        where, poses = poses, read_poses(poses)
        if not poses:
            raise ModelError(f"{where}: no configurations")
        have = set().union(*poses.values())
        missing = [v for v in rig.pose_variables if v not in have]
        if missing:  # the poses file lacks the column, not the rig its variable
            raise ModelError(f"{where}: no column 'pose.{missing[0]}' (rig {rig.source} needs the pose "
                             f"variable {missing[0]!r}; pose columns are named pose.<variable>)")
    elif not isinstance(poses, Mapping):
        table = _table(poses)   # a list or None: a TypeError naming it, not an AttributeError
        poses = {c: table.pose(c) for c in table.configs}
    else:   # the caller's own {config: {variable: value}}: numbers, as a poses file's are
        poses = {config: _pose_numbers(config, pose) for config, pose in poses.items()}
    if not poses:
        raise ModelError("predict: no configurations")
    table = _predict(rig, poses, model, n_modes, source=source, progress=progress, **options)
    if out is not None:
        table.to_csv(out)
    return table


def _pose_numbers(config: object, pose: object, where: str = "predict",
                  error: type[FlexmodalError] = ModelError) -> dict[str, float]:
    """A pose {variable: value} of finite numbers (degrees, kg), else ``error`` naming the value."""
    if not isinstance(pose, Mapping):
        raise error(f"{where}: config {config!r}: the pose must be a mapping {{variable: value}}, got "
                    f"{type(pose).__name__}")
    out = {}
    for name, value in pose.items():
        if isinstance(value, bool) or not isinstance(value, numbers.Real) or not math.isfinite(value):
            raise error(f"{where}: config {config!r}: pose {name} = {value!r} is not a finite number")
        out[str(name)] = float(value)
    return out


# -- comparison and diagnosis ----------------------------------------------------------------------

def _named(tables: Iterable[ModalTable | PathLike | tuple[str, ModalTable]]) -> list[tuple[str, ModalTable]]:
    from flexmodal.compare.tables import table_name

    out = []
    for t in tables:
        if isinstance(t, tuple):
            out.append(t)
        else:
            table = _table(t)
            sources = table.frame["source"].dropna().astype(str).unique() if "source" in table.frame else ()
            if len(sources) > 1:   # one column per model: two models in one file were paired as one
                from flexmodal.compare.errors import CompareError

                raise CompareError(f"{table.source}: a predicted table of {len(sources)} sources "
                                   f"({', '.join(map(repr, sources[:4]))}): give one model per file")
            out.append((table_name(table, Path(str(t)).stem if isinstance(t, str | Path)
                                   else Path(table.source).stem), table))
    return out


def compare_modes(measured: ModalTable | PathLike,
                  *predicted: ModalTable | PathLike | tuple[str, ModalTable],
                  min_mac: float = 0.5) -> Comparison:
    """Pair every predicted table with the measured one (docs/compare-and-report.md).

    Pairs by MAC where both tables have shapes at two or more common sensors, else by ascending
    frequency; unpaired modes are kept.

    Parameters
    ----------
    measured : contract.table.ModalTable, str or Path
        The measured modal table.
    *predicted : contract.table.ModalTable, str, Path or (name, table)
        Predicted tables, named by their ``source`` column, else by the file name.
    min_mac : float
        MAC pairs below this value [0, 1] are rejected.

    Returns
    -------
    compare.tables.Comparison
        Printed by :func:`format_comparison`.

    References
    ----------
    R. J. Allemang and D. L. Brown, "A correlation coefficient for modal vector analysis", Proc. 1st
    International Modal Analysis Conference (IMAC), Orlando, 1982, 110-116 (MAC).

    Examples
    --------
    >>> import flexmodal as fm
    >>> measured = fm.read_table("examples/measured/seed003_table3_f1f2.csv")
    >>> fe = fm.predict("examples/rigs/seed003_two_link.toml", measured, "fe", 2)
    >>> print(fm.format_comparison(fm.compare_modes(measured, fe)).splitlines()[2])
    | theta0 | 1 | 25.33 | 25.50 | -0.7 |
    """
    from flexmodal.compare.errors import CompareError
    from flexmodal.compare.tables import compare_tables, table_name

    if isinstance(min_mac, bool) or not isinstance(min_mac, numbers.Real) or not 0.0 <= min_mac <= 1.0:
        raise CompareError(f"--min-mac: must lie in [0, 1] (got {min_mac!r})")
    meas = _table(measured)
    return compare_tables(meas, _named(predicted), measured_name=table_name(meas, "experiment"),
                          min_mac=min_mac)


def format_comparison(comparison: Comparison, fmt: str = "md", layout: str = "modes",
                      caption: str = "Measured and predicted natural frequencies") -> str:
    """The comparison as text.

    Parameters
    ----------
    comparison : compare.tables.Comparison
        A :func:`compare_modes` result.
    fmt : {"md", "csv", "tex", "html", "json"}
        Markdown, CSV (full precision), LaTeX booktabs, an HTML page or JSON rows.
    layout : {"modes", "sources"}
        A row per mode and a column per source, or a row per source and a column per mode.
    caption : str
        Table caption (tex and html).

    Returns
    -------
    str
        Frequencies [Hz], measured damping ratio [%], error (pred - meas)/meas [%] and MAC [-].

    Examples
    --------
    >>> import flexmodal as fm
    >>> measured = fm.read_table("examples/measured/seed003_table3_f1f2.csv")
    >>> fe = fm.predict("examples/rigs/seed003_two_link.toml", measured, "fe", 2)
    >>> print(fm.format_comparison(fm.compare_modes(measured, fe), "csv").splitlines()[0])
    config,mode,fe_freq_hz,experiment_freq_hz,fe_err_pct
    """
    from flexmodal.compare.tables import render

    return render(comparison, fmt, layout, caption)


def write_comparison(comparison: Comparison, out: PathLike, fmt: str = "md", layout: str = "modes",
                     caption: str = "Measured and predicted natural frequencies") -> Path:
    """Write :func:`format_comparison`'s text to a file, atomically (never over one of the tables
    compared).

    Parameters
    ----------
    comparison : compare.tables.Comparison
        A :func:`compare_modes` result.
    out : str or Path
        The file to write.
    fmt : {"md", "csv", "tex", "html", "json"}
        The text's format, as :func:`format_comparison`.
    layout : {"modes", "sources"}
        A row per mode or a row per source, as :func:`format_comparison`.
    caption : str
        Table caption (tex and html).

    Returns
    -------
    Path
        ``out``.

    Examples
    --------
    >>> import tempfile
    >>> import flexmodal as fm
    >>> measured = fm.read_table("examples/measured/seed003_table3_f1f2.csv")
    >>> fe = fm.predict("examples/rigs/seed003_two_link.toml", measured, "fe", 2)
    >>> path = fm.write_comparison(fm.compare_modes(measured, fe), tempfile.mkdtemp() + "/t.csv", "csv")
    >>> path.read_text().splitlines()[0]
    'config,mode,fe_freq_hz,experiment_freq_hz,fe_err_pct'
    """
    from flexmodal.checked_io.output import output_file, write_text
    from flexmodal.compare.errors import CompareError

    tables = [comparison.measured, *(t for _, t in comparison.predictions)]
    target = output_file(out, CompareError, "table (--out)", inputs=[t.source for t in tables])
    return write_text(target, format_comparison(comparison, fmt, layout, caption))


DIAGNOSIS_FILES = ("diagnosis.json", "diagnosis.html")   # what write_diagnosis writes into its folder
# how each starts, and the mark near its end (the page's footer), when flexmodal wrote it
DIAGNOSIS_MARKS = ((b'{\n' + 2 * b' ' + b'"baseline"', b""),   # json.dumps(indent=2)'s first key
                   (b"<!DOCTYPE html>", b"<p>Versions: flexmodal "))
# the start of a diagnosis.html written before the footer (67daf75, 26 Nov): the report template's
# "Generated ... by flexmodal" line under the title (since 7d23b90), or compare.diagnosis.render_html's page
OLDER_DIAGNOSIS_PAGES = (
    re.compile(rb'<!DOCTYPE html>\n<html lang="en">\n.*?<p class="meta">Generated [^<]*? by flexmodal ',
               re.S),
    re.compile(rb'<!DOCTYPE html><html><head><meta charset="utf-8"><title>Sim-to-real gap diagnosis</title>'))


def _diagnosis_folder(out_dir: PathLike, inputs: Sequence[PathLike]) -> Path:
    """``out_dir`` checked as the folder of :data:`DIAGNOSIS_FILES`: each may replace only a file
    flexmodal wrote there (the user named the folder, not the files: a diagnosis.json or .html of
    their own was replaced in silence)."""
    from flexmodal.checked_io.output import output_dir, sidecar_file

    out = output_dir(out_dir, CompareError, "diagnosis folder (--out)", files=DIAGNOSIS_FILES,
                     inputs=inputs)
    for name, (signature, mark), older in zip(DIAGNOSIS_FILES, DIAGNOSIS_MARKS, ((), OLDER_DIAGNOSIS_PAGES),
                                              strict=True):
        sidecar_file(out / name, CompareError, name, signature, mark, older)
    return out


def diagnose(rig: Rig | PathLike, measured: ModalTable | PathLike, *, effects: str | Sequence[str] = "all",
             holdout: str | Sequence[str] = "auto", scatter: float | None = 0.005,
             out_dir: PathLike | None = None, progress: Callable[[str], None] | None = None) -> Diagnosis:
    """Sim-to-real gap diagnosis of a nominal rig against measured modes over several poses.

    Where the gap is, which unmodelled effect (models/effects.py) at which location explains it, judged
    by the error on held-out configurations (docs/diagnosis.md).

    Parameters
    ----------
    rig : models.rig.Rig, str or Path
        The nominal rig, or its TOML file.
    measured : contract.table.ModalTable, str or Path
        Measured modes with ``pose.<var>`` columns (degrees, kg), several configurations.
    effects : str or sequence of str
        ``"all"`` or the effect names to rank.
    holdout : str or sequence of str
        ``"auto"`` (leave one pose out; 5-fold above 10 poses) or the configurations to hold out.
    scatter : float, optional
        Fallback relative scatter of the measured frequencies [-] (0.005 = 0.5 %), used only when the
        table carries no estimate (repeated configurations or ``freq_std_hz``); None: the default.
    out_dir : str or Path, optional
        Also write ``diagnosis.json`` and ``diagnosis.html`` into this folder (:func:`write_diagnosis`);
        the folder is checked before any work.
    progress : callable, optional
        Called with one line once the inputs are read and checked, then at each stage of the ranking
        (with a transient bar of the fits on a terminal's stderr).

    Returns
    -------
    compare.result.Diagnosis
        Frozen records: ``.verdict`` (effect, location, parameters with 95 % intervals, held-out RMS
        relative error before/after [-]), ``.ranking``, ``.where``, ``.warnings`` (one line per reason
        why measured shapes -- zero, empty or NaN at the rig's sensors -- paired some configurations'
        modes by frequency order, not by MAC; the command prints them on stderr); ``.to_json()`` is
        diagnosis.json (docs/formats.md); :func:`format_diagnosis` the command's summary.

    Raises
    ------
    CompareError
        Inputs that do not fit the rig, unknown effects, a bad hold-out (one line).

    References
    ----------
    A. E. Abdelraheim, M. Nejlaoui, N. A. Alqahtani, "Bioinspired Computation for Identifying Joint
    Compliance in Biomimetic Flexible Manipulators", Biomimetics 11(7), 474 (2026): Table 3 (the
    measured frequencies), Table 6 (the joint-compliance model).

    Examples
    --------
    Seed 003's two-link arm against its measured Table 3 (three poses fitted, three held out): the
    paper's joint compliance is part of the verdict, and the held-out RMS gap falls below the 5 % issue
    26 asks of this case:

    >>> import flexmodal as fm
    >>> result = fm.diagnose("examples/rigs/seed003_two_link.toml",
    ...                      "examples/measured/seed003_table3_f1f2.csv", holdout="theta30,theta90,theta150")
    >>> "joint_stiffness" in result.verdict.effect.split("+")
    True
    >>> result.verdict.heldout_rms_rel_error_after < 0.05 < result.verdict.heldout_rms_rel_error_before
    True
    """
    if out_dir is not None:
        _diagnosis_folder(out_dir, _paths([rig, measured]))   # before the heavy imports
    rig, table = _rig(rig), _table(measured)
    from flexmodal.compare.candidates import parse_effects
    from flexmodal.compare.diagnosis import diagnose as _diagnose
    from flexmodal.compare.diagnosis import folds_for

    if not isinstance(effects, str) and not (isinstance(effects, Iterable)
                                            and all(isinstance(e, str) for e in effects)):
        raise TypeError(f"diagnose: effects must be 'all', a comma list or a list of effect names, got "
                        f"{effects!r}")
    parse_effects(effects if isinstance(effects, str) else ",".join(effects))  # bad input fails now
    if scatter is not None and (isinstance(scatter, bool) or not isinstance(scatter, numbers.Real)):
        raise TypeError(f"diagnose: scatter must be a fraction (0.005 = 0.5 %) or None, got {scatter!r}")
    folds_for(table.configs, holdout)
    result = _diagnose(rig, table, effects=effects, holdout=holdout, scatter=scatter, progress=progress)
    if out_dir is not None:
        write_diagnosis(result, out_dir, inputs=[rig.source, table.source])
    return result


def format_diagnosis(result: Diagnosis) -> str:
    """The summary ``flexmodal diagnose`` prints: verdict, held-out improvement, scatter, parameters
    with their 95 % intervals, what remains, and the next measurement.

    Parameters
    ----------
    result : compare.result.Diagnosis
        A :func:`diagnose` result (or :func:`read_diagnosis`).

    Returns
    -------
    str
        Lines of text (no final newline); errors in percent, parameters in the effect's SI units.

    Examples
    --------
    Seed 003's arm against its Table 3, ranking the paper's joint compliance only (``effects``: one
    candidate fitted; :func:`diagnose` shows the full ranking):

    >>> import flexmodal as fm
    >>> result = fm.diagnose("examples/rigs/seed003_two_link.toml",
    ...                      "examples/measured/seed003_table3_f1f2.csv", effects="joint_stiffness",
    ...                      holdout="theta30,theta90,theta150")
    >>> print(fm.format_diagnosis(result).splitlines()[0])   # doctest: +ELLIPSIS
    verdict: joint_stiffness at elbow; held-out RMS ...% -> ...%
    """
    from flexmodal.checked_io.percent import percent
    from flexmodal.compare.verdict_text import advice_words, alternatives_words, scatter_line, verdict_words

    result = _diagnosis(result)
    v = result.verdict
    lines = [f"verdict: {v.effect} at {v.location or '-'}; held-out RMS "
             f"{percent(v.heldout_rms_rel_error_before)} -> {percent(v.heldout_rms_rel_error_after)}"]
    words = verdict_words(result)
    lines += [x for x in (words, scatter_line(result)) if x]
    lines += [f"  {name} = {v.params[name]:.4g} (95 % interval {lo:.4g} .. {hi:.4g})"
              for name, (lo, hi) in (v.param_intervals or {}).items()]
    said = bool(v.residual_feature) and f"it shows as {v.residual_feature}" in words   # not twice
    remaining = [f"remaining: {v.residual_feature}"] if v.residual_feature and not said else []
    remaining += [f"flagged: {f}" for f in v.flags or ()]
    if remaining:
        lines.append("; ".join(remaining))
    if v.ranked and v.ranked > 1:
        lines.append(f"not the top of the ranking ({v.ranked}): {v.why_not_top}")
    if v.ambiguous and v.alternatives:
        lines.append(f"fits as well within noise: {alternatives_words(result)}")
    if v.next_measurements or v.ambiguous:
        lines.append(f"next measurement: {advice_words(result)}")
    return "\n".join(lines)


def _paths(sources: Iterable[object]) -> list[PathLike]:
    """The files among ``sources`` (paths, ``FILE::RUN_ID``, (file, run id); objects are skipped):
    the inputs an output must not replace."""
    found: list[PathLike] = []
    for s in sources:
        if isinstance(s, tuple) and s and isinstance(s[0], str | Path):
            found.append(s[0])
        elif isinstance(s, Path):
            found.append(s)
        elif isinstance(s, str):
            found.append(s.partition("::")[0])
    return found


def write_diagnosis(result: Diagnosis, out_dir: PathLike,
                    inputs: Sequence[PathLike] = ()) -> tuple[Path, Path]:
    """Write ``diagnosis.json`` and ``diagnosis.html`` of a :func:`diagnose` result into a folder.

    The JSON is strict (docs/formats.md, Diagnosis JSON); the page is the validation report's
    diagnosis section alone (one renderer, reports/html.py).  Each file is written atomically.

    Parameters
    ----------
    result : compare.result.Diagnosis
        A :func:`diagnose` result.
    out_dir : str or Path
        The folder (created if missing; its two files replaced, never an input).
    inputs : sequence of str or Path
        The files the result came from (the rig and the measured modes), named on the page.

    Returns
    -------
    (Path, Path)
        The JSON and the HTML file.

    Examples
    --------
    >>> import tempfile
    >>> import flexmodal as fm
    >>> result = fm.diagnose("examples/rigs/seed003_two_link.toml",
    ...                      "examples/measured/seed003_table3_f1f2.csv", effects="joint_stiffness",
    ...                      holdout="theta30,theta90,theta150")   # one candidate
    >>> pj, ph = fm.write_diagnosis(result, tempfile.mkdtemp())
    >>> pj.name, ph.name, fm.read_diagnosis(pj).verdict.effect == result.verdict.effect
    ('diagnosis.json', 'diagnosis.html', True)
    """
    from flexmodal.checked_io.output import atomic_group, write_text
    from flexmodal.reports.html import write_report

    result = _diagnosis(result)
    out = _diagnosis_folder(out_dir, inputs)
    out.mkdir(parents=True, exist_ok=True)
    with atomic_group():   # diagnosis.json and .html: both, or neither
        pj = write_text(out / DIAGNOSIS_FILES[0], result.to_json())
        ph = write_report(out / DIAGNOSIS_FILES[1], diagnosis=result, title="Sim-to-real gap diagnosis",
                          inputs=list(inputs))
    return pj, ph


def read_diagnosis(path: PathLike) -> Diagnosis:
    """A diagnosis.json (docs/formats.md) read back into the :func:`diagnose` result it came from.

    Parameters
    ----------
    path : str or Path
        The diagnosis.json written by :func:`write_diagnosis` or ``flexmodal diagnose``.

    Returns
    -------
    compare.result.Diagnosis
        The result as :func:`diagnose` returned it.

    Raises
    ------
    ReportError
        Naming the file and the key when it is not a diagnosis.

    Examples
    --------
    >>> import tempfile
    >>> import flexmodal as fm
    >>> out = tempfile.mkdtemp() + "/bad.json"
    >>> _ = open(out, "w").write("{}")
    >>> fm.read_diagnosis(out)
    Traceback (most recent call last):
    ...
    flexmodal.reports.errors.ReportError: ...
    """
    _path_arg(path, "read_diagnosis: path")
    from flexmodal.reports.html import load_diagnosis

    return load_diagnosis(path)


# -- figures ---------------------------------------------------------------------------------------

def _frf_result(frf: object) -> FrfResult:
    """``frf`` when it is an FRF result; else a TypeError naming what it is (None, a path: not an
    AttributeError deep in the plotting)."""
    from flexmodal.modal.frf import FrfResult

    if not isinstance(frf, FrfResult):
        raise TypeError(f"expected an FRF result (compute_frf, frf_from_arrays), got {type(frf).__name__}")
    return frf


def plot_frf(frf: FrfResult, title: str = "") -> Figure:
    """Magnitude, phase [deg] and coherence [-] of the FRFs of one run (first reference).

    Parameters
    ----------
    frf : modal.frf.FrfResult
        A :func:`compute_frf` result.
    title : str
        Figure title.

    Returns
    -------
    matplotlib.figure.Figure
        Against frequency [Hz]: magnitude (the FRF's unit, log), phase [deg] and coherence [-].

    Examples
    --------
    >>> import tempfile
    >>> import flexmodal as fm
    >>> from flexmodal.fixtures.examples import impact_run
    >>> path = impact_run(tempfile.mkdtemp())    # a simulated impact test of the demo arm
    >>> fig = fm.plot_frf(fm.compute_frf(path))
    >>> len(fig.axes)
    3
    """
    from flexmodal.reports import plots

    frf = _frf_result(frf)
    return plots.plot_frf(frf.freq_hz, frf.H, frf.coherence, frf.outputs,
                          plots.frf_unit(frf.quantity), title=title)


def plot_stabilisation(frf: FrfResult, modes: Modes | None = None, *, fmin: float | None = None,
                       fmax: float | None = None, max_order: int | None = None, title: str = "") -> Figure:
    """Stabilisation diagram of the pLSCF identification of an FRF over the CMIF of its band.

    Parameters
    ----------
    frf : modal.frf.FrfResult
        A :func:`compute_frf` result.
    modes : modal.identify.Modes, optional
        The identification to draw (an :func:`identify` result's ``modes[config]``); else ``frf`` is
        identified here.
    fmin, fmax : float, optional
        Band [Hz] of the identification done here.
    max_order : int, optional
        Highest pLSCF order (default: the order adapts to the data).
    title : str
        Figure title.

    Returns
    -------
    matplotlib.figure.Figure
        Stable (filled) and unstable (open) poles per model order over the CMIF, frequency in Hz.

    References
    ----------
    B. Peeters, H. Van der Auweraer, P. Guillaume, J. Leuridan, "The PolyMAX frequency-domain method",
    Shock and Vibration 11 (2004) 395-409.

    Examples
    --------
    >>> import tempfile
    >>> import flexmodal as fm
    >>> from flexmodal.fixtures.examples import impact_run
    >>> path = impact_run(tempfile.mkdtemp())    # a simulated impact test of the demo arm
    >>> fig = fm.plot_stabilisation(fm.compute_frf(path), fmax=400.0)
    >>> type(fig).__name__
    'Figure'
    """
    from flexmodal.modal.sources import identify_frf
    from flexmodal.reports import plots

    frf = _frf_result(frf)
    _check_band(fmin, fmax)
    if max_order is not None:
        opt.given(max_order, opt.model_order, "plot_stabilisation: max_order", ModalError)
    if modes is None:
        modes = identify_frf(frf, fmin=fmin, fmax=fmax, max_order=max_order)
    return plots.plot_identification_diagram(frf, modes, plots.frf_unit(frf.quantity), title=title)


def plot_mode_shapes(rig: Rig | PathLike, measured: ModalTable | PathLike, config: str,
                     n_fe_modes: int = 8, title: str = "") -> Figure:
    """Measured shapes of one configuration drawn on the arm at its pose.

    Each measured shape at the rig's sensors is drawn with the best-matching (MAC) of the frame FE
    model's ``n_fe_modes`` lowest modes as a curve.

    Parameters
    ----------
    rig : models.rig.Rig, str or Path
        The rig, or its TOML file.
    measured : contract.table.ModalTable, str or Path
        Modal table with ``shape.<sensor>`` columns.
    config : str
        The configuration to draw.
    n_fe_modes : int
        FE modes to match against.
    title : str
        Figure title.

    Returns
    -------
    matplotlib.figure.Figure
        Each measured shape at the sensors drawn on the arm (m), with the FE mode of highest MAC.

    References
    ----------
    R. J. Allemang and D. L. Brown, "A correlation coefficient for modal vector analysis", Proc. 1st
    International Modal Analysis Conference (IMAC), Orlando, 1982, 110-116 (MAC).

    Examples
    --------
    >>> import flexmodal as fm
    >>> rig = "examples/rigs/demo_arm.toml"
    >>> fe = fm.predict(rig, {"theta30": {"theta_deg": 30.0}}, "fe", 3)
    >>> type(fm.plot_mode_shapes(rig, fe, "theta30")).__name__
    'Figure'
    """
    from flexmodal.models.arm_shapes import arm_modes
    from flexmodal.reports import plots

    opt.given(n_fe_modes, opt.count, "plot_mode_shapes: n_fe_modes", ReportError)
    rig, measured = _rig(rig), _table(measured)
    _config_of(measured, config, ReportError)
    sensors = [s.name for s in rig.sensors if s.name in measured.sensors]
    return plots.plot_mode_shapes(arm_modes(rig, measured.pose(config), sensors, n_fe_modes), measured,
                                  config, title=title)


def plot_comparison(measured: ModalTable | PathLike,
                    *predicted: ModalTable | PathLike | tuple[str, ModalTable], pose_var: str | None = None,
                    repeats: Sequence[ModalTable | PathLike] = (),
                    title: str = "") -> Figure:
    """Measured and predicted natural frequencies [Hz] against a pose variable.

    Parameters
    ----------
    measured : contract.table.ModalTable, str or Path
        The measured modal table (its mean with ``repeats``, ± 1 standard deviation).
    *predicted : contract.table.ModalTable, str, Path or (name, table)
        Predicted tables, a line per model and mode.
    pose_var : str, optional
        The pose variable on the x axis (default: the first that varies).
    repeats : sequence of modal tables or paths
        Repeated measurements of the same configurations.
    title : str
        Figure title.

    Returns
    -------
    matplotlib.figure.Figure
        Natural frequencies [Hz] against the pose variable: measured points, a line per model and mode.

    Examples
    --------
    >>> import flexmodal as fm
    >>> measured = fm.read_table("examples/measured/seed003_table3_f1f2.csv")
    >>> fe = fm.predict("examples/rigs/seed003_two_link.toml", measured, "fe", 2)
    >>> fig = fm.plot_comparison(measured, fe)
    >>> fig.axes[0].get_xlabel()
    'theta_deg [deg]'
    """
    from flexmodal.reports import plots
    from flexmodal.reports.errors import ReportError
    from flexmodal.reports.html import pose_unit, varying_pose_vars

    meas = [_table(measured)] + [_table(r) for r in repeats]
    if pose_var is None:
        varying = varying_pose_vars(meas[0])
        if not varying:
            raise ReportError(f"{meas[0].source}: no pose variable varies across configurations")
        pose_var = varying[0]
    return plots.plot_freq_vs_pose(meas, _named(predicted), pose_var, pose_unit(pose_var), title=title)


def plot_gap(diagnosis: Diagnosis | Mapping | PathLike, title: str = "") -> Figure:
    """Per-mode RMS relative frequency error [%] before and after the diagnosed effect.

    Parameters
    ----------
    diagnosis : compare.result.Diagnosis, mapping, str or Path
        A :func:`diagnose` result, a parsed diagnosis.json or its path.
    title : str
        Figure title.

    Returns
    -------
    matplotlib.figure.Figure
        Bars of each mode's relative frequency error [%], RMS over configurations: of the nominal model
        over all of them, with the diagnosed effect over those it is judged on (the held-out ones, or
        all when the diagnosis held none out: the legend says which); and the held-out RMS error [%]
        over all modes, before and after.

    Examples
    --------
    >>> import flexmodal as fm
    >>> result = fm.diagnose("examples/rigs/seed003_two_link.toml",
    ...                      "examples/measured/seed003_table3_f1f2.csv", effects="joint_stiffness",
    ...                      holdout="theta30,theta90,theta150")   # one candidate
    >>> type(fm.plot_gap(result)).__name__
    'Figure'
    """
    from flexmodal.reports import plots

    return plots.plot_gap(_diagnosis(diagnosis), title=title)


def _diagnosis(diagnosis: Diagnosis | Mapping | PathLike) -> Diagnosis:
    """A :func:`diagnose` result as it is, or read from a parsed diagnosis.json or its path
    (ReportError naming the key that does not fit docs/formats.md)."""
    from flexmodal.compare.errors import CompareError
    from flexmodal.compare.result import Diagnosis
    from flexmodal.reports.errors import ReportError

    if isinstance(diagnosis, str | Path):
        return read_diagnosis(diagnosis)
    if isinstance(diagnosis, Mapping):
        try:
            return Diagnosis.from_dict(dict(diagnosis))
        except CompareError as exc:
            raise ReportError(str(exc)) from None
    if not isinstance(diagnosis, Diagnosis):
        raise TypeError(f"expected a diagnosis (diagnose, read_diagnosis), its dict or the path of "
                        f"diagnosis.json, got {type(diagnosis).__name__}")
    return diagnosis


# -- report ----------------------------------------------------------------------------------------

def _tracked_map_figures(inputs) -> list[tuple[Figure, str]]:
    """The report's modal-map section: a measured table from ``identify --track`` (source ``track``)
    drawn as frequency against its pose (compare/modal_map.py branches, reports/modal_map_plot.py),
    with the first prediction's frequencies at the same configurations overlaid (``predict --poses
    MAP.csv``); nothing for any other table."""
    import numpy as np

    from flexmodal.compare.modal_map import PredictionBand, modal_map
    from flexmodal.reports.html import pose_unit
    from flexmodal.reports.modal_map_plot import plot_modal_map

    meas = inputs.measured
    if meas is None or "source" not in meas.frame or not (meas.frame["source"] == "track").all() \
            or len(meas.pose_columns) != 1:
        return []
    var = meas.pose_columns[0].removeprefix("pose.")
    band, named = None, ""
    for name, pred in inputs.predictions[:1]:
        configs = sorted((c for c in meas.configs if c in pred.configs), key=lambda c: meas.pose(c)[var])
        n = min((pred.freq_hz(c).size for c in configs), default=0)
        if n:
            f = np.array([pred.freq_hz(c)[:n] for c in configs])
            band = PredictionBand(np.array([meas.pose(c)[var] for c in configs]), f, f, f, label=name)
            named = f", {name}'s frequencies at the same poses as lines"
    fig = plot_modal_map(modal_map(meas), band, pose_label=f"{var} [{pose_unit(var)}]",
                         title="modes tracked while the arm moved (mean ± 95 % interval per pose bin)")
    return [(fig, f"Natural frequency against {var} of the modes tracked while the arm moved (identify "
                  f"--track: one point per pose bin, bars ± 1.96 standard errors of its windows){named}")]


def report(out: PathLike, *, runs: Sequence[PathLike | tuple[PathLike, str]] = (),
           measured: ModalTable | PathLike | None = None, repeats: Sequence[ModalTable | PathLike] = (),
           predictions: Sequence[ModalTable | PathLike | tuple[str, ModalTable]] = (),
           diagnosis: Diagnosis | Mapping | PathLike | None = None,
           rig: Rig | PathLike | None = None, title: str = "flexmodal validation report",
           oma_fmin: float | None = None, oma_fmax: float | None = None,
           fmin: float | None = None, fmax: float | None = None, geometry: PathLike | None = None,
           progress: Callable[[str], None] | None = None, pdf: bool = False,
           shapes_at: Sequence[str] | None = None) -> Path:
    """Write the self-contained HTML validation report (docs/compare-and-report.md).

    One file, images embedded, nothing fetched from a network: run metadata, channels, data quality,
    FRFs with the stabilisation diagram of their identification, measured vs predicted modes, mode
    shapes on the arm, the gap diagnosis and every registered report section (reports/sections.py).
    Everything is computed here; ``reports.html`` only renders it.  The output (and the inputs' runs)
    are checked before any work.

    Parameters
    ----------
    out : str or Path
        The HTML file (its folder must exist; never one of the inputs).
    runs : sequence of str, Path or (path, run id)
        HDF5 files (all their runs), ``FILE::RUN_ID`` or (file, id).  Runs with stored FRFs are shown
        with the stabilisation diagram of :func:`identify` in ``fmin``..``fmax``; output-only runs
        (operational, or no force channel) with their FDD singular values and SSI-cov diagram in
        ``oma_fmin``..``oma_fmax`` (docs/oma.md).
    measured : contract.table.ModalTable, str or Path, optional
        Identified modes.
    repeats : sequence of modal tables or paths
        Repeated tests of the same configurations (error bars).
    predictions : sequence of modal tables, paths or (name, table)
        Predicted modes, one table per model.
    diagnosis : compare.result.Diagnosis, mapping or path, optional
        A :func:`diagnose` result, a parsed diagnosis.json or its path.
    rig : models.rig.Rig, str or Path, optional
        Draws the measured shapes on the arm and animates them beside the FE model's.
    title : str
        The report's title.
    oma_fmin, oma_fmax, fmin, fmax : float, optional
        Identification bands [Hz] of output-only runs and of runs with FRFs (default: the whole
        record).
    geometry : str or Path, optional
        A Universal File with the test geometry (datasets 15 or 2411, 82, 18 or 2420) to animate the
        measured modes on (their sensors named ``<node>+z`` ...).
    progress : callable, optional
        Called with a short message per step.
    pdf : bool
        Also print the report to ``REPORT.pdf`` beside it with headless Chromium (:func:`report_pdf`);
        a missing Chromium fails before any work.
    shapes_at : sequence of str, optional
        The measured configurations whose mode shapes are drawn on the arm (with ``rig``), in this
        order; default: the first and the last of ``measured``.  Names are checked before any work.

    Returns
    -------
    Path
        The HTML report.

    Raises
    ------
    ReportError
        Nothing to report, a bad band, an output that would replace an input, no Chromium for ``pdf``,
        ``shapes_at`` naming a configuration ``measured`` does not have (or given without ``measured``
        and ``rig``).

    Examples
    --------
    >>> import tempfile
    >>> from pathlib import Path
    >>> import flexmodal as fm
    >>> measured = fm.read_table("examples/measured/seed003_table3_f1f2.csv")
    >>> fe = fm.predict("examples/rigs/seed003_two_link.toml", measured, "fe", 2)
    >>> page = fm.report(Path(tempfile.mkdtemp()) / "report.html", measured=measured, predictions=[fe])
    >>> "Measured and predicted modes" in page.read_text(encoding="utf-8")
    True
    """
    from flexmodal.checked_io.output import output_file
    from flexmodal.reports.errors import ReportError

    if not isinstance(title, str):   # None was printed as the page's title "None"
        raise TypeError(f"report: title must be text (str), got {type(title).__name__} {title!r}")
    from flexmodal.contract.table import ModalTable

    for name, value in (("repeats", repeats), ("predictions", predictions)):
        if isinstance(value, str | bytes | os.PathLike | ModalTable) or not isinstance(value, Iterable):
            raise TypeError(f"report: {name} must be a list of modal tables or paths, got "
                            f"{type(value).__name__} {value!r:.60}: for one table write [...]")
    sources = _paths([*runs, measured, *repeats, *predictions, diagnosis, rig, geometry])
    output_file(out, ReportError, "report (--out)", inputs=sources)
    if pdf:
        from flexmodal.checked_io.output import sidecar_file
        from flexmodal.reports.pdf import PDF_CREATOR, PDF_SIGNATURE, find_chromium

        beside = output_file(Path(out).with_suffix(".pdf"), ReportError, "PDF report (beside --out)",
                             inputs=(*sources, out))
        sidecar_file(beside, ReportError, "PDF file", PDF_SIGNATURE, PDF_CREATOR)   # the user's PDF stays
        if find_chromium() is None:
            raise ReportError("report --pdf: no Chromium found (install chromium, or leave out --pdf)")
    if not (runs or measured is not None or predictions or diagnosis is not None):
        raise ReportError("report: nothing to report (give RUN.h5 files, --measured, --pred or --diagnosis)")
    for name, value in (("oma_fmin", oma_fmin), ("oma_fmax", oma_fmax), ("fmin", fmin), ("fmax", fmax)):
        if value is not None and (isinstance(value, bool) or not isinstance(value, numbers.Real)
                                  or not 0 < value < float("inf")):
            raise ReportError(f"report: {name} = {value!r} must be a positive number of Hz")
    if oma_fmin is not None and oma_fmax is not None and oma_fmin >= oma_fmax:
        raise ReportError(f"report: oma_fmin = {oma_fmin:g} Hz must be below oma_fmax = {oma_fmax:g} Hz")
    if fmin is not None and fmax is not None and fmin >= fmax:
        raise ReportError(f"report: fmin = {fmin:g} Hz must be below fmax = {fmax:g} Hz")
    given = [n for n, v in (("fmin", fmin), ("fmax", fmax), ("oma_fmin", oma_fmin), ("oma_fmax", oma_fmax))
             if v is not None]
    meas = _table(measured) if measured is not None else None
    shapes_at = _shape_configs(shapes_at, meas, rig)
    from flexmodal.daq.run_schema import check_run_file
    from flexmodal.daq.store import expand_runs, run_entries

    runs = run_entries(runs)
    if given and not runs:   # the bands of the runs' identification: with no run, nothing used them
        raise ReportError(f"report: {given[0]} sets the band of the runs' identification, and no run "
                          "(RUN.h5) is given")
    from flexmodal.modal.runs_io import read_frf

    for path, run_id in expand_runs(runs):   # a stored FRF group that is not what flexmodal writes:
        check_run_file(path, run_id)         # refused now, before the heavy imports
        read_frf(path, run_id)
    from flexmodal.compare.tables import compare_tables, ordered_configs, table_name
    from flexmodal.modal.errors import ModalError
    from flexmodal.modal.oma import OmaResults, default_method, output_channels, output_only_results
    from flexmodal.modal.sources import given_unit, identify_frf, si_frf, si_samples
    from flexmodal.reports.html import write_report
    from flexmodal.reports.runs import RunSummary
    from flexmodal.reports.sections import Section, register_section, registered_sections

    if "modal-map" not in registered_sections():
        register_section("modal-map", Section("Modal map of the moving arm", _tracked_map_figures,
                                              needs="a measured table of identify --track (--measured)"))

    geo = None
    if geometry is not None:    # read first: a bad geometry file stops the report before any work
        from flexmodal.reports.geometry import read_uff_geometry

        geo = read_uff_geometry(geometry)
    step = progress or (lambda _msg: None)
    summaries = []
    entries = expand_runs(runs)
    if entries:   # one line for all runs (they are quick; the plotting, slower, says each run)
        files = list(dict.fromkeys(path.name for path, _ in entries))
        step(f"reading and identifying {counted(len(entries), 'run')} of {', '.join(files[:3])}"
             + (f" and {counted(len(files) - 3, 'more file')}" if len(files) > 3 else ""))
    for path, run_id in entries:   # responses stored in different units: in m/s^2, as identify takes them
        run, frf = read_run(path, run_id), read_frf(path, run_id)
        names, kinds = [c.name for c in run.channels], [c.kind for c in run.channels]
        where = f"{path.name}::{run_id}"
        modes = oma = None
        stored = frf
        if frf is not None:
            try:
                frf = si_frf(frf, run.channels, where)
                modes = identify_frf(frf, fmin=fmin, fmax=fmax)
            except ModalError as exc:
                modes = str(exc)
        elif default_method(kinds, run.excitation) == "ssi":
            try:
                samples = si_samples(run.samples, run.channels, output_channels(kinds), where)
            except ModalError as exc:
                oma = OmaResults(tuple(names[j] for j in output_channels(kinds)), str(exc), str(exc))
            else:
                oma = output_only_results(samples, run.sample_rate_hz, names, kinds, fmin=oma_fmin,
                                          fmax=oma_fmax, where=where)
        units = None if frf is stored else tuple(given_unit([c.unit for c in run.channels if c.name in side])
                                                 for side in (frf.outputs, frf.inputs))
        summaries.append(RunSummary(run, frf, modes, oma, frf_units=units))
    named = _named(predictions)
    comparison = None
    if meas is not None and named:
        step("comparing modes")
        comparison = compare_tables(meas, named, measured_name=table_name(meas, "experiment"))
    rig = _rig(rig) if rig is not None else None
    shapes: dict[str, object] = {}
    common = [s.name for s in rig.sensors if s.name in meas.sensors] if rig is not None and meas else []
    if len(common) >= 2:
        from flexmodal.models.arm_shapes import arm_modes

        step("solving the FE model for the mode shapes")
        configs = ordered_configs(meas)
        for config in shapes_at or list(dict.fromkeys([configs[0], configs[-1]]))[:SHAPE_CONFIGS]:
            pose = meas.pose(config)
            missing = [v for v in rig.pose_variables if v not in pose]
            shapes[config] = (f"No mode shapes drawn for {config}: the measured table gives no "
                              f"pose.{missing[0]} for the rig") if missing else arm_modes(rig, pose, common)
    inputs = [path for path, _ in expand_runs(runs)]
    inputs += [t.source for t in ([meas] if meas is not None else []) + [_table(r) for r in repeats]]
    inputs += [t.source for _, t in named]
    inputs += [diagnosis] if isinstance(diagnosis, str | Path) else []
    inputs += [rig.source] if rig is not None else []
    inputs += [geometry] if geometry is not None else []
    page = write_report(out, runs=summaries, comparison=comparison, measured=meas,
                        repeats=[_table(r) for r in repeats], predictions=named, shapes=shapes,
                        diagnosis=_diagnosis(diagnosis) if diagnosis is not None else None,
                        rig_name=getattr(rig, "name", ""), title=title, inputs=inputs, geometry=geo,
                        progress=progress)
    if pdf:
        step("printing to PDF with headless Chromium")
        report_pdf(page)
    return page


def animate_mode(out: PathLike, measured: ModalTable | PathLike, config: str, mode: int = 1, *,
                 rig: Rig | PathLike | None = None, geometry: PathLike | None = None, frames: int = 24,
                 fps: int = 12) -> Path:
    """An animated GIF of one measured mode for slides (matplotlib's PillowWriter).

    Parameters
    ----------
    out : str or Path
        The GIF to write (atomically).
    measured : contract.table.ModalTable, str or Path
        The modal table with ``shape.<sensor>`` columns.
    config : str
        The configuration whose mode is drawn.
    mode : int
        The mode, 1-based.
    rig : models.rig.Rig, str or Path, optional
        Draw the mode at the sensors on the arm beside the frame FE model's best-matching (MAC) mode.
    geometry : str or Path, optional
        Or a Universal File (nodes, trace lines, coordinate systems): the mode on the test structure.
        Give the rig or the geometry.
    frames : int
        Frames per period of the animation.
    fps : int
        Frames per second [1/s].

    Returns
    -------
    Path
        ``out``.

    References
    ----------
    R. J. Allemang and D. L. Brown, "A correlation coefficient for modal vector analysis", Proc. 1st
    International Modal Analysis Conference (IMAC), Orlando, 1982, 110-116 (MAC).

    Examples
    --------
    >>> import tempfile
    >>> from pathlib import Path
    >>> import flexmodal as fm
    >>> from flexmodal.fixtures.rig_sim import DEMO_RIG
    >>> rig = fm.load_rig(DEMO_RIG)
    >>> table = fm.predict(rig, {"theta60": {"theta_deg": 60.0}}, "fe", n_modes=2)
    >>> gif = fm.animate_mode(Path(tempfile.mkdtemp()) / "mode1.gif", table, "theta60", 1, rig=rig)
    >>> gif.read_bytes()[:6]
    b'GIF89a'
    """
    from flexmodal.checked_io.output import output_file
    from flexmodal.reports import animate
    from flexmodal.reports.errors import ReportError

    for name, value, lo, hi in (("mode", mode, 1, 10**6), ("frames", frames, 2, 1000), ("fps", fps, 1, 100)):
        if not isinstance(value, numbers.Integral) or isinstance(value, bool) or not lo <= value <= hi:
            raise ReportError(f"animate_mode: {name} = {value!r} is not a whole number in [{lo}, {hi}]")
    target = output_file(out, ReportError, "GIF (out)", inputs=_paths([measured, rig, geometry]))
    table = _table(measured)
    n = len(table.freq_hz(_config_of(table, config, ReportError)))
    if not 1 <= mode <= n:
        raise ReportError(f"{table.source}: {config} has modes 1..{n}, not {mode}")
    if (rig is None) == (geometry is None):
        raise ReportError("animate_mode: give the rig or a UFF geometry (one of them)")
    if geometry is not None:
        from flexmodal.reports.geometry import read_uff_geometry

        shapes = [animate.geometry_shapes(read_uff_geometry(geometry), table, config)[mode - 1]]
    else:
        from flexmodal.models.arm_shapes import arm_modes

        rig = _rig(rig)
        sensors = [s.name for s in rig.sensors if s.name in table.sensors]
        test, model = animate.arm_pairs(arm_modes(rig, table.pose(config), sensors), table, config)[mode - 1]
        shapes = [s for s in (test, model) if s is not None]
    return animate.write_gif(shapes, target, frames=frames, fps=fps)


def _shape_configs(shapes_at: Sequence[str] | None, meas, rig) -> list[str]:
    """``shapes_at`` of :func:`report` checked: text names of configurations of ``meas`` (a modal table
    or None), with a ``rig`` to draw them on, each once in the order given; [] for None (the default
    choice).  A ReportError in one line names the first bad one and the configurations there are, or
    says the table has no shapes at two of the rig's sensors (nothing would be drawn)."""
    if shapes_at is None:
        return []
    if isinstance(shapes_at, str) or not isinstance(shapes_at, Iterable):
        raise TypeError(f"report: shapes_at must be a list of configuration names, got "
                        f"{type(shapes_at).__name__} {shapes_at!r:.60}: for one write [...]")
    if meas is None or rig is None:
        raise ReportError("report --shapes-at: mode shapes are drawn from the measured table on the rig: "
                          f"give {'--measured' if meas is None else '--rig'} too")
    from flexmodal.compare.tables import ordered_configs

    have = ordered_configs(meas)   # by pose, as the report shows them
    for name in shapes_at:
        if name not in have:
            listed = ", ".join(have[:8]) + (f" and {len(have) - 8} more" if len(have) > 8 else "")
            raise ReportError(f"report --shapes-at {name!r}: no such configuration in "
                              f"{Path(meas.source).name if meas.source else 'the measured table'} "
                              f"(it has {counted(len(have), 'configuration')}: {listed})")
    rig = _rig(rig)
    common = [s.name for s in rig.sensors if s.name in meas.sensors]
    if shapes_at and len(common) < 2:   # the shapes are drawn at two or more of the rig's sensors
        table = Path(meas.source).name if meas.source else "the measured table"
        at = f"only at {common[0]}" if common else "at none"
        names = [s.name for s in rig.sensors]
        listed = ", ".join(names[:6]) + (f" and {len(names) - 6} more" if len(names) > 6 else "")
        raise ReportError(f"report --shapes-at: {table} has mode shapes {at} of the rig's sensors "
                          f"({listed}); two or more are needed to draw them")
    return list(dict.fromkeys(shapes_at))


def report_pdf(html: PathLike, pdf: PathLike | None = None) -> Path:
    """Print an HTML report to PDF with headless Chromium: A4, every run's block opened, tables whole
    with their headers repeated on each page.

    Parameters
    ----------
    html : str or Path
        A report :func:`report` wrote.
    pdf : str or Path, optional
        The PDF to write (default: beside the HTML, ``.pdf``; never the HTML itself).

    Returns
    -------
    Path
        The PDF.

    Raises
    ------
    ReportError
        No Chromium installed (one line).

    Examples
    --------
    >>> import tempfile
    >>> from pathlib import Path
    >>> import flexmodal as fm
    >>> measured = fm.read_table("examples/measured/seed003_table3_f1f2.csv")
    >>> page = fm.report(Path(tempfile.mkdtemp()) / "report.html", measured=measured)
    >>> pdf = fm.report_pdf(page)
    >>> pdf.name, pdf.read_bytes()[:5]
    ('report.pdf', b'%PDF-')
    """
    _path_arg(html, "report_pdf: html")
    from flexmodal.checked_io.output import output_file, sidecar_file
    from flexmodal.reports.errors import ReportError
    from flexmodal.reports.pdf import PDF_CREATOR, PDF_SIGNATURE, print_pdf

    target = output_file(Path(html).with_suffix(".pdf") if pdf is None else pdf, ReportError, "PDF report",
                         inputs=(html,))
    if pdf is None:   # the PDF beside the report replaces a PDF, never another file of the user's
        sidecar_file(target, ReportError, "PDF file", PDF_SIGNATURE, PDF_CREATOR)
    return print_pdf(html, target)


# -- the simulated rig -----------------------------------------------------------------------------

def demo(out_dir: PathLike = "flexmodal-demo", *, rig: PathLike | None = None, quiet: bool = True) -> Path:
    """The main job end to end on the embedded simulated rig (``flexmodal demo``; no hardware).

    Simulates impact and random tests of the demo arm (which hides a compliant elbow) in five poses,
    one of them acquired through the serial stack, and writes ``runs.h5``, ``operational.h5``,
    ``modes.csv``, ``fe.csv``, ``diagnosis.json``/``.html`` and ``report.html`` into ``out_dir``; the
    comparison and the verdict, next to the hidden truth, go to stdout.

    Parameters
    ----------
    out_dir : str or Path
        Output folder (created; its existing outputs are replaced).
    rig : str or Path, optional
        Simulate this rig TOML instead of the demo arm.
    quiet : bool
        No progress bar on stderr.

    Returns
    -------
    Path
        The report.

    Raises
    ------
    FixtureError
        The folder cannot hold the outputs (checked before any work; one line).

    Examples
    --------
    The whole demo takes 20-60 s (tests/test_demo.py runs it); its folder is checked first:

    >>> import flexmodal as fm
    >>> fm.demo("examples/rigs/demo_arm.toml")
    Traceback (most recent call last):
    ...
    flexmodal.fixtures.errors.FixtureError: examples/rigs/demo_arm.toml: exists and is not a directory ...
    """
    from flexmodal.checked_io.output import output_dir
    from flexmodal.fixtures.errors import FixtureError

    out = output_dir(out_dir, FixtureError, "demo folder (--out)")   # before the demo's heavy imports
    from flexmodal.fixtures.demo import OUTPUTS, Writers, run_demo

    tables = [name for name in OUTPUTS if not name.endswith(".h5")]   # the run files are replaced whole
    output_dir(out, FixtureError, "demo folder (--out)", files=tables, inputs=[rig])

    writers = Writers(write_diagnosis, report, format_diagnosis)
    return run_demo(out, writers, None if rig is None else Path(rig), quiet=quiet)


@dataclass(frozen=True)
class SelfCheck:
    """The blind self-check of the diagnosis.

    Parameters
    ----------
    results : tuple of fixtures.blind.BlindResult
        One per simulated case: the case (the effect hidden), the verdict and its time [s].
    summary : mapping
        ``fixtures.blind.summarise``: accuracy fractions in [0, 1] (NaN where a category is absent,
        e.g. ``accepted_accuracy``), counts, ``seconds_per_case`` [s] and the ``misses``.
    text : str
        The summary as ``flexmodal selftest`` prints it.
    """

    results: tuple
    summary: Mapping[str, float]
    text: str


def selftest(n_cases: int, *, seed: int = 0, progress: Callable[[object], None] | None = None) -> SelfCheck:
    """Blind self-check of :func:`diagnose` (``flexmodal diagnose --selftest N``).

    Random rigs are simulated by the independent truth model (a Timoshenko frame, fixtures/truth_arm.py)
    with withheld effects, diagnosed, and the verdicts scored against what was hidden (docs/diagnosis.md).

    Parameters
    ----------
    n_cases : int
        Cases to run, the first of the fixed schedule.
    seed : int
        Random seed of the cases.
    progress : callable, optional
        Called with each case's result as it is done.

    Returns
    -------
    SelfCheck
        ``results`` per case, ``summary`` (accuracies as fractions [0, 1]) and the printed ``text``.

    References
    ----------
    S. P. Timoshenko, "On the correction for shear of the differential equation for transverse
    vibrations of prismatic bars", Philosophical Magazine 41 (1921) 744-746 (the truth model's beam).

    Examples
    --------
    >>> import flexmodal as fm
    >>> check = fm.selftest(1)
    >>> len(check.results), check.text.splitlines()[0]
    (1, 'cases: 1 (1 library effect, 0 none, 0 outside the library)')
    """
    from flexmodal.fixtures.blind import format_summary, run_blind, summarise

    if isinstance(n_cases, bool) or not isinstance(n_cases, numbers.Integral) or n_cases < 1:
        raise FixtureError(f"selftest: n_cases = {n_cases!r} is not a whole number >= 1 (accuracies of no "
                           "case are not numbers)")
    opt.given(seed, opt.seed, "selftest: seed", FixtureError)   # -1 was numpy's ValueError
    results = run_blind(int(n_cases), seed=seed, progress=progress)
    summary = summarise(results)
    return SelfCheck(tuple(results), summary, format_summary(summary))


def serve_simulator(protocol: str, *, faults: Mapping[str, float | None] | None = None, stdout=None,
                    **options: object) -> None:
    """Run a simulated device streaming the simulated rig (``flexmodal sim serve``) until SIGTERM/SIGINT
    or ``duration`` seconds of samples.

    Parameters
    ----------
    protocol : str
        A protocol with a simulator (fixtures.simulators): ``serial`` (a pty), ``can`` (an slcan
        adapter on a pty) or ``modbus`` (TCP on 127.0.0.1, or RTU over a pty pair).
    faults : mapping, optional
        Faults to inject, by the field names of daq.faults.Faults (``corrupt_rate``, ``drop_at_s``
        [s], ...).
    stdout : file, optional
        Where the endpoint (pty path or ``host:port``) is written as the first line (default
        ``sys.stdout``).
    **options
        The other fields of fixtures.sim_serve.ServeOptions: ``rig`` (TOML path; default the demo arm),
        ``test``, ``rate`` [Hz], ``pose`` (degrees, kg), ``seed``, ``effects``
        ("EFFECT@LOCATION:PARAM=VALUE,..."), ``duration`` [s], ``link``, ``port``, ``transport``,
        ``framing``, ``format``, ``scans_per_frame``, ``fault_log``, ``exit_with_parent``, ``quiet``.

    Returns
    -------
    None
        When the device stops (``duration`` reached, SIGTERM or SIGINT).

    Raises
    ------
    FixtureError
        An unknown option or a bad value (one line).

    Examples
    --------
    A serial device on a pty streaming the demo arm for a quarter of a second:

    >>> import io
    >>> import flexmodal as fm
    >>> endpoint = io.StringIO()
    >>> fm.serve_simulator("serial", duration=0.25, stdout=endpoint, quiet=True)
    >>> endpoint.getvalue().startswith("/")     # the pty a session's ``port`` names
    True
    """
    import sys

    from flexmodal.daq.faults import Faults
    from flexmodal.fixtures.errors import FixtureError
    from flexmodal.fixtures.sim_serve import ServeOptions, serve

    if options.get("fault_log"):
        from flexmodal.checked_io.output import output_file

        output_file(options["fault_log"], FixtureError, "fault log (--fault-log)",
                    inputs=(options.get("rig"), options.get("link")))   # the pty link is an output too
    try:
        chosen = ServeOptions(protocol, faults=Faults(**(faults or {})), **options)
    except TypeError as exc:
        raise FixtureError(f"serve_simulator: {exc}") from None
    serve(chosen, stdout or sys.stdout)
