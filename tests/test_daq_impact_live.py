"""Live hit screening in the terminal: an impact session on the serial simulator with an injected double
hit and an overload, its live view read from a pseudo-terminal; and the screening rules on known pulses."""

from __future__ import annotations

import fcntl
import os
import pty
import re
import select
import struct
import subprocess
import sys
import termios
import time
from pathlib import Path

import numpy as np
from cpu_wait import CpuWait

from flexmodal.daq.hits import HitMonitor, double_hit

REPO = Path(__file__).resolve().parents[1]
ANSI = re.compile(r"\x1b\[[0-9;?]*[A-Za-z]|\x1b\][^\x07]*\x07|\r")


def test_screening_rules_on_known_pulses():
    fs = 1000.0
    f = np.zeros(6000)
    for h in (1000, 2000, 3000, 4000, 5000, 5300):
        f[h:h + 3] = 50.0
    f[2015:2018] = 30.0  # the hammer bounced: a second pulse after the first ended
    f[3000:3003] = 150.0  # beyond the 100 N full scale
    f[4000:4003] = 3.0  # below min_peak
    x = np.convolve(f, np.exp(-np.arange(200) / 30) * np.sin(np.arange(200) * 0.5))[:6000]
    m = HitMonitor(0, 1, fs, 500, 10, 5.0, (100.0, np.inf))
    rows = np.column_stack([f, x])
    for a in range(0, 6000, 100):
        m.add(rows[a:a + 100], a, [h for h in (1000, 2000, 3000, 4000, 5000, 5300) if a <= h < a + 100])
    m.finish()
    assert [(h.row, h.verdict, h.reason) for h in m.hits] == [
        (1000, "accepted", ""), (2000, "rejected", "double hit"), (3000, "rejected", "overload"),
        (4000, "rejected", "too weak"), (5000, "rejected", "cut short"), (5300, "accepted", "")]
    freq, h1, coh = m.h1()  # two identical accepted hits: H1 is the exact ratio, coherence 1
    ref = np.fft.rfft(x[990:1490]) / np.fft.rfft(f[990:1490])
    np.testing.assert_allclose(h1, np.abs(ref), rtol=1e-9)
    np.testing.assert_allclose(coh, 1.0, rtol=1e-9)
    assert not double_hit(np.r_[0, 1.0, 0.5, 0.15, 0.05, 0.0], 1)  # a smooth decay is one hit


def test_a_hit_inside_the_pretrigger_of_the_run_start_is_judged_at_once():
    # the run began 4 samples before a hit (pretrigger 10): no whole window can ever hold it; it was
    # left pending until the run ended (and kept every stored row in memory till then)
    m = HitMonitor(0, 1, 1000.0, 500, 10, 5.0, (100.0, np.inf))
    rows = np.zeros((100, 2))
    rows[4:7, 0] = 50.0
    judged = m.add(rows, 0, [4])
    assert [(h.row, h.verdict, h.reason) for h in judged] == [(4, "rejected", "cut short")]
    assert m.pending == [] and m.rows.shape[0] <= 10 + 500


