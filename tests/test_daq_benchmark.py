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


@pytest.mark.slow
@pytest.mark.parametrize("rate_hz", [64_000.0, 256_000.0])
def test_serial_32_channels_paced_over_a_pty_is_lossless(tmp_path, rate_hz):
    from daq_throughput import N_CH, bench_serial

    stored, intact = bench_serial(tmp_path, 2.0, 1.0, rate_hz)
    print(f"32 ch x {rate_hz:g} Hz: {stored / 1e6:.2f} MS/s stored, lossless {intact}")
    assert intact  # every value equal to what was sent, no gap, corrupt frame or dropped block
    assert stored >= 0.8 * N_CH * rate_hz if rate_hz <= 64_000 else stored > 0
