"""The modal map figure f(q): tracked modes across a pose variable with error bars and a prediction band.

``plot_modal_map(mmap, band=None, pose_label="pose [-]", title="") -> matplotlib.figure.Figure``
    ``mmap`` a compare.modal_map.ModalMap (``track_modes``/``modal_map``): one colour per tracked
    branch, points at the measured poses with 95 % error bars (1.96 x ``freq_std_hz``; none where the
    uncertainty is unknown), the points of a branch joined; order swaps (``mmap.events``, veering or
    crossing) marked by a grey vertical line.  ``band`` an optional compare.modal_map.PredictionBand:
    the model's frequencies as lines and their 95 % interval as a shaded band (none, and no legend entry,
    when its bounds equal the frequencies).  ``pose_label`` the
    x-axis label with its unit (e.g. ``"theta_deg [deg]"``).

The function only draws what it is given (the tracking and the band are computed in compare/); it
uses ``matplotlib.figure.Figure`` without pyplot and changes no global state.  The legend sits below
the axes, never over the points.

Examples
--------
>>> import numpy as np
>>> from flexmodal.compare.modal_map import track_modes
>>> m = track_modes([0.0, 1.0, 2.0], [np.array([10.0, 20.0]), np.array([11.0, 19.0]), np.array([12.0, 18.0])])
>>> fig = plot_modal_map(m, pose_label="q [rad]")
>>> len(fig.axes)
1
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np
from matplotlib.figure import Figure

if TYPE_CHECKING:
    from flexmodal.compare.modal_map import ModalMap, PredictionBand

_COLOURS = ("#1f77b4", "#d62728", "#2ca02c", "#9467bd", "#ff7f0e", "#8c564b", "#e377c2", "#17becf")
Z95 = 1.959963984540054
"""Two-sided 95 % normal quantile: the error bars are +-Z95 standard deviations."""


def plot_modal_map(mmap: ModalMap, band: PredictionBand | None = None, pose_label: str = "pose [-]",
                   title: str = "") -> Figure:
    """Natural frequency [Hz] of each tracked branch against the pose (module docstring)."""
    fig = Figure(figsize=(8, 4.5), layout="constrained")
    ax = fig.subplots()
    if band is not None:
        spread = bool(np.any(band.upper_hz > band.lower_hz))   # a bare prediction has no interval to show
        for m in range(band.freq_hz.shape[1]):
            if spread:
                ax.fill_between(band.pose, band.lower_hz[:, m], band.upper_hz[:, m], color="0.75", alpha=0.5,
                                lw=0, label=f"{band.label}: 95 % prediction interval" if m == 0 else None)
            ax.plot(band.pose, band.freq_hz[:, m], "-", color="0.35", lw=1.0,
                    label=band.label if m == 0 else None)
    for b in range(mmap.n_branches):
        seen = mmap.mode_number[:, b] > 0
        colour = _COLOURS[b % len(_COLOURS)]
        err = Z95 * mmap.freq_std_hz[seen, b]
        ax.errorbar(mmap.pose[seen], mmap.freq_hz[seen, b], yerr=np.where(np.isfinite(err), err, 0.0),
                    fmt="o-", color=colour, ms=4, lw=1.0, capsize=3, label=f"branch {b + 1}")
    for q, _, _ in mmap.events:
        ax.axvline(0.5 * (mmap.pose[q - 1] + mmap.pose[q]), color="0.6", ls=":", lw=1.0)
    ax.set_xlabel(pose_label)
    ax.set_ylabel("natural frequency [Hz]")
    ax.grid(True, alpha=0.3)
    fig.legend(*ax.get_legend_handles_labels(), loc="outside lower center", fontsize=7, ncol=4)
    ax.set_title(title or "modal map (measured: mean ± 95 % interval)")
    return fig
