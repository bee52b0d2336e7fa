"""Report figures: every function returns a ``matplotlib.figure.Figure`` (no pyplot, no backend choice, no
rcParams: library code changes no global matplotlib state, so figures display inline in Jupyter and a
user's own mathtext keeps working).  Layouts are constrained (nothing leaves the canvas), log axes are
labelled in plain text (:func:`log_axis`), labels from data escape ``$`` (:func:`text`), phase is drawn
wrapped to ±180° with the line broken at each wrap (:func:`wrapped_phase_deg`).

Units sit on every axis.  Frequencies in Hz, FRF magnitude in the FRF's own unit (accelerance
(m/s²)/N by default), phase in degrees, coherence and MAC dimensionless (0..1), errors in %.

* ``plot_frf``: magnitude, phase and ordinary coherence of the FRFs of one run;
* ``plot_stabilisation``: poles per model order (modal.lscf pLSCF) over the complex mode indicator
  function (CMIF, Shih et al. 1988: singular values of H(f) at each line, modal.peaks.cmif), with the
  poles of the selected modes and the identification band marked;
* ``plot_identification_diagram`` / ``plot_identification_synthesis``: the same for a run's
  identification (a modal.identify.Modes);
* ``plot_synthesis``: measured vs synthesised FRFs (modal.lsfd from the identified modes), with the
  FRAC of each pair;
* ``plot_mac``: AutoMAC of the identified shapes, or test-model MAC matrix;
* ``plot_freq_vs_pose``: measured vs predicted natural frequency across a pose variable, a line per
  model and mode, experiment points with ±1 standard deviation bars from repeated tests;
* ``plot_trends``: frequency of each mode against one pose variable, a line per value of another
  (payload / configuration trends in the style of seed 001);
* ``plot_mode_shapes``: measured shapes at the sensors drawn on the arm geometry at a pose with the
  frame FE model's deformed shape (given as a models.arm_shapes.ArmModes) as a curve;
* ``plot_gap``: the per-mode frequency error before and after a diagnosed effect (docs/formats.md).
"""

from __future__ import annotations

import io
import math
import re
from collections.abc import Mapping, Sequence
from typing import TYPE_CHECKING

import numpy as np
from matplotlib.axis import Axis
from matplotlib.figure import Figure
from matplotlib.ticker import Formatter, LogLocator, NullFormatter

from flexmodal.contract.mac import mac, to_real
from flexmodal.contract.table import ModalTable
from flexmodal.modal.peaks import cmif
from flexmodal.reports.errors import ReportError

if TYPE_CHECKING:
    from flexmodal.compare.result import Diagnosis

FRF_UNITS = {"accelerance": "(m/s²)/N", "mobility": "(m/s)/N", "receptance": "m/N"}
_COLOURS = ("#1f77b4", "#d62728", "#2ca02c", "#9467bd", "#ff7f0e", "#8c564b", "#e377c2", "#17becf")
_SUPERSCRIPT = str.maketrans("-0123456789", "⁻⁰¹²³⁴⁵⁶⁷⁸⁹")


def frf_unit(quantity: str) -> str:
    """Unit of an FRF of the given quantity (accelerance, mobility, receptance), per newton."""
    return FRF_UNITS.get(quantity, "FRF unit")


def unit_text(unit: str) -> str:
    """A unit as a reader expects it, its powers as superscripts: the ``m/s^2`` a run's channels store
    is ``m/s²`` in the report's tables as on its axes.

    Examples
    --------
    >>> unit_text("m/s^2"), unit_text("(m/s**2)^2/Hz"), unit_text("s^-1"), unit_text("µε")
    ('m/s²', '(m/s²)²/Hz', 's⁻¹', 'µε')
    """
    return re.sub(r"(?:\^|\*\*)(-?\d+)", lambda m: m.group(1).translate(_SUPERSCRIPT), unit)


def ratio_unit(out_units: Sequence[str], in_unit: str) -> str:
    """Unit of a response per input from the channels' units: ``("g", "g"), "N"`` -> ``g/N``,
    ``("m/s²",), "N"`` -> ``(m/s²)/N``; ``mixed/N`` when the outputs' units differ.

    Examples
    --------
    >>> ratio_unit(["m/s^2", "m/s^2"], "N")
    '(m/s²)/N'
    >>> ratio_unit(["g"], "lbf")
    'g/lbf'
    """
    units = {unit_text(u) for u in out_units} or {"-"}
    out = units.pop() if len(units) == 1 else "mixed"
    return f"({out})/{in_unit}" if "/" in out else f"{out}/{in_unit}"


def text(label: object) -> str:
    """A label from data (channel, sensor, configuration names) as matplotlib text: a ``$`` in it is
    a dollar sign, not the start of mathtext (per label; no global ``text.parse_math``)."""
    return str(label).replace("$", r"\$")