def test_live_view_shows_rejections_with_reasons_within_a_second(tmp_path):
    text = (REPO / "examples" / "sessions" / "serial-sim.toml").read_text()
    text = text.replace('rig = "../rigs/', f'rig = "{REPO}/examples/rigs/')
    text = text.replace("[simulator]\n", "[simulator]\ndouble_hit_at_s = 2.1\noverload_at_s = 4.1\n")
    text = text.replace('location = "tip"', 'location = "tip"\nfull_scale = 199.9')  # F clips at 200 N
    # The simulated record (8 s) has hits at 0.1, 2.1, 4.1 and 6.1 s; the run starts o seconds into it
    # (0-0.5 s, more under load); 7.5 s hold the double hit, the overload and a whole accepted window
    # (1 s) for any o below 2 s (6.5 s held none for 0.07 < o < 0.57 s: seen at o = 0.42 under load).
    config = tmp_path / "impact.toml"
    config.write_text("reconnect_timeout_s = 120.0\n" + text)  # a starved simulator is not a lost device
    master, slave = pty.openpty()
    fcntl.ioctl(slave, termios.TIOCSWINSZ, struct.pack("HHHH", 60, 200, 0, 0))
    env = {**os.environ, "COLUMNS": "200", "LINES": "60", "TERM": "xterm-256color"}
    proc = subprocess.Popen([sys.executable, "-m", "flexmodal", "acquire", "--config", str(config), "--out",
                             str(tmp_path / "run.h5"), "--duration", "7.5"], cwd=REPO,
                            stdin=subprocess.DEVNULL, stdout=subprocess.PIPE, stderr=slave, env=env)
    os.close(slave)
    screen, arrived = b"", []  # bytes of the terminal, and (end offset, time) of each read
    deadline = time.monotonic() + 300  # the start alone can take a minute on a loaded machine
    with CpuWait(proc.pid) as waits:
        while time.monotonic() < deadline:
            ready, _, _ = select.select([master], [], [], 0.5)
            if ready:
                try:
                    chunk = os.read(master, 65536)
                except OSError:
                    break
                if not chunk:
                    break
                screen += chunk
                arrived.append((len(screen), time.monotonic()))
            elif proc.poll() is not None:
                break
    proc.communicate(timeout=30)
    os.close(master)
    assert proc.returncode == 0
    ends = np.array([e for e, _ in arrived])
    starts = [m.start() for m in re.finditer(b"acquiring", screen)] + [len(screen)]
    frames = []  # (time the refresh reached the terminal, its text), one per refresh of the live view
    for a, b in zip(starts[:-1], starts[1:], strict=True):
        t = arrived[min(int(np.searchsorted(ends, b)), len(arrived) - 1)][1]
        frames.append((t, ANSI.sub("", screen[a:b].decode(errors="replace"))))
    stored = [(t, int(m.group(1)) / 2048.0) for t, f in frames
              if (m := re.search(r"\s+[\d.]+ s\s+(\d+) samples", f))]
    first_seen = {}
    for t, frame in frames:
        for hit_s, reason in re.findall(r"hit at\s+([\d.]+) s .*?REJECTED: ([a-z ]+)", frame):
            first_seen.setdefault(reason, (float(hit_s), t))
    assert {"double hit", "overload"} <= set(first_seen), first_seen
    assert any(re.search(r"hit at +[\d.]+ s  peak +[\d.]+ N  ", f) for _, f in frames)   # the force's unit
    for reason in ("double hit", "overload"):
        hit_s, t_shown = first_seen[reason]
        t_hit = next(t for t, s_ in stored if s_ >= hit_s)  # the hit's samples reached the file
        # within a second, not counting the time acquire's processes (or this test) were runnable but
        # waiting for a CPU (tests/cpu_wait.py): the wall time on a quiet machine, whatever the load
        shown_s = waits.unloaded(t_hit, t_shown)
        print(f"{reason}: shown {shown_s:.2f} s ({t_shown - t_hit:.2f} s wall) after the hit's samples "
              "were stored")
        assert shown_s <= 1.0, f"{reason} shown {shown_s:.2f} s ({t_shown - t_hit:.2f} s wall) after the hit"
    frames = [f for _, f in frames]
    last = frames[-1]
    assert "|H1| a1" in last and "coh" in last and "ACCEPTED" in last


def test_the_live_spectrum_fits_an_80_column_console():
    # off a terminal (acquire > log 2>&1, CI) rich falls back to 80 columns: a 64-column sparkline
    # made the |H1| line ~98 characters and it wrapped onto a second line
    from io import StringIO

    from rich.console import Console
    from rich.live import Live
    from rich.text import Text

    from flexmodal.daq.acquire import Display

    fs = 1024.0
    f = np.zeros(4096)
    f[1000:1003] = 50.0
    x = np.convolve(f, np.exp(-np.arange(200) / 30) * np.sin(np.arange(200) * 0.5))[:4096]
    m = HitMonitor(0, 1, fs, 2048, 10, 5.0, (100.0, np.inf))
    m.add(np.column_stack([f, x]), 0, [1000])
    m.finish()
    for cols, spark in ((80, 38), (200, 64)):
        d = Display(("f1", "a1"), ("N", "m/s2"), quiet=True)
        d.monitor, d.response, d.fs = m, "a1", fs
        d.live = Live(console=Console(file=StringIO(), width=cols), auto_refresh=False)
        h1, coh = (str(t) for t in d._impact_lines(Text)[-2:])
        assert h1.startswith("  |H1| a1  ") and len(h1) <= cols, (cols, h1)
        assert len(h1.split("  ")[2]) == spark and h1.index("0-") == coh.index("0..1")   # aligned


def test_the_live_status_is_two_lines_of_its_own_in_80_columns():
    # as the table's title the status (about 130 characters) was wrapped to the table's width and
    # centred: three ragged lines on every terminal and in a log
    from collections import Counter
    from io import StringIO

    from rich.console import Console
    from rich.live import Live

    from flexmodal.daq.acquire import Display

    out = StringIO()
    d = Display(("F", "a1"), ("N", "m/s^2"), quiet=True)
    d.live = Live(console=Console(file=out, width=80), auto_refresh=False)
    d.live.start()
    d.update(123456, 2048.0, 0, Counter(trigger=3, gap=1), force=True)
    d.close()
    lines = out.getvalue().splitlines()
    status = r"acquiring +[\d.]+ s   123456 samples   [\d,]+ S/s \(nominal 2048\)"
    assert re.fullmatch(status, lines[0]), lines
    assert lines[1] == "  drops 0   corrupt 0   gaps 1   reconnects 0   triggers 3", lines
    assert lines[2].startswith("┏") and all(len(line) <= 80 for line in lines), lines
