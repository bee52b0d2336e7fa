"""Known answers for the validation modules of issue 13 (checked_io.text, checked_io.csv_tables,
checked_io.options, checked_io.output, daq.run_schema / daq.h5file.open_read, models.rig_schema,
modal.valid_uff)."""

from __future__ import annotations

import argparse
import math
import os
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
from cpu_wait import CpuWait

from flexmodal.checked_io import options as opt
from flexmodal.checked_io.csv_tables import read_table
from flexmodal.checked_io.output import hdf5_output, output_dir, output_file
from flexmodal.checked_io.text import decode_text, one_line, read_toml
from flexmodal.daq.errors import DaqError
from flexmodal.daq.h5file import open_read
from flexmodal.daq.store import Channel, RunWriter, list_runs, read_run
from flexmodal.modal.errors import ModalError
from flexmodal.modal.valid_uff import check_functions
from flexmodal.models.errors import ModelError
from flexmodal.models.rig_schema import check_document


class Bad(ValueError):
    pass


def test_decode_text_names_line_and_byte() -> None:
    assert decode_text("\ufeffa = 1\n".encode(), "f", Bad) == "a = 1\n"  # byte-order mark dropped
    with pytest.raises(Bad, match=r"^f: line 3: byte 0xb5 at offset 9 is not UTF-8"):
        decode_text(b"a\nbc\nx = \xb5\n", "f", Bad)
    with pytest.raises(Bad, match=r"^f: line 2: binary data \(NUL byte at offset 3\)"):
        decode_text(b"ab\n\x00", "f", Bad)


def test_read_toml_one_line(tmp_path: Path) -> None:
    p = tmp_path / "x.toml"
    p.write_text("a = 1\nb = = 2\n")
    with pytest.raises(Bad) as info:
        read_toml(p, Bad)
    assert "\n" not in str(info.value) and "line 2" in str(info.value)
    with pytest.raises(Bad, match="not found"):
        read_toml(tmp_path / "none.toml", Bad)
    with pytest.raises(Bad, match="is a directory"):
        read_toml(tmp_path, Bad)
    assert one_line("a\n  b\tc") == "a b c" and len(one_line("x" * 1000)) == 300


def test_read_table(tmp_path: Path) -> None:
    p = tmp_path / "t.csv"
    p.write_text("config,mode,freq_hz\n007,1,2.5\n\nx,2,3\n")
    df = read_table(p, Bad, required=("config", "freq_hz"), text_columns=("config",))
    assert df["config"].tolist() == ["007", "x"] and df["freq_hz"].tolist() == [2.5, 3.0]
    cases = {"": "empty CSV table", "a,a\n1,2\n": "line 1: column 'a' appears twice",
             "config,mode,freq_hz\nx,1\n": "line 2: 2 fields, the header has 3",
             "config,mode,freq_hz\nx,1,2,3\n": "line 2: 4 fields",
             "config,mode\nx,1\n": "missing required column 'freq_hz'",
             "config,mode,freq_hz\nx,1,2\n ,2,3\n": "line 3: empty 'config' cell"}
    for text, message in cases.items():
        p.write_text(text)
        with pytest.raises(Bad, match=message):
            read_table(p, Bad, required=("config", "freq_hz"), text_columns=("config",))


def test_option_types() -> None:
    assert opt.seconds("2.5") == 2.5 and opt.overlap("0") == 0.0 and opt.tcp_port("65535") == 65535
    for parse, text in [(opt.seconds, "inf"), (opt.seconds, "nan"), (opt.seconds, "0"), (opt.overlap, "1"),
                        (opt.fraction, "1.01"), (opt.tcp_port, "99999"), (opt.workers, "-1"),
                        (opt.model_order, "1"), (opt.integer(1), "2.5"), (opt.hertz, "-1e-9")]:
        with pytest.raises(argparse.ArgumentTypeError, match=repr(text).replace(".", r"\.")):
            parse(text)