def tick_text(value: float, powers: bool = False) -> str:
    """A log-axis tick as plain text (no mathtext): 0.01..9999 as decimals, else (or with ``powers``,
    for an axis whose other ticks need them) ``10⁵`` or ``2×10⁻³``.

    Examples
    --------
    >>> [tick_text(v) for v in (0.05, 200.0, 1e5, 2e-3)]
    ['0.05', '200', '10⁵', '2×10⁻³']
    >>> [tick_text(v, powers=True) for v in (0.01, 1.0, 100.0)]
    ['10⁻²', '10⁰', '10²']
    """
    if value <= 0 or not math.isfinite(value):
        return ""
    if not powers and 0.01 <= value < 1e4:
        return f"{value:g}"
    exp = math.floor(math.log10(value) + 1e-9)
    mantissa = round(value / 10.0 ** exp, 6)
    power = "10" + str(exp).translate(_SUPERSCRIPT)
    return power if mantissa == 1 else f"{mantissa:g}×{power}"


class LogTicks(Formatter):
    """Labels of a log axis in plain text (:func:`tick_text`): 1, 2, 3 and 5 of each decade over up
    to two decades (so that 30 and 300 Hz are read off a 25-400 Hz axis), 1, 2 and 5 over up to four,
    decades only over more; all as decimals, or all as powers of ten when one label needs it (an axis
    reading 10⁻³, 0.01, 0.1 mixes two notations)."""

    _ticks: tuple[float, ...] = ()
    _powers: tuple = ((), False)   # (view interval and ticks, whether a labelled tick needs a power)

    def set_locs(self, locs) -> None:
        """Keep the tick values being labelled (the notation is chosen over all of them)."""
        self._ticks = tuple(float(v) for v in locs)

    @staticmethod
    def _labelled(x: float, lo: float, hi: float) -> bool:
        mantissa = x / 10.0 ** math.floor(math.log10(x) + 1e-9) if x > 0 else 0.0
        span = math.log10(hi / lo) if lo > 0 else math.inf
        shown = (1.0, 2.0, 3.0, 5.0) if span <= 2.0 else (1.0, 2.0, 5.0) if span <= 4.0 else (1.0,)
        return any(abs(mantissa - m) < 1e-6 * m for m in shown)

    def __call__(self, x: float, pos: int | None = None) -> str:
        lo, hi = sorted(self.axis.get_view_interval())
        if not self._labelled(x, lo, hi):
            return ""
        key = (lo, hi, self._ticks)
        if self._powers[0] != key:   # once per axis view and set of ticks, not once per tick
            self._powers = (key, any(not 0.01 <= v < 1e4 for v in self._ticks
                                     if lo <= v <= hi and self._labelled(v, lo, hi)))
        return tick_text(x, powers=self._powers[1] or (lo <= x <= hi and not 0.01 <= x < 1e4))


def log_axis(axis: Axis) -> None:
    """Make a log-scaled ``axis`` readable without mathtext: ticks at 1, 2, 3 and 5 per decade labelled
    by :class:`LogTicks`, minor ticks unlabelled."""
    axis.set_major_locator(LogLocator(base=10, subs=(1.0, 2.0, 3.0, 5.0), numticks=40))
    axis.set_major_formatter(LogTicks())
    axis.set_minor_formatter(NullFormatter())


def log_scale_if_positive(ax, values: np.ndarray) -> bool:
    """Put ``ax``'s y axis on a log scale (readable ticks, :func:`log_axis`) when ``values`` [any shape]
    hold a positive finite number, else leave it linear: an FRF or a spectrum that is zero everywhere
    made matplotlib print "Data has no positive values, and therefore cannot be log-scaled" with a
    source line on stderr, under --quiet too.  Returns whether the axis is logarithmic."""
    v = np.asarray(values, float)
    log = bool((np.isfinite(v) & (v > 0)).any())
    if log:
        ax.set_yscale("log")
        log_axis(ax.yaxis)
    return log


def wrapped_phase_deg(H: np.ndarray) -> np.ndarray:
    """Phase of H [deg] wrapped to ±180, NaN at each line where it wraps, so a line drawn through it
    breaks instead of jumping across the axis (the jump reads as corrupt data)."""
    deg = np.degrees(np.angle(H))
    jump = np.abs(np.diff(deg, axis=-1)) > 180.0
    deg[..., 1:][jump] = np.nan
    return deg


def _phase_axis(ax) -> None:
    ax.set_ylim(-185, 185)
    ax.set_yticks([-180, -90, 0, 90, 180])
    ax.set_ylabel("phase (wrapped) [deg]")


def figure_png(fig: Figure, dpi: int = 100) -> bytes:
    """The figure as PNG bytes."""
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=dpi)  # constrained layout: everything inside the canvas
    return buf.getvalue()


