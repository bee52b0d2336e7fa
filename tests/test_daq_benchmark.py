"""The overrun figures of benchmarks/daq_throughput.py (docs/acquisition.md) re-run: a Modbus session
below the rate its stack sustains records no overrun, far above it an overrun event fires."""

from __future__ import annotations

import sys
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "benchmarks"))
from daq_throughput import bench_overrun  # noqa: E402


@pytest.mark.slow
def test_modbus_overrun_fires_above_the_polling_limit_only(tmp_path):
    assert bench_overrun("modbus", 200.0, 4.0, tmp_path) == (0, pytest.approx(float("nan"), nan_ok=True))
    n, lag = bench_overrun("modbus", 8000.0, 4.0, tmp_path)
    assert n >= 1 and 1.0 <= lag < 3.0