def test_output_paths(tmp_path: Path) -> None:
    assert output_file(tmp_path / "a.csv", Bad, inputs=()) == tmp_path / "a.csv"
    assert output_dir(tmp_path / "new" / "deeper", Bad) == tmp_path / "new" / "deeper"
    assert not (tmp_path / "new").exists()  # checked, not created
    (tmp_path / "f.txt").write_text("x")
    for call, message in [(lambda: output_file(tmp_path / "no" / "a.csv", Bad, inputs=()), "does not exist"),
                          (lambda: output_file(tmp_path, Bad, inputs=()), "is a directory"),
                          (lambda: output_file("/proc/a.csv", Bad, inputs=()),
                           "/proc/a.csv: is a device or process"),
                          (lambda: output_dir(tmp_path / "f.txt", Bad), "not a directory"),
                          (lambda: output_dir(tmp_path / "f.txt" / "sub", Bad), "not a directory"),
                          (lambda: hdf5_output(tmp_path / "f.txt", Bad), "not an HDF5 file")]:
        with pytest.raises(Bad, match=message):
            call()
    assert not list(tmp_path.glob(".flexmodal-probe-*"))


def _write(path: Path, n: int = 2048) -> None:
    with RunWriter(path, "r1", sample_rate_hz=512.0, channels=[Channel("F", "force", "N")],
                   excitation="impact", pose={}) as w:
        w.append(np.arange(n, dtype=float)[:, None])