def plot_frf(freq_hz: np.ndarray, H: np.ndarray, coherence: np.ndarray | None = None,
             labels: Sequence[str] = (), unit: str = "(m/s²)/N", title: str = "") -> Figure:
    """Magnitude (log), phase [deg] and coherence [-] of FRFs H [n_out, n_freq] (or [n_out, 1, n_freq])."""
    H = np.asarray(H)
    if H.ndim == 3:
        H = H[:, 0, :]
    labels = list(labels) or [f"out {i + 1}" for i in range(H.shape[0])]
    rows = 3 if coherence is not None else 2
    fig = Figure(figsize=(8, 2.2 * rows + 0.9), layout="constrained")
    axes = fig.subplots(rows, 1, sharex=True, gridspec_kw={"height_ratios": [2, 1, 1][:rows]})
    phase = wrapped_phase_deg(H)
    log_scale_if_positive(axes[0], np.abs(H))
    for i, label in enumerate(labels):
        c = _COLOURS[i % len(_COLOURS)]
        axes[0].plot(freq_hz, np.abs(H[i]), color=c, lw=0.9, label=text(label))
        axes[1].plot(freq_hz, phase[i], color=c, lw=0.7)
        if coherence is not None:
            axes[2].plot(freq_hz, np.asarray(coherence)[i], color=c, lw=0.7)
    axes[0].set_ylabel(f"|H| [{text(unit)}]")
    _phase_axis(axes[1])
    if coherence is not None:
        axes[2].set_ylabel("coherence [-]")
        axes[2].set_ylim(0, 1.05)
    axes[-1].set_xlabel("frequency [Hz]")
    fig.legend(*axes[0].get_legend_handles_labels(), loc="outside lower center", fontsize=7,
               ncol=min(len(labels), 6))
    for ax in axes:
        ax.grid(True, which="both", alpha=0.3)
    if title:
        axes[0].set_title(text(title))
    return fig


def plot_stabilisation(freq_hz: np.ndarray, H: np.ndarray, poles, unit: str = "(m/s²)/N",
                       title: str = "", selected: np.ndarray | None = None,
                       band_hz: tuple[float, float] | None = None,
                       modes_hz: np.ndarray | None = None, spectrum_name: str = "CMIF") -> Figure:
    """Stable (filled) and unstable (open) poles per model order over the CMIF of H [n_out, n_in, n_freq].

    ``poles``: a ``modal.lscf.Stabilisation`` (or anything with equal-length ``order``, ``freq_hz`` [Hz]
    and boolean ``stable`` arrays).  ``selected`` [n_poles] marks the poles of the chosen modes (black
    crosses), ``modes_hz`` the identified frequencies (dotted lines), ``band_hz`` the identification
    band (shaded); ``spectrum_name`` labels the singular-value axis (right).
    """
    stable = np.asarray(poles.stable, bool)
    if not np.size(poles.order) == np.size(poles.freq_hz) == stable.size:
        raise ReportError("stabilisation: order, freq_hz and stable differ in length")
    if selected is not None and np.size(selected) != stable.size:
        raise ReportError("stabilisation: the selected-pole mask differs in length from the poles")
    fig = Figure(figsize=(8, 4.6), layout="constrained")
    ax = fig.subplots()
    if band_hz is not None:
        ax.axvspan(*band_hz, color=_COLOURS[2], alpha=0.08, lw=0, label="identification band")
    ax.plot(poles.freq_hz[~stable], poles.order[~stable], "o", mfc="none", mec="0.6", ms=4,
            label="unstable pole")
    ax.plot(poles.freq_hz[stable], poles.order[stable], "o", color=_COLOURS[1], ms=4, label="stable pole")
    if selected is not None:
        sel = np.asarray(selected, bool)
        ax.plot(poles.freq_hz[sel], poles.order[sel], "x", color="k", ms=5, mew=1.0,
                label="pole of a selected mode")
    for k, f in enumerate(np.atleast_1d(modes_hz) if modes_hz is not None else []):
        ax.axvline(float(f), color="k", lw=0.6, ls=":", label="identified mode" if k == 0 else None)
    ax.set_xlabel("frequency [Hz]")
    ax.set_ylabel("model order [-]")
    mif_ax = ax.twinx()
    singular = cmif(H)
    log_scale_if_positive(mif_ax, singular)
    for k, sv in enumerate(singular):
        mif_ax.plot(freq_hz, sv, color=_COLOURS[0], lw=1.0 if k == 0 else 0.6,
                        alpha=1.0 if k == 0 else 0.5,
                        label=(spectrum_name if "singular values" in spectrum_name
                               else f"{spectrum_name} (singular values)") if k == 0 else None)
    mif_ax.set_ylabel(f"{spectrum_name} [{text(unit)}]", color=_COLOURS[0])
    ax.set_xlim(float(np.min(freq_hz)), float(np.max(freq_hz)))
    handles, names = ax.get_legend_handles_labels()
    more, more_names = mif_ax.get_legend_handles_labels()
    fig.legend(handles + more, names + more_names, loc="outside lower center", fontsize=7, ncol=3)
    if title:
        ax.set_title(text(title))
    return fig


