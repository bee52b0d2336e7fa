"""Issue 24: outputs never destroy inputs, and writers cannot half-write.

``checked_io.output`` refuses an output that is an input of the same command (same inode, through symlinks
and hard links), an existing HDF5 file where a table goes, a FIFO, a device or a directory; it writes
regular files only, whole, and through a symlink writes the link's target.  ``modal.runs_io.write_frf``
leaves a complete FRF group or the previous state on a full disk (a real tmpfs where this process may
mount one, else an injected lack of space), an I/O error or a signal.
"""

from __future__ import annotations

import errno
import hashlib
import os
import select
import subprocess
import sys
import time
from collections import namedtuple
from pathlib import Path

import h5py
import numpy as np
import pytest

from flexmodal.checked_io.output import atomic_path, hdf5_output, output_dir, output_file, write_text
from flexmodal.modal import runs_io
from flexmodal.modal.errors import ModalError

sys.path.insert(0, str(Path(__file__).parent))
from test_cli_table import write_run  # noqa: E402  (the table's small valid run)


class Bad(Exception):
    pass


def _digest(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


def test_an_input_is_never_an_output(tmp_path: Path) -> None:
    src = tmp_path / "modes.csv"
    src.write_text("config,mode,freq_hz\nA,1,10\n")
    (tmp_path / "link.csv").symlink_to(src)
    os.link(src, tmp_path / "hard.csv")
    for out in (src, tmp_path / "link.csv", tmp_path / "hard.csv"):
        with pytest.raises(Bad, match="is also an input or output of this command"):
            output_file(out, Bad, inputs=[src])
        with pytest.raises(Bad, match="is also an input or output of this command"):
            output_file(src, Bad, inputs=[out])
    with pytest.raises(Bad, match="diagnosis.json: is also an input"):
        output_dir(tmp_path, Bad, files=["diagnosis.json"], inputs=[_same(tmp_path / "diagnosis.json", src)])
    assert output_file(tmp_path / "new.csv", Bad, inputs=[src, None, "-"]) == tmp_path / "new.csv"


def _same(path: Path, src: Path) -> Path:
    os.link(src, path)
    return src


def test_special_files_and_run_stores_are_refused(tmp_path: Path) -> None:
    fifo = tmp_path / "fifo"
    os.mkfifo(fifo)
    run = tmp_path / "run.h5"
    with h5py.File(run, "w", libver="latest") as f:   # superblock 3, as flexmodal writes run stores
        f["x"] = np.arange(3)
    text = tmp_path / "notes.txt"
    text.write_text("mine\n")
    for call, message in [(lambda: output_file(fifo, Bad, inputs=()), "is a FIFO"),
                          (lambda: hdf5_output(fifo, Bad), "is a FIFO"),
                          (lambda: output_file("/dev/null", Bad, inputs=()), "device or process file"),
                          (lambda: output_file("/dev/stdout", Bad, inputs=()), "device or process file"),
                          (lambda: hdf5_output("/dev/zero", Bad), "device or process file"),
                          (lambda: output_file(run, Bad, inputs=()), "is an HDF5 file"),
                          (lambda: hdf5_output(text, Bad), "not an HDF5 file"),
                          (lambda: output_file(tmp_path, Bad, inputs=()), "is a directory")]:
        with pytest.raises(Bad, match=message):
            call()
    assert hdf5_output(run, Bad) == run and fifo.is_fifo()


def test_a_symlinked_output_keeps_its_link(tmp_path: Path) -> None:
    real = tmp_path / "data" / "table.csv"
    real.parent.mkdir()
    real.write_text("old\n")
    link = tmp_path / "table.csv"
    link.symlink_to(real)
    write_text(output_file(link, Bad, inputs=()), "new\n")
    assert link.is_symlink() and os.readlink(link) == str(real) and real.read_text() == "new\n"
    dangling = tmp_path / "later.csv"
    dangling.symlink_to(tmp_path / "data" / "later.csv")
    write_text(output_file(dangling, Bad, inputs=()), "x\n")
    assert dangling.is_symlink() and (tmp_path / "data" / "later.csv").read_text() == "x\n"


def test_a_full_disk_names_the_output_and_leaves_the_old_file(tmp_path: Path) -> None:
    target = tmp_path / "table.csv"
    target.write_text("old\n")
    with pytest.raises(OSError, match="No space left") as info, atomic_path(target) as tmp:
        tmp.write_text("half")
        raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))
    assert info.value.filename == str(target) and info.value.errno == errno.ENOSPC
    assert "nothing was written" in info.value.strerror
    assert target.read_text() == "old\n" and [p.name for p in tmp_path.iterdir()] == ["table.csv"]


