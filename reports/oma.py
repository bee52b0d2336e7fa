"""Report figures of output-only (operational) runs, drawn from the results the caller computed
(``modal.oma.OmaResults``, :func:`flexmodal.modal.oma.output_only_results`): the FDD singular values of
the output cross-spectral matrix with the picked peaks, and the SSI-cov stabilisation diagram drawn over
the singular values of the outputs' cross-spectral matrix with SSI's references
(:func:`flexmodal.reports.plots.plot_stabilisation`).  Units: frequency Hz, spectral densities in the
outputs' unit squared per Hz (m/s² -> (m/s²)²/Hz), model order dimensionless."""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np
from matplotlib.figure import Figure
from matplotlib.transforms import offset_copy

from flexmodal.modal.stability import (
    SSI_MPC_MIN,
    SSI_MPD_MAX_DEG,
    SSI_STABLE_DAMPING_REL,
    SSI_ZETA_MAX,
    STABLE_FREQ_REL,
)
from flexmodal.reports.plots import _COLOURS, log_scale_if_positive, plot_stabilisation, text
from flexmodal.reports.stabilisation_caption import shape_clause

if TYPE_CHECKING:
    from flexmodal.modal.fdd import FddResult
    from flexmodal.modal.oma import OmaResults
    from flexmodal.modal.ssi import SsiResult