def plot_synthesis(freq_hz: np.ndarray, H: np.ndarray, synthesis: np.ndarray,
                   labels: Sequence[str] = (), correlation: np.ndarray | None = None,
                   unit: str = "(m/s²)/N", title: str = "", max_frfs: int = 6) -> Figure:
    """Measured (solid) and synthesised (dashed, from the identified modes and residuals) FRFs:
    magnitude (log) and phase [deg] of up to ``max_frfs`` FRFs of H, synthesis [n_out, n_in, n_freq]
    (first reference), with each FRF's measured-vs-synthesised FRAC [-] in the legend."""
    H, S = np.asarray(H), np.asarray(synthesis)
    if H.shape != S.shape or H.shape[-1] != np.size(freq_hz):
        raise ReportError(f"synthesis: FRFs {H.shape}, synthesis {S.shape} and {np.size(freq_hz)} lines "
                          "differ")
    H, S = H[:, 0, :], S[:, 0, :]
    labels = list(labels) or [f"out {i + 1}" for i in range(H.shape[0])]
    fig = Figure(figsize=(8, 5.6), layout="constrained")
    mag, ph = fig.subplots(2, 1, sharex=True, gridspec_kw={"height_ratios": [2, 1]})
    shown = min(max_frfs, H.shape[0])
    ph_meas, ph_syn = wrapped_phase_deg(H[:shown]), wrapped_phase_deg(S[:shown])
    log_scale_if_positive(mag, np.abs(np.concatenate([H[:shown], S[:shown]])))
    for i in range(shown):
        c = _COLOURS[i % len(_COLOURS)]
        corr = f" (FRAC {float(np.asarray(correlation)[i, 0]):.3f})" if correlation is not None else ""
        mag.plot(freq_hz, np.abs(H[i]), color=c, lw=0.9, label=f"{text(labels[i])} measured{corr}")
        mag.plot(freq_hz, np.abs(S[i]), color=c, lw=1.1, ls="--", label=f"{text(labels[i])} synthesised")
        ph.plot(freq_hz, ph_meas[i], color=c, lw=0.7)
        ph.plot(freq_hz, ph_syn[i], color=c, lw=0.9, ls="--")
    mag.set_ylabel(f"|H| [{text(unit)}]")
    _phase_axis(ph)
    ph.set_xlabel("frequency [Hz]")
    fig.legend(*mag.get_legend_handles_labels(), loc="outside lower center", fontsize=7, ncol=3)
    for ax in (mag, ph):
        ax.grid(True, which="both", alpha=0.3)
    if title:
        mag.set_title(text(title))
    return fig


def plot_mac(phi_a: np.ndarray, phi_b: np.ndarray | None = None, labels_a: Sequence[str] = (),
             labels_b: Sequence[str] = (), name_a: str = "mode", name_b: str = "mode",
             title: str = "") -> Figure:
    """MAC matrix [-] (Allemang & Brown 1982) of shapes ``phi_a`` [n_points, n_a] against ``phi_b``
    (default: itself, the AutoMAC), as a grey-scale grid with the values written in."""
    a = np.atleast_2d(np.asarray(phi_a))
    b = a if phi_b is None else np.atleast_2d(np.asarray(phi_b))
    if a.shape[0] != b.shape[0]:
        raise ReportError(f"MAC: shapes at {a.shape[0]} and {b.shape[0]} points cannot be compared")
    m = mac(np.nan_to_num(a), np.nan_to_num(b))
    la = list(labels_a) or [str(k + 1) for k in range(m.shape[0])]
    lb = list(labels_b) or ([*la] if phi_b is None else [str(k + 1) for k in range(m.shape[1])])
    size = 2.2 + 0.45 * max(m.shape)
    fig = Figure(figsize=(min(size + 1.2, 9), min(size, 8)), layout="constrained")
    ax = fig.subplots()
    im = ax.imshow(m, vmin=0, vmax=1, cmap="Greys", origin="upper")
    for (i, j), v in np.ndenumerate(m):
        ax.text(j, i, f"{v:.2f}" if np.isfinite(v) else "–",   # "–": a zero shape, MAC undefined
                ha="center", va="center", fontsize=7, color="w" if v > 0.5 else "k")
    ax.set_xticks(range(m.shape[1]), [text(t) for t in lb], rotation=45 if max(len(t) for t in lb) > 4 else 0,
                  fontsize=7, ha="right" if max(len(t) for t in lb) > 4 else "center")
    ax.set_yticks(range(m.shape[0]), [text(t) for t in la], fontsize=7)
    ax.set_xlabel(text(name_b))
    ax.set_ylabel(text(name_a))
    fig.colorbar(im, ax=ax, label="MAC [-]", fraction=0.046, pad=0.04)
    ax.set_title(text(title) if title else ("AutoMAC" if phi_b is None else "MAC"), fontsize=9)
    return fig