def _frf_groups(path: Path) -> list[str]:
    with h5py.File(path, "r") as f:
        return sorted(f["runs/r1"])


def test_frf_written_into_a_hidden_group_survives_a_failure_half_way(tmp_path: Path, monkeypatch) -> None:
    from flexmodal import api

    run = tmp_path / "run.h5"
    write_run(run)
    first = api.compute_frf(run, store=True)
    before = runs_io.read_frf(run, "r1")
    real_fill = runs_io._fill

    def fail_after_h(out, H, freq_hz, coherence, result):
        out.create_dataset("H", data=H)
        raise OSError(errno.EIO, "injected I/O error after H")

    monkeypatch.setattr(runs_io, "_fill", fail_after_h)
    with pytest.raises(ModalError, match=r"run.h5: run 'r1': cannot write the FRFs \(.*injected I/O"):
        runs_io.write_frf(run, "r1", first)
    monkeypatch.setattr(runs_io, "_fill", real_fill)
    assert _frf_groups(run) == ["channels", "events", "frf", "samples"]
    after = runs_io.read_frf(run, "r1")
    np.testing.assert_array_equal(after.H, before.H)
    assert after.provenance == before.provenance


def _tmpfs(folder: Path, size: str) -> bool:
    """Mount a tmpfs of ``size`` on ``folder``; False where this process may not mount."""
    if os.geteuid() != 0:
        return False
    done = subprocess.run(["mount", "-t", "tmpfs", "-o", f"size={size}", "tmpfs", str(folder)],
                          capture_output=True, timeout=30, check=False)
    return done.returncode == 0


def test_frf_on_a_full_disk_exits_2_and_leaves_the_run_byte_identical(tmp_path: Path, monkeypatch,
                                                                      warm_cli) -> None:
    """A tmpfs with room for the run but not its FRFs (or, where mounting is refused, the same lack of
    room reported by an injected ``shutil.disk_usage``): one line naming the file, exit 2."""
    src = tmp_path / "src.h5"
    write_run(src)
    disk = tmp_path / "disk"
    disk.mkdir()
    mounted = _tmpfs(disk, f"{src.stat().st_size // 1024 + 150}k")
    try:
        run = disk / "run.h5"
        run.write_bytes(src.read_bytes())
        digest = _digest(run)
        if mounted:
            code, stderr = warm_cli.run(["frf", str(run), "--workers", "0"], Path.cwd(), timeout_s=600)
            assert code == 2, stderr
            lines = stderr.strip().splitlines()
            assert len(lines) == 1 and "Traceback" not in stderr
            message = lines[0]
        else:
            usage = namedtuple("usage", "total used free")
            monkeypatch.setattr(runs_io.shutil, "disk_usage", lambda _p: usage(1 << 20, 1 << 20, 150_000))
            from flexmodal import api
            with pytest.raises(ModalError) as info:
                api.compute_frf(run, store=True)
            message = str(info.value)
        assert f"{run}: run 'r1': no space left on the device" in message and "unchanged" in message
        assert _digest(run) == digest
    finally:
        if mounted:
            subprocess.run(["umount", str(disk)], capture_output=True, timeout=30, check=False)


def test_a_stale_partial_group_is_cleared_by_the_next_write(tmp_path: Path) -> None:
    from flexmodal import api

    run = tmp_path / "run.h5"
    write_run(run)
    with h5py.File(run, "a") as f:
        f["runs/r1"].create_group(runs_io.PARTIAL_PREFIX + "dead")
    api.compute_frf(run, store=True)
    assert _frf_groups(run) == ["channels", "events", "frf", "samples"]


