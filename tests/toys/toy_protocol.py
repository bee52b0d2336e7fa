"""A toy acquisition protocol, the whole of it: a device whose sample i carries the values
(gain i, -gain i), delivered at ``rate_factor`` x the session rate, with its own configuration
dataclass (``[[device]]`` fields ``gain`` and ``rate_factor``)."""

import time
from dataclasses import dataclass

import numpy as np

from flexmodal.daq.devices import Block, Device, Driver
from flexmodal.daq.protocols import register_protocol

NAME = "toy"


@dataclass(frozen=True)
class ToyConfig:
    gain: float = 1.0
    rate_factor: float = 1.0
    sources: tuple[str, ...] = ("up", "down")


class ToyDriver(Driver):
    protocol = NAME

    @classmethod
    def parse_device(cls, t, name):
        t.reject_unknown({"gain", "rate_factor"})
        config = ToyConfig(t.get("gain", float, 1.0), t.get("rate_factor", float, 1.0))
        return Device(name, cls.protocol, config)

    def __init__(self, device, sample_rate_hz):
        self.name, self.sources, self.limits = device.name, device.config.sources, None
        self.gain, self.rate = device.config.gain, sample_rate_hz * device.config.rate_factor
        self.t0, self.n = None, 0

    def open(self):
        self.t0 = self.t0 or time.monotonic()

    def read(self):
        time.sleep(0.02)
        due = int((time.monotonic() - self.t0) * self.rate)
        i = np.arange(self.n, due, dtype=float)
        first, self.n = self.n, due
        if not i.size:
            return []
        values = self.gain * np.column_stack([i, -i])
        return [Block(self.name, first, values, time.time() - i.size / self.rate)]

    def close(self):
        pass


register_protocol(NAME, ToyDriver)