def plot_gap_vs_pose(diagnosis: Diagnosis, pose: Mapping[str, float], pose_label: str) -> Figure | None:
    """Each mode's relative frequency error ``f_model / f_measured - 1`` [%] against a pose variable, one
    panel per mode: the nominal model (grey circles) and with the diagnosed effect (blue squares, on the
    configurations :meth:`Diagnosis.after_hz` judges it on), so a reviewer sees where along the pose the
    gap lies and what the effect leaves.

    Parameters
    ----------
    diagnosis : flexmodal.compare.result.Diagnosis
        A diagnosis with its ``predictions`` (measured, nominal and best-candidate frequencies [Hz]).
    pose : Mapping[str, float]
        Each configuration's value of the pose variable, in the unit ``pose_label`` names (deg for
        ``theta_deg``); configurations missing here are left out.
    pose_label : str
        The horizontal axis's label with its unit (``theta_deg [deg]``).

    Returns
    -------
    matplotlib.figure.Figure or None
        One panel per mode, vertical axis the relative frequency error [%]; None when the diagnosis
        carries no frequencies or no configuration has a pose.

    Examples
    --------
    >>> import flexmodal as fm
    >>> result = fm.diagnose("examples/rigs/seed003_two_link.toml",
    ...                      "examples/measured/seed003_table3_f1f2.csv", effects="joint_stiffness",
    ...                      holdout="theta30,theta90,theta150")   # one candidate
    >>> pose = {c: float(c.removeprefix("theta")) for c in result.predictions.measured_hz}
    >>> fig = plot_gap_vs_pose(result, pose, "theta_deg [deg]")
    >>> [ax.get_title() for ax in fig.axes]
    ['mode 1', 'mode 2']
    >>> x, y = fig.axes[0].get_lines()[1].get_data()   # the nominal model (after the zero line)
    >>> pred = result.predictions
    >>> bool(x[0] == 0.0 and abs(y[0] - 100 * (pred.baseline_hz["theta0"][0] / 25.5 - 1)) < 1e-12)
    True
    >>> plot_gap_vs_pose(result, {}, "theta_deg [deg]") is None   # no configuration has a pose
    True
    """
    pred = diagnosis.predictions
    configs = [c for c in pred.measured_hz if c in pose] if pred is not None else []
    if not configs:
        return None
    n = max(len(pred.measured_hz[c]) for c in configs)
    after = diagnosis.after_hz()
    held = after is not None and after is pred.best_heldout_hz

    def errors(table: Mapping[str, Sequence[float | None]] | None, k: int) -> tuple[np.ndarray, np.ndarray]:
        pts = [(pose[c], 100 * (table[c][k] / pred.measured_hz[c][k] - 1)) for c in configs
               if table is not None and c in table and k < min(len(table[c]), len(pred.measured_hz[c]))
               and table[c][k] is not None and pred.measured_hz[c][k] is not None]
        return (np.array([x for x, _ in pts], float), np.array([y for _, y in pts], float))

    fig = Figure(figsize=(min(2.6 * n + 0.8, 9.0), 3.2), layout="constrained")   # read at 700-900 px
    axes = np.atleast_1d(fig.subplots(1, n, sharex=True, sharey=True))   # one [%] scale, labelled once
    for k, ax in enumerate(axes):
        ax.axhline(0.0, color="k", lw=0.6)
        ax.plot(*errors(pred.baseline_hz, k), "o", color="0.55", ms=4, label="nominal model")
        if after is not None:
            how = "held out" if held else "fitted to all"
            ax.plot(*errors(after, k), "s", color=_COLOURS[0], ms=4,
                    label=text(f"with {diagnosis.verdict.effect} ({how})"))
        ax.set_title(f"mode {k + 1}", fontsize=9)
        ax.set_xlabel(text(pose_label))
        ax.grid(True, alpha=0.3)
    axes[0].set_ylabel("relative frequency error [%]")
    fig.legend(*axes[0].get_legend_handles_labels(), loc="outside lower center", fontsize=8, ncol=2)
    return fig


def _identified_band(frf, modes) -> np.ndarray:
    """Lines of the FRFs ``frf`` inside the band ``modes`` were identified in (above 0 Hz)."""
    if modes.stabilisation is None or modes.band_freq_hz is None:
        raise ReportError(f"no stabilisation diagram: the modes were identified by {modes.method!r}")
    lo, hi = float(modes.band_freq_hz.min()), float(modes.band_freq_hz.max())
    return (frf.freq_hz >= lo) & (frf.freq_hz <= hi) & (frf.freq_hz > 0)


