"""Smoke test of benchmarks/modal.py on tiny data (the timing itself is not a unit test)."""

from __future__ import annotations

import importlib.util
from pathlib import Path


def test_benchmark_script_runs_and_reports_ratios_and_differences(capsys, tmp_path):
    path = Path(__file__).resolve().parents[1] / "benchmarks" / "modal.py"
    spec = importlib.util.spec_from_file_location("modal_benchmark", path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    assert module.main(["--duration-s", "4", "--nfft", "1024", "--responses", "2", "--frfs", "4",
                        "--lines", "400", "--repeat", "1", "--process-nfft", "256",
                        "--folder", str(tmp_path)]) == 0
    out = capsys.readouterr().out
    assert "ratio" in out and "max relative difference" in out
    assert "FFT floor: the 114 bare float32 FFTs" in out   # 3 channels x 38 half-overlapping segments
    assert "flexmodal modes found 6/6" in out
    assert "PROC whole `flexmodal frf` process" in out and "flexmodal process / floor" in out
    assert "; 155 segments" in out      # 4 s at 5 kHz in segments of 256 advancing by 128
    assert list(tmp_path.iterdir()) == []
