"""The signal the device simulators emit: a simulated rig test as 16-bit ADC counts, looped.

The simulated test (``fixtures.rig_sim.simulate``) is digitised through a realistic transducer chain:
each channel has a sensitivity (force 50 mV/N, acceleration 100 mV/g, strain 5 mV/µε) into a ±10 V,
16-bit ADC, so one count is ``LSB_MV`` = 0.30518 mV and the physical value of a count is
``LSB_MV / sensitivity * k`` (k = 9.80665 for g -> m/s^2).  Encoders deliver raw counts (4096/rev).
Sample ``n`` of the stream is row ``n % record_length`` of the record, so any later reader can rebuild
exactly what a simulator emitted from (rig, test, rate, seed) and the device's sample index.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from flexmodal.daq.session import G_M_PER_S2

if TYPE_CHECKING:
    from flexmodal.fixtures.rig_sim import HiddenEffect

ADC_FULL_SCALE_MV = 10_000.0
ADC_BITS = 16
LSB_MV = 2 * ADC_FULL_SCALE_MV / 2**ADC_BITS
ENCODER_COUNTS_PER_REV = 4096
# kind -> (sensitivity, sensitivity_unit, physical unit of the sensitivity's denominator -> channel unit)
CHAIN = {
    "force": (50.0, "mV/N", 1.0),
    "acceleration": (100.0, "mV/g", G_M_PER_S2),
    "strain": (5.0, "mV/µε", 1.0),
}


@dataclass(frozen=True)
class SimChannel:
    """One emitted channel: stored value = counts * scale / sensitivity * factor (channel units)."""

    name: str
    kind: str
    unit: str
    sensitivity: float
    sensitivity_unit: str
    scale: float  # electrical unit (mV) per count; 1 for encoders
    factor: float
    location: str
    direction: str

    @property
    def step(self) -> float:
        """One quantisation step in channel units."""
        return self.scale / self.sensitivity * self.factor


@dataclass(frozen=True)
class SimSource:
    """A looped record of ADC counts [record_length, n_channels] (int16; int32 for encoders)."""

    channels: tuple[SimChannel, ...]
    sample_rate_hz: float
    counts: np.ndarray

    def block(self, start: int, n: int) -> np.ndarray:
        """Counts of samples start .. start+n-1 [n, n_channels] (the record repeats)."""
        return np.take(self.counts, np.arange(start, start + n) % self.counts.shape[0], axis=0)

    def physical(self, start: int, n: int) -> np.ndarray:
        """The same samples in channel units [n, n_channels]."""
        return self.block(start, n) * np.array([c.step for c in self.channels])


def sim_source(rig_path: str | Path | None = None, test: str = "impact", sample_rate_hz: float = 2048.0,
               record_s: float = 8.0, seed: int = 0, pose: dict | None = None,
               effects: Sequence[HiddenEffect] = ()) -> SimSource:
    """Simulate ``test`` on the rig (default: the demo arm) at ``pose`` with hidden ``effects`` and
    digitise it.

    Pose variables not given are 30 for angles (``*_deg``) and 0 otherwise.
    """
    from flexmodal.fixtures.rig_sim import DEMO_RIG, simulate
    from flexmodal.models.rig import load_rig

    rig = load_rig(rig_path or DEMO_RIG)
    default = {v: 30.0 if v.endswith("_deg") else 0.0 for v in rig.pose_variables}
    pose = {**default, **(pose or {})}
    links = [link.name for link in rig.links]
    pulse_s = max(1.5e-3, 4 / sample_rate_hz)  # a softer hammer tip at low rates, so hits are sampled
    probe = simulate(rig, pose, excitation=test, duration_s=0.25, sample_rate_hz=sample_rate_hz,
                     seed=seed, strain_gauges=(f"{links[0]}@0.1",), pulse_width_s=pulse_s, effects=effects)
    chain = [CHAIN.get(c.kind, (1.0, "", 1.0)) for c in probe.channels]
    full_scale = [ADC_FULL_SCALE_MV / s * f if c.kind in CHAIN else 2.0**31
                  for c, (s, _, f) in zip(probe.channels, chain, strict=True)]
    sim = simulate(rig, pose, excitation=test, duration_s=record_s, sample_rate_hz=sample_rate_hz, seed=seed,
                   strain_gauges=(f"{links[0]}@0.1",), full_scale=full_scale,
                   encoder_counts_per_rev=ENCODER_COUNTS_PER_REV, pulse_width_s=pulse_s, effects=effects)
    channels = []
    for c, (sens, sens_unit, factor) in zip(sim.channels, chain, strict=True):
        if c.kind == "encoder":
            channels.append(SimChannel(c.name, c.kind, "deg", ENCODER_COUNTS_PER_REV, "counts/rev", 1.0,
                                       360.0, c.location, c.direction))
        else:
            channels.append(SimChannel(c.name, c.kind, c.unit, sens, sens_unit, LSB_MV, factor, c.location,
                                       c.direction))
    steps = np.array([c.step if c.kind != "encoder" else 1.0 for c in channels])
    counts = np.round(sim.samples / steps)
    lo, hi = -(2 ** (ADC_BITS - 1)), 2 ** (ADC_BITS - 1) - 1
    analog = [i for i, c in enumerate(channels) if c.kind != "encoder"]
    counts[:, analog] = np.clip(counts[:, analog], lo, hi)
    return SimSource(tuple(channels), float(sample_rate_hz), counts.astype(np.int32))
