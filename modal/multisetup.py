"""Multi-setup output-only modal analysis: several records sharing reference sensors, with the other
(roving) sensors moved between them, merged into one set of global mode shapes.

Method: post-separate estimation re-scaling (PoSER; Döhler, Andersen & Mevel 2012, Mech. Syst. Signal
Process. 28; Brincker & Ventura 2015 §11.4).  Every setup is identified on its own
(:func:`flexmodal.modal.ssi.ssi_cov` with that setup's reference sensors as the Hankel references);
the modes of each setup are paired with those of the first setup by frequency (within ``freq_tol``)
and by MAC on the reference sensors (>= ``mac_min``); each paired shape is scaled by the complex least-
squares factor that best maps its reference entries onto the first setup's,
``alpha = (phi_s,ref^H phi_1,ref) / (phi_s,ref^H phi_s,ref)``, and the global shape takes every
setup's roving entries and the mean of the re-scaled reference entries.  Frequencies and damping
ratios are the means over the setups.

Why PoSER rather than pre-identification merging (PreGER, one identification of the stacked,
reference-normalised covariances): an arm in operation is excited by its own motors, so the excitation
level and spectrum change from setup to setup; PoSER needs no assumption on that, each setup's
stabilisation diagram and validation can be checked on its own, and a setup that lost a mode shows as
a named warning instead of corrupting one joint identification.  The price is that a mode is merged
only where every setup identified it.  Shapes stay unscaled (output-only data).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from flexmodal.contract.mac import mac, to_real, unit_max
from flexmodal.modal.errors import ModalError
from flexmodal.modal.identify import Modes
from flexmodal.modal.ssi import ssi_cov


@dataclass(frozen=True)
class OmaSetup:
    """One setup: an output-only record [n_samples, n_channels] with channel names; ``references``
    names the channels shared with every other setup."""

    samples: np.ndarray
    sample_rate_hz: float
    channels: tuple[str, ...]
    references: tuple[str, ...]


@dataclass(frozen=True)
class MergedModes:
    """Global ``modes`` over ``points`` (references first, then each setup's roving sensors in order);
    the per-setup frequency spread (max - min, Hz) of each merged mode."""

    modes: Modes
    points: tuple[str, ...]
    freq_spread_hz: np.ndarray


def _layout(setups: Sequence[OmaSetup]) -> tuple[list[list[int]], list[list[int]], tuple[str, ...]]:
    """Rows of the references and of the roving sensors in each setup, and the global point names."""
    if not setups:
        raise ModalError("multi-setup: no setups given")
    refs = setups[0].references
    if not refs:
        raise ModalError("multi-setup: no reference sensors are shared between the setups")
    for k, s in enumerate(setups):
        missing = [r for r in refs if r not in s.channels]
        if missing or tuple(s.references) != tuple(refs):
            names = missing or list(refs)
            what = "reference sensor" if len(names) == 1 else "reference sensors"
            raise ModalError(f"multi-setup: setup {k + 1} lacks {what} {', '.join(names)}")
    ref_rows = [[s.channels.index(r) for r in refs] for s in setups]
    roving = [[j for j, c in enumerate(s.channels) if c not in refs] for s in setups]
    points = tuple(refs) + tuple(s.channels[j] for s, rov in zip(setups, roving, strict=True) for j in rov)
    if len(set(points)) != len(points):
        raise ModalError("multi-setup: a roving sensor name appears in two setups")
    return ref_rows, roving, points


def merge_setups(setup_modes: Sequence[Modes], setups: Sequence[OmaSetup], *, freq_tol: float = 0.02,
                 mac_min: float = 0.9) -> MergedModes:
    """PoSER merge of modes identified separately in each setup (see module docstring)."""
    if len(setup_modes) != len(setups):
        raise ModalError(f"multi-setup: {len(setup_modes)} sets of modes for {len(setups)} setups")
    ref_rows, roving, points = _layout(setups)
    base = setup_modes[0]
    pairs = np.full((len(setups), base.freq_hz.size), -1)
    pairs[0] = np.arange(base.freq_hz.size)
    warnings: list[str] = []
    for k in range(1, len(setups)):   # a loop over setups
        m = setup_modes[k]
        close = np.abs(m.freq_hz[None, :] / base.freq_hz[:, None] - 1) <= freq_tol
        similar = mac(base.complex_shapes[ref_rows[0]], m.complex_shapes[ref_rows[k]]) >= mac_min
        score = np.where(close & similar, -np.abs(m.freq_hz[None, :] - base.freq_hz[:, None]), -np.inf)
        best = np.argmax(score, axis=1)
        pairs[k] = np.where(np.isfinite(score[np.arange(best.size), best]), best, -1)
    complete = np.all(pairs >= 0, axis=0)
    warnings += [f"mode at {f:.4g} Hz of setup 1 is missing from another setup: not merged"
                 for f in base.freq_hz[~complete]]
    if not complete.any():
        raise ModalError("multi-setup: no mode was identified in every setup")
    cols = pairs[:, complete]
    shapes = [setup_modes[k].complex_shapes[:, cols[k]] for k in range(len(setups))]
    ref0 = shapes[0][ref_rows[0]]
    scaled = []
    for k, sh in enumerate(shapes):   # a loop over setups
        r = sh[ref_rows[k]]
        alpha = np.einsum("ir,ir->r", r.conj(), ref0) / np.einsum("ir,ir->r", r.conj(), r).real
        scaled.append(sh * alpha[None, :])
    glob = np.vstack([np.mean([sc[ref_rows[k]] for k, sc in enumerate(scaled)], axis=0)]
                     + [sc[rov] for sc, rov in zip(scaled, roving, strict=True)])
    freqs = np.array([setup_modes[k].freq_hz[cols[k]] for k in range(len(setups))])
    zetas = np.array([setup_modes[k].damping_ratio[cols[k]] for k in range(len(setups))])
    complex_shapes = unit_max(glob)
    modes = Modes(freqs.mean(axis=0), zetas.mean(axis=0), to_real(complex_shapes), complex_shapes,
                  base.method + "+poser", False, tuple(warnings))
    return MergedModes(modes, points, np.ptp(freqs, axis=0))


def ssi_multisetup(setups: Sequence[OmaSetup], *, freq_tol: float = 0.02, mac_min: float = 0.9,
                   **ssi_options) -> MergedModes:
    """Identify every setup by SSI-cov with its reference sensors as references, then
    :func:`merge_setups`.  ``ssi_options`` go to :func:`flexmodal.modal.ssi.ssi_cov`."""
    ref_rows, _, _ = _layout(setups)
    found = [ssi_cov(s.samples, s.sample_rate_hz, references=rows, **ssi_options).modes
             for s, rows in zip(setups, ref_rows, strict=True)]
    return merge_setups(found, setups, freq_tol=freq_tol, mac_min=mac_min)