def plot_fdd(result: FddResult, unit: str = "(m/s²)²/Hz", title: str = "") -> Figure:
    """Singular values of the output cross-spectral matrix [unit] against frequency [Hz], largest first,
    with the identified modes marked (Brincker et al. 2001): a dashed line at each, its frequency
    written above the plot (:func:`label_peaks`, clear of the peaks and of each other), the legend
    beside it."""
    fig = Figure(figsize=(8, 3.8), layout="constrained")
    ax = fig.subplots()
    log_scale_if_positive(ax, np.asarray(result.singular_values)[:, 1:])
    for k, sv in enumerate(result.singular_values):
        ax.plot(result.freq_hz[1:], sv[1:], color=_COLOURS[k % len(_COLOURS)], lw=1.0 if k == 0 else 0.6,
                label=f"s{k + 1}")
    for f in result.modes.freq_hz:
        ax.axvline(f, color="0.4", lw=0.6, ls="--")
    ax.set_xlabel("frequency [Hz]")
    ax.set_ylabel(f"singular values of G_yy [{text(unit)}]")
    ax.set_xlim(float(result.freq_hz[1]), float(result.freq_hz[-1]))
    height_pt = label_peaks(ax, result.modes.freq_hz, axes_width_in=0.78 * fig.get_figwidth())
    ax.legend(loc="upper left", bbox_to_anchor=(1.01, 1.0), borderaxespad=0.0, fontsize=7,
              ncol=1 + len(result.singular_values) // 9)
    if title:
        ax.set_title(text(title), pad=height_pt + 4.0)
    return fig


def label_peaks(ax, freq_hz: np.ndarray, axes_width_in: float, fontsize: float = 7.0) -> float:
    """Write each frequency [Hz] of ``freq_hz`` (``"52.55 Hz"``, upright) in a band above ``ax``, each
    joined to its place on the top edge by a short leader, so no label covers a peak; labels closer
    than their own width (at ``axes_width_in`` [in] of axes width) are moved apart as little as
    possible, in order (least squares under the minimum spacing: an isotonic regression,
    scipy.optimize.isotonic_regression).  Returns the band's height [pt] (a title goes above it).

    Examples
    --------
    >>> from matplotlib.figure import Figure
    >>> ax = Figure().subplots()
    >>> _ = ax.set_xlim(0.0, 100.0)
    >>> height = label_peaks(ax, np.array([50.0, 50.5, 90.0]), axes_width_in=5.0)
    >>> [round(float(t.xyann[0]), 3) for t in ax.texts]   # the close pair pulled apart about 50.25 Hz
    [0.489, 0.516, 0.9]
    """
    from scipy.optimize import isotonic_regression

    freq_hz = np.sort(np.asarray(freq_hz, dtype=float))
    if freq_hz.size == 0:
        return 0.0
    lo, hi = ax.get_xlim()
    at = (freq_hz - lo) / (hi - lo)                       # places on the top edge, axes fraction
    n = at.size
    gap = min(1.4 * fontsize / 72.0 / axes_width_in, 1.0 / n)   # a rotated label's width, with air
    steps = gap * np.arange(n)
    x = np.clip(isotonic_regression(at - steps).x, 0.0, 1.0 - steps[-1]) + steps
    lift_pt = 8.0                                         # the leader's height
    above = offset_copy(ax.transAxes, fig=ax.figure, y=lift_pt, units="points")
    labels = [f"{f:.4g} Hz" for f in freq_hz]
    for label, a, b in zip(labels, at, x, strict=True):
        ax.annotate(label, xy=(a, 1.0), xycoords="axes fraction", xytext=(b, 1.0), textcoords=above,
                    fontsize=fontsize, rotation=90, ha="center", va="bottom", annotation_clip=False,
                    arrowprops={"arrowstyle": "-", "color": "0.4", "lw": 0.6, "shrinkA": 0, "shrinkB": 1,
                                "relpos": (0.5, 0.0)})
    return lift_pt + 0.62 * fontsize * max(len(s) for s in labels)


def plot_ssi_stabilisation(result: SsiResult, freq_hz: np.ndarray, spectrum: np.ndarray,
                           unit: str = "(m/s²)²/Hz", title: str = "") -> Figure:
    """SSI-cov poles per model order (filled: stable in frequency, damping and shape) over the singular
    values of the cross-spectral matrix ``spectrum`` [n_freq, n_outputs, n_refs] on ``freq_hz`` [Hz]."""
    return plot_stabilisation(freq_hz, np.moveaxis(spectrum, 0, -1), result.stabilisation, unit, title=title,
                              spectrum_name="FDD singular values")


def oma_figures(oma: OmaResults, label: str, unit: str = "(m/s²)²/Hz") -> list[tuple[Figure | None, str]]:
    """The FDD and SSI figures of an output-only record, each with its caption (a figure of None with
    the reason in the caption when the method found nothing)."""
    out: list[tuple[Figure | None, str]] = []
    if isinstance(oma.fdd, str):
        out.append((None, f"{label}: no FDD ({oma.fdd})"))
    else:
        out.append((plot_fdd(oma.fdd, unit, title=label), f"{label}: FDD, singular values of the output "
                    f"cross-spectral matrix ({', '.join(oma.outputs)}); "
                    f"peaks {_listed(oma.fdd.modes.freq_hz)}"))
    if isinstance(oma.ssi, str):
        out.append((None, f"{label}: no SSI ({oma.ssi})"))
        return out
    modes = _listed(oma.ssi.modes.freq_hz)
    if oma.spectrum is None or oma.spectrum_hz is None:
        out.append((None, f"{label}: SSI-cov modes {modes} (unscaled shapes); no stabilisation diagram "
                          "drawn: no segment of the record is free of gaps for its spectrum"))
        return out
    shape = shape_clause(oma.ssi.shapes.shape[0])   # rows: the SSI channels
    orders = f"{oma.ssi.stabilisation.order.min()}-{oma.ssi.stabilisation.order.max()}"
    out.append((plot_ssi_stabilisation(oma.ssi, oma.spectrum_hz, oma.spectrum, unit, title=label),
                f"{label}: SSI-cov stabilisation diagram, orders {orders} against frequency [Hz] (left axis: "
                f"model order [-], right: the FDD singular values [{unit}], log scale). Filled dots: poles "
                f"stable from one order to the next (frequency within {100 * STABLE_FREQ_REL:g} %, damping "
                f"ratio within {100 * SSI_STABLE_DAMPING_REL:g} %{shape}), open "
                f"grey dots: the other poles, all of them physical (MPC ≥ {SSI_MPC_MIN:g}, MPD ≤ "
                f"{SSI_MPD_MAX_DEG:g} deg, damping ratio 0-{100 * SSI_ZETA_MAX:g} %); modes {modes} "
                "(unscaled shapes)"))
    return out


def _listed(freq_hz: np.ndarray) -> str:
    return ", ".join(f"{f:.4g} Hz" for f in freq_hz)
