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

from flexmodal.reports.plots import _COLOURS, log_axis, plot_stabilisation, text

if TYPE_CHECKING:
    from flexmodal.modal.fdd import FddResult
    from flexmodal.modal.oma import OmaResults
    from flexmodal.modal.ssi import SsiResult


def plot_fdd(result: FddResult, unit: str = "(m/s²)²/Hz", title: str = "") -> Figure:
    """Singular values of the output cross-spectral matrix [unit] against frequency [Hz], largest first,
    with the identified modes marked (Brincker et al. 2001)."""
    fig = Figure(figsize=(8, 3.8), layout="constrained")
    ax = fig.subplots()
    for k, sv in enumerate(result.singular_values):
        ax.semilogy(result.freq_hz[1:], sv[1:], color=_COLOURS[k % len(_COLOURS)], lw=1.0 if k == 0 else 0.6,
                    label=f"s{k + 1}")
    for f in result.modes.freq_hz:
        ax.axvline(f, color="0.4", lw=0.6, ls="--")
        ax.annotate(f"{f:.4g} Hz", (f, 1.0), xycoords=("data", "axes fraction"), fontsize=7, rotation=90,
                    va="top", ha="right")
    ax.set_xlabel("frequency [Hz]")
    ax.set_ylabel(f"singular values of G_yy [{text(unit)}]")
    log_axis(ax.yaxis)
    ax.set_xlim(float(result.freq_hz[1]), float(result.freq_hz[-1]))
    ax.legend(loc="upper right", fontsize=7, ncol=2)
    if title:
        ax.set_title(text(title))
    return fig


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
    orders = f"{oma.ssi.stabilisation.order.min()}-{oma.ssi.stabilisation.order.max()}"
    out.append((plot_ssi_stabilisation(oma.ssi, oma.spectrum_hz, oma.spectrum, unit, title=label),
                f"{label}: SSI-cov stabilisation diagram, orders {orders} (filled: stable in frequency, "
                f"damping and shape), over the FDD singular values; modes {modes} (unscaled shapes)"))
    return out


def _listed(freq_hz: np.ndarray) -> str:
    return ", ".join(f"{f:.4g} Hz" for f in freq_hz)