def plot_identification_diagram(frf, modes, unit: str = "(m/s²)/N", title: str = "") -> Figure:
    """The stabilisation diagram of an identification (``modes``: a ``modal.identify.Modes`` of the
    pLSCF method) over the CMIF of the FRFs ``frf`` (a ``modal.frf.FrfResult``) above 0 Hz, with the
    poles of the selected modes, the identified frequencies and the identification band marked."""
    f = frf.freq_hz[_identified_band(frf, modes)]
    shown = frf.freq_hz > 0   # the whole measured range, the identification band shaded in it
    return plot_stabilisation(frf.freq_hz[shown], frf.H[..., shown], modes.stabilisation, unit, title=title,
                              selected=modes.selected, band_hz=(float(f.min()), float(f.max())),
                              modes_hz=modes.freq_hz)


def plot_identification_synthesis(frf, modes, unit: str = "(m/s²)/N", title: str = "") -> Figure:
    """:func:`plot_synthesis` of an identification's synthesised FRFs against the measured ones."""
    band = _identified_band(frf, modes)
    return plot_synthesis(frf.freq_hz[band], frf.H[..., band], modes.synthesis, frf.outputs,
                          modes.frf_synthesis_corr, unit, title=title)

def _pose_values(table: ModalTable, pose_var: str) -> dict[str, float]:
    col = "pose." + pose_var
    if col not in table.frame:
        raise ReportError(f"{table.source}: no column {col!r} to plot against")
    return {c: float(table.rows(c)[col].iloc[0]) for c in table.configs}


def _experiment_stats(measured: Sequence[ModalTable], pose_var: str):
    """Per (pose value, mode): mean frequency [Hz] and standard deviation over repeated tests [Hz]."""
    import pandas as pd

    frames = []
    for t in measured:
        x = _pose_values(t, pose_var)
        cols = ["config", "mode", "freq_hz"] + (["freq_sd_hz"] if "freq_sd_hz" in t.frame else [])
        df = t.frame[cols].copy()
        df["x"] = df["config"].map(x)
        frames.append(df)
    df = pd.concat(frames)
    stats = df.groupby(["mode", "x"])["freq_hz"].agg(["mean", "std", "count"]).reset_index()
    if "freq_sd_hz" in df:  # a table that already holds the repeatability (mean and sd per mode)
        sd = df.groupby(["mode", "x"])["freq_sd_hz"].mean().reset_index(drop=True)
        stats["std"] = np.where(stats["count"] > 1, stats["std"], sd)
    stats["std"] = stats["std"].fillna(0.0)
    return stats


def experiment_words(measured: Sequence[ModalTable], pose_var: str) -> str:
    """What the experiment points of :func:`plot_freq_vs_pose` are, for a caption: the mean ± 1 standard
    deviation over how many tests at each value of ``pose_var`` (tables at the same pose, and
    configurations at the same pose within a table, are repeats), or the ``freq_sd_hz`` a table gives.

    Examples
    --------
    >>> from flexmodal.contract.table import ModalTable
    >>> rows = [{"config": c, "mode": 1, "freq_hz": f, "pose.theta_deg": t}
    ...         for c, f, t in [("a-impact", 10.0, 0), ("a-random", 10.2, 0), ("b", 12.0, 30)]]
    >>> experiment_words([ModalTable.from_records(rows)], "theta_deg")
    'experiment mean ± 1 standard deviation over the 1 to 2 tests at each pose'
    """
    stats = _experiment_stats(measured, pose_var)
    lo, hi = int(stats["count"].min()), int(stats["count"].max())
    stated = any("freq_sd_hz" in t.frame for t in measured)
    if hi == 1:
        return ("experiment mean ± 1 standard deviation as the table states it (freq_sd_hz)" if stated
                else "experiment: one test at each pose (no error bar)")
    n = f"{hi}" if lo == hi else f"{lo} to {hi}"
    return f"experiment mean ± 1 standard deviation over the {n} tests at each pose"