@pytest.mark.parametrize("command", [
    "identify {d}/run.h5 --out {d}/run.h5",
    "compare {d}/modes.csv {d}/modes.csv --out {d}/run.h5",
    "compare {d}/modes.csv {d}/modes.csv --out {d}/modes.csv",
    "compare {d}/modes.csv {d}/modes.csv --out {d}/fifo",
    "predict {d}/rig.toml --model fe --poses {d}/poses.csv --out {d}/run.h5",
    "predict {d}/rig.toml --model fe --poses {d}/poses.csv --out {d}/link.csv",
    "report {d}/run.h5 --out {d}/run.h5",
    "identify {d}/run.h5 --out {d}/m.csv --uff {d}/m.csv",
])
def test_cli_refuses_to_destroy_an_input(tmp_path: Path, command: str, warm_cli) -> None:
    from conftest import REPO

    write_run(tmp_path / "run.h5")
    (tmp_path / "modes.csv").write_text(
        (REPO / "examples" / "measured" / "seed003_table3_f1f2.csv").read_text())
    (tmp_path / "rig.toml").write_text((REPO / "examples" / "rigs" / "seed003_two_link.toml").read_text())
    (tmp_path / "poses.csv").write_text("config,pose.theta_deg\ntheta0,0\n")
    (tmp_path / "link.csv").symlink_to(tmp_path / "poses.csv")
    os.mkfifo(tmp_path / "fifo")
    before = {p.name: _digest(p) for p in tmp_path.iterdir() if p.is_file()}
    code, stderr = warm_cli.run(command.replace("{d}", str(tmp_path)).split(), Path.cwd(), timeout_s=600)
    assert code == 2 and len(stderr.strip().splitlines()) == 1, stderr
    assert "Traceback" not in stderr
    assert {p.name: _digest(p) for p in tmp_path.iterdir() if p.is_file()} == before
    assert (tmp_path / "fifo").is_fifo() and (tmp_path / "link.csv").is_symlink()


def test_a_fault_log_is_a_regular_file(tmp_path: Path) -> None:
    """The simulator's fault log: a FIFO (no reader) or a device fails at once, never blocks."""
    from flexmodal.fixtures.errors import FixtureError
    from flexmodal.fixtures.sim_common import FaultLog

    os.mkfifo(tmp_path / "fifo")
    for path, message in [(tmp_path / "fifo", "cannot write the fault log"),
                          ("/dev/null", "character device, not a regular file")]:
        with pytest.raises(FixtureError, match=message):
            FaultLog(path)
    log = FaultLog(tmp_path / "faults.log")
    log.write("drop", at_s=1.5)
    log.close()
    assert (tmp_path / "faults.log").read_text() == '{"fault": "drop", "at_s": 1.5}\n'


def test_the_live_display_ends_its_last_frame_with_a_newline(capsys) -> None:
    """On a stream that is not a terminal rich prints the last frame at the end without a newline; the
    display adds it, so an error line printed next starts on its own line."""
    from collections import Counter

    from flexmodal.daq.acquire import Display

    display = Display(("F", "a1"), ("N", "m/s^2"), quiet=False)
    display.update(2048, 2048.0, 0, Counter(), force=True)
    display.close()
    err = capsys.readouterr().err
    assert "acquiring" in err and err.endswith("\n") and not err.endswith("\n\n")


