"""Smoke tests of benchmarks/modal.py, batch.py and memory.py on tiny data (the timing itself is not a
unit test)."""

from __future__ import annotations

import importlib.util
from pathlib import Path

import pytest


def _script(name: str):
    path = Path(__file__).resolve().parents[1] / "benchmarks" / f"{name}.py"
    spec = importlib.util.spec_from_file_location(f"{name}_benchmark", path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_benchmark_script_runs_and_reports_ratios_and_differences(capsys, tmp_path):
    assert _script("modal").main(["--duration-s", "4", "--nfft", "1024", "--responses", "2", "--frfs", "4",
                        "--lines", "400", "--repeat", "1", "--process-nfft", "256",
                        "--folder", str(tmp_path)]) == 0
    out = capsys.readouterr().out
    assert "ratio" in out and "max relative difference" in out
    assert "FFT floor: the 114 bare float32 FFTs" in out   # 3 channels x 38 half-overlapping segments
    assert "flexmodal modes found 6/6" in out
    assert "PROC whole `flexmodal frf` process" in out and "process / floor = " in out
    assert "; 155 segments" in out      # 4 s at 5 kHz in segments of 256 advancing by 128
    assert "without a bytecode cache" in out and "`import numpy, h5py`" in out and "the rest (parser" in out
    assert "HELP `flexmodal frf --help`, bytecode cached: " in out
    assert "so none is more than" in out and "KERNEL Welch H1 + H2 + coherence" in out
    assert "(target <= 1.4)" in out and out.count("(target <= 0.6)") == 5
    assert "a spinning process in our session, nice 19" in out
    assert "fair scheduling gives 2 threads at most 1.33 CPUs" in out and "on 2 CPUs with nobody else" in out
    assert "where the CPU of 1 thread goes" in out and "FFTs " in out and "cross-spectra product " in out
    assert "offset shift (the record's first read) " in out and "the rest " in out
    assert "scipy.fft on top of them" in out and "flexmodal's own modules" in out
    assert "the least any numpy/scipy estimate does" in out and "the Python glue (holds the GIL)" in out
    assert "the FFTs from the record " in out and ", the cross-spectra " in out
    assert "two idle cores bound 2 / 1 at " in out
    assert "(target <= 2: process <=" in out and "in CPU (steadier on a shared machine)" in out
    assert list(tmp_path.iterdir()) == []


@pytest.mark.slow
def test_memory_benchmark_reports_peak_rss_linearity_and_equality(capsys, tmp_path):
    assert _script("memory").main(["--durations", "2", "4", "--repeat", "1", "--folder", str(tmp_path)]) == 0
    out = capsys.readouterr().out
    assert out.count("`flexmodal frf` peak RSS") == 2 and "(1.00 = linear)" in out
    assert out.count("max relative difference of H 0.0e+00, of coherence 0.0e+00") == 2   # identical
    assert list(tmp_path.iterdir()) == []


@pytest.mark.slow
def test_batch_benchmark_reports_every_case_against_serial(capsys, tmp_path):
    assert _script("batch").main(["--runs", "4", "--duration-s", "1", "--repeat", "1",
                                  "--folder", str(tmp_path)]) == 0
    out = capsys.readouterr().out
    assert "BATCH 4 runs" in out and "serial on 1 CPU / this = 1.00x" in out
    assert "--workers 0 / this = 1.00x" in out
    assert "--workers 2 (pool)" in out and "default (by cost)" in out and "POOL start-up" in out
    assert "COST one run of 1 s" in out and "caller's CPU per task" in out
    assert "pool start (fork server" in out and "a helper's fork" in out and "runs with one helper" in out
    assert "ACCEPTANCE default against serial on 1 CPU: 4 runs" in out
    assert out.count("CPUs busy") == 4 and "CPUs busy pool workers not counted" in out
    assert list(tmp_path.iterdir()) == []