def plot_freq_vs_pose(measured: Sequence[ModalTable], predictions: Sequence[tuple[str, ModalTable]],
                      pose_var: str, unit: str = "deg", title: str = "") -> Figure:
    """Natural frequency [Hz] against ``pose.<pose_var>``: a line per model and mode, experiment points.

    ``measured`` may hold repeated tests (several tables over the same configurations): points are the
    mean, error bars ±1 sample standard deviation (or a ``freq_sd_hz`` column when given).
    """
    fig = Figure(figsize=(8, 4.5), layout="constrained")
    ax = fig.subplots()
    for k, (name, table) in enumerate(predictions):
        x = _pose_values(table, pose_var)
        df = table.frame.assign(x=table.frame["config"].map(x)).sort_values("x")
        colour = _COLOURS[(k + 1) % len(_COLOURS)]
        for j, (mode, g) in enumerate(df.groupby("mode")):
            ax.plot(g["x"], g["freq_hz"], "-", color=colour, lw=1.2, label=text(name) if j == 0 else None)
            if k == 0:
                ax.annotate(f"mode {mode}", (g["x"].iloc[-1], g["freq_hz"].iloc[-1]), xytext=(4, 0),
                            textcoords="offset points", fontsize=7, va="center")
    if measured:
        stats = _experiment_stats(measured, pose_var)
        ax.errorbar(stats["x"].to_numpy(float), stats["mean"].to_numpy(float),
                    yerr=stats["std"].to_numpy(float), fmt="o", color="k", ms=4, capsize=3,
                    label="experiment (mean ± 1 sd)" if (stats["std"] > 0).any() else "experiment")
    ax.set_xlabel(f"{text(pose_var)} [{text(unit)}]")
    ax.set_ylabel("natural frequency [Hz]")
    ax.set_yscale("log")
    log_axis(ax.yaxis)
    ax.margins(x=0.08)
    ax.grid(True, which="both", alpha=0.3)
    fig.legend(*ax.get_legend_handles_labels(), loc="outside lower center", fontsize=8, ncol=4)
    if title:
        ax.set_title(text(title))
    return fig


def plot_trends(table: ModalTable, x_var: str, group_var: str | None = None, x_unit: str = "kg",
                group_unit: str = "deg", title: str = "") -> Figure:
    """Frequency [Hz] of each mode against ``pose.<x_var>``, a line per value of ``pose.<group_var>``."""
    x = _pose_values(table, x_var)
    groups = _pose_values(table, group_var) if group_var else dict.fromkeys(table.configs, 0.0)
    df = table.frame.assign(x=table.frame["config"].map(x), g=table.frame["config"].map(groups))
    modes = sorted(df["mode"].unique())
    cols = min(3, len(modes))
    rows = math.ceil(len(modes) / cols)
    fig = Figure(figsize=(3.2 * cols, 2.6 * rows + 0.4), layout="constrained")
    axes = np.atleast_1d(fig.subplots(rows, cols, squeeze=False)).ravel()
    for ax, mode in zip(axes, modes, strict=False):
        sub = df[df["mode"] == mode]
        for k, (gval, g) in enumerate(sub.groupby("g")):
            g = g.sort_values("x")
            label = text(f"{group_var} = {gval:g} {group_unit}") if group_var else None
            ax.plot(g["x"], g["freq_hz"], "o-", ms=3, color=_COLOURS[k % len(_COLOURS)], label=label)
        ax.set_title(f"mode {mode}", fontsize=9)
        ax.set_xlabel(f"{text(x_var)} [{text(x_unit)}]")
        ax.set_ylabel("frequency [Hz]")
        ax.grid(True, alpha=0.3)
    for ax in axes[len(modes):]:
        ax.set_visible(False)
    if group_var:
        axes[0].legend(fontsize=8)
    if title:
        fig.suptitle(text(title))
    return fig


def plot_mode_shapes(arm, measured: ModalTable, config: str, title: str = "") -> Figure:
    """Measured mode shapes of ``config`` at the sensors drawn on the arm, with the FE model's curve.

    ``arm``: a ``models.arm_shapes.ArmModes`` (the FE modes at that configuration's pose, sampled along
    the links and at the sensors whose shapes are drawn).  For every measured mode the FE mode with the
    highest MAC at the sensors is drawn as the deformed links, scaled by least squares onto the measured
    points; both show displacement normal to each link (axial sensors are drawn along their link).
    Displacements are exaggerated to 15 % of the arm's reach; coordinates in m.
    """
    if len(arm.sensor_names) < 2:
        raise ReportError(f"{measured.source}: needs shapes at two or more of the rig's sensors to draw")
    curve_xy = np.concatenate(arm.link_xy)
    shapes = measured.shapes(config, list(arm.sensor_names))
    freqs = measured.freq_hz(config)
    macs = mac(np.nan_to_num(shapes), arm.sensor_disp)
    real_shapes = to_real(np.nan_to_num(shapes))
    reach = float(np.ptp(curve_xy, axis=0).max()) or 1.0

    n = shapes.shape[1]
    cols = min(3, n)
    rows = math.ceil(n / cols)
    fig = Figure(figsize=(3.4 * cols, 3.0 * rows + 0.9), layout="constrained")
    axes = np.atleast_1d(fig.subplots(rows, cols, squeeze=False)).ravel()
    for k, ax in enumerate(axes[:n]):
        meas = real_shapes[:, k]
        j = int(np.argmax(np.nan_to_num(macs[k], nan=-1.0)))   # a zero shape: MAC undefined
        model = arm.sensor_disp[:, j]
        alpha = float(model @ meas / (model @ model)) if model @ model > 0 else 0.0
        disp = [alpha * d[:, j] for d in arm.link_disp]
        biggest = max(float(np.abs(meas).max()), max(float(np.abs(d).max()) for d in disp), 1e-30)
        scale = 0.15 * reach / biggest
        ax.plot(curve_xy[:, 0], curve_xy[:, 1], color="0.75", lw=2, label="undeformed arm")
        for i, (xy, d) in enumerate(zip(arm.link_xy, disp, strict=True)):
            ax.plot(*(xy + scale * d[:, None] * arm.link_normal[i]).T, color=_COLOURS[0], lw=1.3,
                    label="FE model, best-matching mode" if i == 0 else None)
        pts = arm.sensor_xy + scale * meas[:, None] * arm.sensor_dir
        ax.plot(pts[:, 0], pts[:, 1], "o", color=_COLOURS[1], ms=5, label="measured")
        ax.set_title(f"mode {k + 1}: {freqs[k]:.2f} Hz\nFE mode {j + 1}: {arm.freq_hz[j]:.1f} Hz, "
                     f"MAC {macs[k, j]:.2f} [-]", fontsize=9)
        ax.set_aspect("equal", adjustable="datalim")
        ax.set_xlabel("x [m]")
        ax.set_ylabel("y [m]")
        ax.grid(True, alpha=0.3)
    for ax in axes[n:]:
        ax.set_visible(False)
    fig.legend(*axes[0].get_legend_handles_labels(), loc="outside lower center", fontsize=9, ncol=3)
    fig.suptitle(text(title or f"{config}: mode shapes (displacement exaggerated)"))
    return fig