def test_acquire_whose_terminal_closes_keeps_the_run_and_its_result_line(tmp_path: Path) -> None:
    """stderr is a terminal (a pty, not the controlling one: no SIGHUP) that closes while the run goes
    on, so the live view's next frames, the last one at the end included, meet EIO.  The view ends, the
    run is recorded whole, the result line reaches stdout and the exit code is 0 - not the 1 of a
    traceback (the line went through rich's stdout proxy into the dead terminal: `acquire` died after a
    SIGHUP 1 run in 8)."""
    from test_daq_shutdown import START_S, plain_run, session_file, stored

    out = tmp_path / "run.h5"
    master, slave = os.openpty()
    proc = subprocess.Popen([sys.executable, "-m", "flexmodal", "acquire", "--config",
                             str(session_file(tmp_path, "serial")), "--out", str(out), "--duration", "4"],
                            stdin=subprocess.DEVNULL, stdout=subprocess.PIPE, stderr=slave, text=True)
    os.close(slave)
    try:
        end = time.monotonic() + START_S
        while stored(out) < 2048 and time.monotonic() < end:
            if select.select([master], [], [], 0.05)[0]:
                os.read(master, 65536)  # a live terminal while the first second is recorded
        os.close(master)  # then it goes away; the last frame is drawn after 4 s of samples
        stdout, _ = proc.communicate(timeout=START_S)
    finally:
        proc.kill()
    assert proc.returncode == 0 and stdout.startswith(f"{out}\t") and "8192 samples" in stdout, stdout
    assert plain_run(out)[0].shape[0] == 8192


def test_an_error_with_stderr_gone_still_exits_2(tmp_path: Path) -> None:
    """The one-line message cannot be written (stderr is a closed terminal): the exit code still says
    bad input, 2, not the 1 of the traceback that writing the message again raised."""
    master, slave = os.openpty()
    os.close(master)
    try:
        done = subprocess.run([sys.executable, "-m", "flexmodal", "identify", str(tmp_path / "none.h5")],
                              stdin=subprocess.DEVNULL, stdout=subprocess.PIPE, stderr=slave, timeout=300)
    finally:
        os.close(slave)
    assert done.returncode == 2 and done.stdout == b""


@pytest.mark.parametrize("command", [
    "compare {d}/modes.csv {d}/modes.csv --out {m}/table.md",
    "predict {d}/rig.toml --model fe --poses {d}/poses.csv --out {m}/pred.csv",
    "identify {d}/run.h5 --method peak --out {m}/modes.csv",
    "report --measured {d}/modes.csv --out {m}/report.html",
])
def test_every_writer_on_a_full_disk_exits_2_with_one_line(tmp_path: Path, command: str, monkeypatch,
                                                           capsys, warm_cli) -> None:
    """A full tmpfs (or, where mounting is refused, an injected ENOSPC at the final rename): exit 2, one
    line naming the output, nothing left on the device."""
    from conftest import REPO

    write_run(tmp_path / "run.h5")
    (tmp_path / "modes.csv").write_text(
        (REPO / "examples" / "measured" / "seed003_table3_f1f2.csv").read_text())
    (tmp_path / "rig.toml").write_text((REPO / "examples" / "rigs" / "seed003_two_link.toml").read_text())
    (tmp_path / "poses.csv").write_text("config,pose.theta_deg\ntheta0,0\n")
    disk = tmp_path / "disk"
    disk.mkdir()
    args = command.replace("{d}", str(tmp_path)).replace("{m}", str(disk)).split()
    if _tmpfs(disk, "64k"):
        try:
            with open(disk / "fill", "wb", buffering=0) as fh, pytest.raises(OSError):   # fill it up
                while True:
                    fh.write(b"\0" * 4096)
            code, err = warm_cli.run(args, Path.cwd(), timeout_s=300)
            left = sorted(p.name for p in disk.iterdir())
        finally:
            subprocess.run(["umount", str(disk)], capture_output=True, timeout=30, check=False)
    else:
        from flexmodal.app import main
        from flexmodal.checked_io import output as valid_output

        def full(_src, _dst):
            raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))

        monkeypatch.setattr(valid_output.os, "replace", full)
        code, err = main(["--quiet", *args]), capsys.readouterr().err
        left = sorted(p.name for p in disk.iterdir() if p.name != "fill")
    lines = err.strip().splitlines()
    assert code == 2 and "Traceback" not in err, err[-2000:]
    assert lines[-1].startswith(f"flexmodal: error: {disk}/") and "No space left on device" in lines[-1], err
    assert left in ([], ["fill"])
