"""Report figures of output-only (operational) runs: the FDD singular values of the output cross-spectral
matrix with the picked peaks, and the SSI-cov stabilisation diagram drawn over those singular values
(:func:`flexmodal.reports.plots.plot_stabilisation`).  Units: frequency Hz, spectral densities in the
outputs' unit squared per Hz (m/s² -> (m/s²)²/Hz), model order dimensionless."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from matplotlib.figure import Figure

from flexmodal.modal.errors import ModalError
from flexmodal.modal.fdd import FddResult, cross_spectra
from flexmodal.modal.oma import default_method, identify_output_only
from flexmodal.modal.ssi import SsiResult
from flexmodal.reports.plots import _COLOURS, plot_stabilisation


def plot_fdd(result: FddResult, unit: str = "(m/s²)²/Hz", title: str = "") -> Figure:
    """Singular values of the output cross-spectral matrix [unit] against frequency [Hz], largest first,
    with the identified modes marked (Brincker et al. 2001)."""
    fig = Figure(figsize=(8, 3.6))
    ax = fig.subplots()
    for k, sv in enumerate(result.singular_values):
        ax.semilogy(result.freq_hz[1:], sv[1:], color=_COLOURS[k % len(_COLOURS)], lw=1.0 if k == 0 else 0.6,
                    label=f"s{k + 1}")
    for f in result.modes.freq_hz:
        ax.axvline(f, color="0.4", lw=0.6, ls="--")
        ax.annotate(f"{f:.4g} Hz", (f, 1.0), xycoords=("data", "axes fraction"), fontsize=7, rotation=90,
                    va="top", ha="right")
    ax.set_xlabel("frequency [Hz]")
    ax.set_ylabel(f"singular values of G_yy [{unit}]")
    ax.set_xlim(float(result.freq_hz[1]), float(result.freq_hz[-1]))
    ax.legend(loc="upper right", fontsize=7, ncol=2)
    if title:
        ax.set_title(title)
    fig.subplots_adjust(left=0.1, right=0.97, bottom=0.14, top=0.9)
    return fig


def plot_ssi_stabilisation(result: SsiResult, y: np.ndarray, sample_rate_hz: float,
                           unit: str = "(m/s²)²/Hz", title: str = "") -> Figure:
    """SSI-cov poles per model order (filled: stable in frequency, damping and shape) over the singular
    values of the cross-spectral matrix of the record ``y`` [n_samples, n_channels] with SSI's
    references."""
    nfft = int(min(4096, 2 ** np.floor(np.log2(max(16, y.shape[0] // 8)))))
    f, G = cross_spectra(y, sample_rate_hz, result.references, nfft)
    top = result.stabilisation.freq_hz.max(initial=f[-1])
    band = (f > 0) & (f <= max(top * 1.1, f[1]))
    fig = plot_stabilisation(f[band], np.moveaxis(G[band], 0, -1), result.stabilisation, unit, title=title)
    fig.axes[1].set_ylabel(f"FDD singular values [{unit}]")
    return fig


def oma_figures(samples: np.ndarray, sample_rate_hz: float, names: Sequence[str], kinds: Sequence[str],
                label: str, unit: str = "(m/s²)²/Hz") -> list[tuple[Figure | None, str]]:
    """The FDD and SSI figures of an output-only record, each with its caption (a figure of None with
    the reason in the caption when the method found nothing)."""
    out: list[tuple[Figure | None, str]] = []
    for method in ("fdd", "ssi"):   # a loop over the two methods
        try:
            result, outputs = identify_output_only(samples, sample_rate_hz, names, kinds, method=method,
                                                   where=label)
        except ModalError as exc:
            out.append((None, f"{label}: no {method.upper()} ({exc})"))
            continue
        modes = ", ".join(f"{f:.4g} Hz" for f in result.modes.freq_hz)
        if isinstance(result, FddResult):
            out.append((plot_fdd(result, unit, title=label), f"{label}: FDD, singular values of the output "
                        f"cross-spectral matrix ({', '.join(outputs)}); peaks {modes}"))
        else:
            y = np.asarray(samples)[:, [list(names).index(o) for o in outputs]]
            orders = f"{result.stabilisation.order.min()}-{result.stabilisation.order.max()}"
            out.append((plot_ssi_stabilisation(result, y, sample_rate_hz, unit, title=label),
                        f"{label}: SSI-cov stabilisation diagram, orders {orders} "
                        f"(filled: stable in frequency, damping and shape), over the FDD singular values; "
                        f"modes {modes} (unscaled shapes)"))
    return out


def is_output_only(kinds: Sequence[str], excitation: str) -> bool:
    """True for a run that OMA identifies (operational excitation or no force channel)."""
    return default_method(kinds, excitation) == "ssi"