def gap_per_mode(diagnosis: Diagnosis) -> tuple[list[str], np.ndarray, np.ndarray | None]:
    """Modes, per-mode relative error [fraction] of the nominal model and with the verdict's effect,
    like for like: both over the configurations the effect is judged on (``Diagnosis.per_mode_before``
    and ``per_mode_after``: held out, or its fit to all when none was held out; before only, over every
    configuration, without a best candidate: after None), NaN where there is none."""
    before, after = diagnosis.per_mode_before(), diagnosis.per_mode_after()
    modes = sorted(diagnosis.baseline.per_mode, key=lambda m: (len(m), m))

    def values(per_mode: Mapping[str, float | None]) -> np.ndarray:
        return np.array([np.nan if per_mode.get(m) is None else per_mode[m] for m in modes], float)

    return modes, values(before), values(after) if after is not None else None


def plot_gap(diagnosis: Diagnosis, title: str = "") -> Figure:
    """Bars of the per-mode RMS relative frequency error [%] before and after the diagnosed effect, and the
    held-out RMS error [%] before and after (docs/formats.md ``verdict``)."""
    modes, before, after = gap_per_mode(diagnosis)
    verdict = diagnosis.verdict
    fig = Figure(figsize=(8, 3.8), layout="constrained")
    ax, ax2 = fig.subplots(1, 2, gridspec_kw={"width_ratios": [3, 1]})
    x = np.arange(len(modes))
    w = 0.4 if after is not None else 0.6
    shift = w / 2 if after is not None else 0.0
    held = after is not None and diagnosis.after_hz() is diagnosis.predictions.best_heldout_hz
    where = ("" if after is None else " (on the held-out configurations)" if held
             else " (on every configuration)")
    bars = [ax.bar(x - shift, 100 * before, w, color="0.6", label=f"nominal model{where}")]
    if after is not None:
        bars.append(ax.bar(x + w / 2, 100 * after, w, color=_COLOURS[0],
                           label=text(f"with {verdict.effect} ({'held out' if held else 'fitted to all'})")))
    for container in bars:
        ax.bar_label(container, fmt="{:.3g} %", fontsize=7)
    ax.set_xticks(x, [f"mode {m}" for m in modes])
    ax.set_ylabel("RMS frequency error [%]")
    fig.legend(*ax.get_legend_handles_labels(), loc="outside lower center", fontsize=7, ncol=2)
    ax.grid(True, axis="y", alpha=0.3)
    totals = [verdict.heldout_rms_rel_error_before, verdict.heldout_rms_rel_error_after]
    if all(v is not None for v in totals):
        ax2.bar_label(ax2.bar([0, 1], [100 * float(v) for v in totals], color=["0.6", _COLOURS[0]]),
                      fmt="{:.3g} %", fontsize=7)
        ax2.set_xticks([0, 1], ["before", "after"])
        ax2.set_ylabel("held-out RMS error [%]")
        ax2.grid(True, axis="y", alpha=0.3)
    else:
        ax2.set_visible(False)
    named = f"{verdict.effect} at {verdict.location}" if verdict.location else verdict.effect
    fig.suptitle(text(title or f"gap per mode: {named}"))
    return fig