def test_truncated_file_fails_at_once(tmp_path: Path) -> None:
    p = tmp_path / "run.h5"
    _write(p)
    data = p.read_bytes()
    for cut in (0, 8, 47, 100, len(data) // 2, len(data) - 1):
        p.write_bytes(data[:cut])
        with CpuWait(os.getpid()) as waits:  # at once: < 2 s not counting waits for a CPU (load)
            t0 = time.monotonic()
            with pytest.raises(DaqError, match=r"run\.h5: (truncated HDF5|not a readable HDF5 run) file"):
                list_runs(p)
            t1 = time.monotonic()
        assert waits.unloaded(t0, t1) < 2.0, f"{t1 - t0:.2f} s wall"


WRITER = """
import sys, time, numpy as np
from flexmodal.daq.store import Channel, RunWriter
w = RunWriter(sys.argv[1], "live", sample_rate_hz=512.0, channels=[Channel("F", "force", "N")],
              excitation="random", pose={}, flush_interval_s=0.05)
w.append(np.ones((1000, 1)))
w.flush()
print("ready", flush=True)
sys.stdin.readline()
w.append(np.ones((500, 1)))
w.flush()
print("more", flush=True)
sys.stdin.readline()
w.close()
"""


def test_live_file_of_another_writer_still_reads(tmp_path: Path) -> None:
    """SWMR: a run another process is writing reads (and grows) while its superblock says 'open'."""
    p = tmp_path / "live.h5"
    proc = subprocess.Popen([sys.executable, "-c", WRITER, str(p)], stdin=subprocess.PIPE,
                            stdout=subprocess.PIPE, text=True)
    try:
        assert proc.stdout.readline().strip() == "ready"
        assert p.read_bytes()[11] != 0  # the open-for-writing flags are set: the SWMR path is taken
        assert read_run(p, "live").samples.shape == (1000, 1)
        proc.stdin.write("\n")
        proc.stdin.flush()
        assert proc.stdout.readline().strip() == "more"
        assert read_run(p, "live").samples.shape == (1500, 1)
        proc.stdin.write("\n")
        proc.stdin.flush()
        assert proc.wait(300) == 0  # a hang guard
    finally:
        if proc.poll() is None:
            proc.kill()
    with open_read(p) as f:
        assert f["runs/live/samples"].shape == (1500, 1)


def test_rig_document_shapes() -> None:
    good = {"link": [{"name": "a", "elements": 500, "section": {"outer_m": 1000.0}}], "base": {}}
    check_document(good, "r.toml")
    cases = [({"base": "x"}, r"r.toml: base: must be a \[base\] table"),
             ({"joint": 3}, r"joint: must be \[\[joint\]\] tables"),
             ({"link": [{"elements": 501}]}, r"link\[0\].elements: 501 is more than 500"),
             ({"link": [{"section": {"outer_m": 1e300}}]}, r"link\[0\].section.outer_m: 1e\+300 m"),
             ({"material": {"al": {"E_Pa": 1e300, "rho_kg_m3": 1}}}, "material.al.E_Pa"),
             ({"joint": [{"angle": 5}]}, r"joint\[0\].angle: must name a pose variable"),
             ({"joint": [{"angle_deg": math.nan}]}, r"joint\[0\].angle_deg: must be a finite number")]
    for doc, message in cases:
        with pytest.raises(ModelError, match=message):
            check_document(doc, "r.toml")


def test_uff_records() -> None:
    ok = {"func_type": 4, "rsp_node": 1, "rsp_dir": 3, "ref_node": 2, "ref_dir": 3, "x": np.arange(3.0),
          "data": np.ones(3, complex), "num_pts": 3}
    check_functions("f.uff", [ok])
    short = {"x": np.arange(1.0), "data": np.ones(1), "num_pts": 1}
    for change, message in [({"num_pts": 5}, "num_pts = 5"), ({"x": np.array([0.0, 2.0, 1.0])}, "increase"),
                            ({"data": np.array([1, np.nan, 1])}, "NaN"), (short, "2 points")]:
        with pytest.raises(ModalError, match=message):
            check_functions("f.uff", [{**ok, **change}])
    with pytest.raises(ModalError, match="missing field 'data'"):
        check_functions("f.uff", [{k: v for k, v in ok.items() if k != "data"}])


def test_naming_puts_the_file_in_front_of_messages_that_lack_it():
    from flexmodal.checked_io.text import naming

    with pytest.raises(ModalError, match=r"^runs\.h5:r1: identify: no stable poles$"):
        with naming("runs.h5:r1", ModalError):
            raise ModalError("identify: no stable poles")
    with pytest.raises(ModalError, match=r"^runs\.h5:r1: record too short$"):  # not named twice
        with naming("runs.h5:r1", ModalError):
            raise ModalError("runs.h5:r1: record too short")
    with pytest.raises(KeyError):  # other errors pass unchanged
        with naming("runs.h5:r1", ModalError):
            raise KeyError("x")


@pytest.mark.parametrize("call", ["acquire", "compute_frfs", "compute_frf", "report", "write_diagnosis"])
def test_api_functions_that_write_probe_their_output_before_any_work(tmp_path, monkeypatch, call):
    """The output's folder is a regular file: each API writer fails at once with its package's error
    naming the path, before the work it guards (replaced here by a function that must not run)."""
    from flexmodal import api
    from flexmodal.compare.errors import CompareError
    from flexmodal.compare.result import Diagnosis
    from flexmodal.reports.errors import ReportError

    def never(*_args, **_kw):
        raise AssertionError("the work started before the output was checked")

    (tmp_path / "plain").write_text("not a folder")
    bad = tmp_path / "plain" / "out.h5"
    run = tmp_path / "run.h5"
    with RunWriter(run, "r1", sample_rate_hz=256.0, channels=[Channel("F", "force", "N"),
                   Channel("a", "acceleration", "m/s^2")], excitation="random", pose={}) as w:
        w.append(np.random.default_rng(0).standard_normal((4096, 2)))
    cases = {
        "acquire": (DaqError, "flexmodal.daq.acquire.acquire",
                    lambda: api.acquire(SESSIONS / "serial-sim.toml", bad)),
        "compute_frfs": (ModalError, "flexmodal.modal.batch.frf_batch",
                         lambda: api.compute_frfs([run], out=bad)),
        "compute_frf": (ModalError, "flexmodal.modal.compute.compute_frf",
                        lambda: api.compute_frf(_moved(api.read_run(run), bad), store=True)),
        "report": (ReportError, "flexmodal.daq.store.expand_runs", lambda: api.report(bad, runs=[run])),
        "write_diagnosis": (CompareError, "flexmodal.compare.result.Diagnosis.to_json",
                            lambda: api.write_diagnosis(Diagnosis.from_json(DIAGNOSIS.read_text()),
                                                        tmp_path / "plain" / "diag")),
    }
    error, work, act = cases[call]
    monkeypatch.setattr(work, never)
    with pytest.raises(error, match=str(tmp_path / "plain")):
        act()


SESSIONS = Path(__file__).resolve().parents[1] / "examples" / "sessions"
DIAGNOSIS = Path(__file__).resolve().parent / "data" / "diagnosis" / "blind_none.json"


def _moved(run, path: Path):
    """``run`` as if it were stored in ``path``."""
    import dataclasses

    return dataclasses.replace(run, path=path)
