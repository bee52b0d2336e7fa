"""The end-to-end demo: runs on the embedded simulated rig, leaves an HDF5 run file (docs/hdf5-format.md)
and a report."""

from __future__ import annotations

import json
import re
import subprocess
import sys
import time
from pathlib import Path

import h5py
import numpy as np
import pytest
from browser import assert_table_and_plot_visible, render
from conftest import REPO

CHANNEL_FIELDS = {"name", "kind", "unit", "sensitivity", "sensitivity_unit", "location", "direction"}
EVENT_FIELDS = {"kind", "sample_index", "count", "detail"}
EXCITATIONS = {"impact", "random", "sweep", "free-decay", "operational"}


@pytest.fixture(scope="module")
def demo_dir(demo_run) -> tuple[Path, float, str]:
    """(folder, seconds, stdout) of the session's demo (tests/conftest.py ``demo_run``)."""
    out, elapsed, stdout, *_ = demo_run
    return out, elapsed, stdout


def test_demo_finishes_in_under_two_minutes_and_leaves_its_files(demo_dir: tuple[Path, float, str]) -> None:
    out, elapsed, stdout = demo_dir
    assert elapsed < 120.0
    assert (out / "runs.h5").is_file() and (out / "report.html").is_file()
    assert str(out / "report.html") in stdout


def test_demo_hdf5_holds_every_contract_item_with_plain_h5py(demo_dir: tuple[Path, float, str]) -> None:
    out, _, _ = demo_dir
    with h5py.File(out / "runs.h5", "r") as f:
        runs = f["runs"]
        assert len(runs) >= 6  # impact + random in at least three poses
        excitations = set()
        for run_id, run in runs.items():
            attrs = run.attrs
            assert float(attrs["sample_rate_hz"]) > 0
            time.strptime(str(attrs["start_time"])[:19], "%Y-%m-%dT%H:%M:%S")
            assert attrs["excitation"] in EXCITATIONS
            excitations.add(attrs["excitation"])
            assert isinstance(json.loads(attrs["pose"]), dict)
            samples = run["samples"]
            assert samples.ndim == 2 and samples.dtype in (np.float32, np.float64)
            assert samples.chunks is not None and samples.maxshape[0] is None
            channels = run["channels"]
            assert CHANNEL_FIELDS <= set(channels.dtype.names)
            assert channels.shape[0] == samples.shape[1]
            assert EVENT_FIELDS <= set(run["events"].dtype.names)
            frf = run["frf"]
            n_out, n_in, n_freq = frf["H"].shape
            assert np.iscomplexobj(frf["H"][()]) and frf["freq_hz"].shape == (n_freq,)
            assert frf["coherence"].shape == (n_out, n_freq)
            for key in ("estimator", "window", "nfft", "n_averages"):
                assert key in frf.attrs, (run_id, key)
        assert {"impact", "random"} <= excitations


def test_demo_report_renders_in_headless_chromium(demo_dir: tuple[Path, float, str], chromium: str,
                                                  tmp_path: Path) -> None:
    out, _, _ = demo_dir
    page = render(chromium, out / "report.html", tmp_path / "profile")
    assert_table_and_plot_visible(page)
    text = (out / "report.html").read_text()
    assert "f [Hz]" in text and "theta30-impact" in text


def test_demo_diagnosis_finds_the_elbow_with_a_realistic_residual(demo_dir: tuple[Path, float, str]) -> None:
    """The demo's "real" arm is the independent truth model (``bench_arm``): the held-out gap after the
    verdict stays between 0.3 % and 2 % (a model-form residual, not a circular 0.00 %) and the hidden
    joint stiffness at the elbow is one of the verdict's components.  The verdict itself is the
    diagnosis's (compare/): with this truth it adds a second component that absorbs the model form
    (``link_stiffness`` of link2 or ``joint_mass`` at the elbow, reported as ambiguous), so the exact
    effect string is not asserted here."""
    out, _, stdout = demo_dir
    v = json.loads((out / "diagnosis.json").read_text(), parse_constant=lambda c: pytest.fail(c))["verdict"]
    assert "joint_stiffness" in v["effect"].split("+") and "elbow" in v["location"].split("+"), v
    assert 0.003 <= v["heldout_rms_rel_error_after"] <= 0.02
    said = re.search(r"^fits as well within noise: (.*)$", stdout, re.MULTILINE)
    assert bool(said) == v["ambiguous"]                    # the demo prints the ambiguity it was told
    assert all(f"{a['effect']} at {a['location']}" in said.group(1) for a in v["alternatives"] if said)
    advice = re.search(r"^next measurement: (.*)$", stdout, re.MULTILINE)   # advised poses, or why none
    assert bool(advice) == bool(v["ambiguous"] or v["next_measurements"])
    first = v["next_measurements"][0]["pose"] if v["next_measurements"] else "no pose is advised"
    assert not advice or advice.group(1).startswith(first)


def test_demo_records_come_from_the_truth_model(demo_dir: tuple[Path, float, str]) -> None:
    """Every record the demo analyses is the truth model's: operational.h5 is ``operational_test``'s
    record, and at every pose (theta30's impact run acquired through the serial simulator included) the
    identified frequencies are the truth model's within 0.3 % and more than 1 % from the diagnosis's FE
    model (with the same hidden spring) on some mode."""
    from flexmodal.contract.table import ModalTable
    from flexmodal.daq.store import read_run
    from flexmodal.fixtures.demo import (
        DEMO_POSES,
        OPERATIONAL_POSE,
        campaign_plan,
        operational_test,
        run_effects,
    )
    from flexmodal.fixtures.rig_sim import DEMO_RIG, simulate
    from flexmodal.fixtures.truth_arm import bench_arm
    from flexmodal.models.rig import load_rig

    out, _, _ = demo_dir
    rig = load_rig(DEMO_RIG)
    stored = read_run(out / "operational.h5", OPERATIONAL_POSE).samples
    np.testing.assert_allclose(stored, operational_test(rig).samples.astype(stored.dtype), rtol=0, atol=0)
    measured = ModalTable.read_csv(out / "modes.csv")
    assert sorted(measured.configs) == sorted(run_id for run_id, *_ in campaign_plan())
    for run_id, config, _, seed in campaign_plan():
        found = measured.freq_hz(run_id)
        n = found.size
        pose, hidden = DEMO_POSES[config], run_effects(seed)
        real = simulate(rig, pose, duration_s=0.1, effects=hidden, truth=bench_arm(rig)).natural_freq_hz
        fe = simulate(rig, pose, duration_s=0.1, effects=hidden).natural_freq_hz
        np.testing.assert_allclose(found, real[:n], rtol=3e-3, err_msg=run_id)
        assert np.max(np.abs(found / fe[:n] - 1)) > 0.01, (run_id, found, fe[:n])


def test_demo_scatter_is_a_real_arms_repeatability(demo_dir: tuple[Path, float, str]) -> None:
    """The measurement scatter the demo's diagnosis prints comes from its repeated tests (a pose's
    impact and random runs) and is of the size a real arm's repeated tests show: seed 003's Table 4
    gives coefficients of variation of 0.31-0.85 % over five independent tests per pose
    (the paper's table seed003_table4_repeatability.csv, copied below).
    Before each test drew its own arm (``REASSEMBLY_SD``) the demo printed 0.0003 %."""
    table4_cv_percent = [0.31, 0.38, 0.41, 0.56, 0.48, 0.85, 0.50, 0.61]   # seed 003, Table 4
    out, _, stdout = demo_dir
    src = json.loads((out / "diagnosis.json").read_text())["scatter_source"]
    assert src["source"] == "repeated configurations"
    assert min(table4_cv_percent) / 2 <= 100 * src["measurement"] <= max(table4_cv_percent), src
    line = r"^scatter: .*; measurement scatter m = [\d.]+ % \(repeated configurations: "
    assert re.search(line, stdout, re.MULTILINE), stdout


def test_demo_report_shows_the_operational_runs_fdd_and_ssi(demo_dir: tuple[Path, float, str]) -> None:
    """api.report computes the output-only results of DIR/operational.h5, reports/oma.py draws them."""
    out, _, _ = demo_dir
    text = (out / "report.html").read_text()
    for what in ("FDD, singular values of the output cross-spectral", "SSI-cov stabilisation diagram"):
        assert re.search(r'<img src="data:image/png;base64,[\w+/=]+" alt="operational\.h5::theta30: '
                         + re.escape(what), text), what


def test_demo_report_lists_the_ssi_modes_the_demo_prints(demo_dir: tuple[Path, float, str]) -> None:
    """The demo and its report identify the operational run with the same band (api.report's oma_fmin,
    oma_fmax): the SSI modes in the report's caption are the ones printed, and no other."""
    out, _, stdout = demo_dir
    line = re.search(r"output-only \(SSI\) on the arm in operation at theta30: ([^;]*) Hz;", stdout).group(1)
    printed = [float(f) for f in line.split(", ")]
    caption = re.search(r"operational\.h5::theta30: SSI-cov stabilisation diagram, orders \d+-\d+ [^;]*; "
                        r"modes ([^(]*) \(unscaled", (out / "report.html").read_text()).group(1)
    listed = [float(f) for f in re.findall(r"([\d.]+) Hz", caption)]
    assert len(printed) == 3 and len(listed) == len(printed), (printed, listed)
    assert np.allclose(listed, printed, rtol=1e-3)   # 4 significant digits vs 2 decimals


def test_demo_and_the_cli_chain_on_the_same_runs_give_the_same_verdict(demo_dir: tuple[Path, float, str],
                                                                        tmp_path: Path, warm_cli) -> None:
    """Issue 26 (a): the documented chain ``frf -> identify -> diagnose`` on the demo's runs, where each
    pose's impact and random runs are repeated configurations (each test of its own arm: scatter of the
    repeats ~0.4 %), gives the demo's verdict.
    The demo prints the graded verdict (share of the gap removed, what remains) and the scatter.
    ``frf`` and ``identify`` run as the console script started warm (tests/conftest.py warm_cli),
    ``diagnose`` as ``python app.py`` started cold (its printed scatter is read)."""
    from flexmodal.fixtures.rig_sim import DEMO_RIG

    out, _, stdout = demo_dir
    runs = tmp_path / "runs.h5"
    runs.write_bytes((out / "runs.h5").read_bytes())
    modes = str(tmp_path / "modes.csv")
    for cmd in (["frf", str(runs), "--quiet"],
                ["identify", str(runs), "--out", modes, "--fmin", "5", "--fmax", "450"]):
        code, stderr = warm_cli.run(cmd, tmp_path, timeout_s=600)
        assert code == 0, stderr
    done = subprocess.run([sys.executable, str(REPO / "app.py"), "diagnose", "--rig", str(DEMO_RIG),
                           "--measured", modes, "--out", str(tmp_path / "d")],
                          capture_output=True, text=True, timeout=600)
    assert done.returncode == 0, done.stderr
    chain = json.loads((tmp_path / "d" / "diagnosis.json").read_text())
    demo = json.loads((out / "diagnosis.json").read_text())
    assert chain["scatter_source"]["source"] == "repeated configurations"
    assert (chain["verdict"]["effect"], chain["verdict"]["location"]) == \
        (demo["verdict"]["effect"], demo["verdict"]["location"])
    assert "scatter:" in done.stdout and "model-form floor" in done.stdout
    graded = re.search(r"^(largely |partly )?explained: \d+ % of the held-out gap removed "
                       r"\(from .* to .*\); (the remaining .* is .* the measurement scatter|what remains)",
                       stdout, re.MULTILINE)
    assert graded, stdout
    assert "explained: False" not in stdout and "x the measurement scatter 0.00%" not in stdout
    assert "model-form floor" in stdout


def test_the_demo_tells_a_log_each_step(demo_run):
    """stderr is not a terminal here (as in CI or a log file): one line per step instead of the bar."""
    stderr = demo_run[4]
    steps = re.findall(r"^demo: step (\d)/5: [a-zA-Z +]+(?: \(at \d+ s\))?$", stderr, re.MULTILINE)
    assert steps == ["1", "2", "3", "4", "5"], stderr
    # the report, the longest step (its 11 runs' figures), says what it is drawing: it was one line, then
    # a minute of silence; and the log ends saying the demo is done
    lines = stderr.splitlines()
    report = lines[next(k for k, line in enumerate(lines) if line.startswith("demo: step 5/5: report")) + 1:]
    plotted = [line for line in report if re.match(r"^demo: report: plotting run \d+/11: ", line)]
    assert len(plotted) == 11 and plotted[-1].endswith("operational.h5::theta30"), stderr
    assert re.fullmatch(r"demo: done \(in \d+ s\)", report[-1]), stderr



UNIT_WORDS = {"Hz": "_hz", "deg": "_deg", "degrees": "_deg", "kg": "_kg"}   # a unit stated: its name suffix
NO_UNIT = re.compile(r"^- |fraction|whole number|mode-shape value|text|who produced")   # said to have none


def test_every_column_the_demo_writes_is_documented_with_its_unit(demo_dir: tuple[Path, float, str]) -> None:
    """A reader of modes.csv or fe.csv finds each header in docs/formats.md's modal table columns, and there
    its unit, or that it has none (``- (0..1)``, a fraction, a whole number); a column with a unit names
    it in its header as freq_hz does (``mpd`` was in degrees with no unit in its name: ``mpd_deg``), pose
    columns too (``pose.theta_deg``); and every number column of the table the demo prints has its unit
    in brackets in its header (``fe f [Hz]``, ``experiment ζ [%]``, ``fe MAC [-]``)."""
    out, _, stdout = demo_dir
    formats = (REPO / "docs" / "formats.md").read_text(encoding="utf-8")
    documented = dict(re.findall(r"^\| `([^`]+)` \| (.+) \|$", formats, re.MULTILINE))   # name: its cells
    for name in ("modes.csv", "fe.csv"):
        header = (out / name).read_text().splitlines()[0].split(",")
        generic = [re.sub(r"^pose\..*", "pose.<var>", re.sub(r"^shape\..*", "shape.<sensor>", c))
                   for c in header]
        assert {"mpc", "mpd_deg", "freq_std_hz"} <= set(header) or name == "fe.csv", header
        assert [c for c in generic if c not in documented] == [], (name, header)
        for column in set(generic) - {"config", "pose.<var>", "shape.<sensor>"}:
            doc = documented[column]
            units = [u for u in UNIT_WORDS if re.search(rf"\b{u}\b", doc)]
            assert units or NO_UNIT.search(doc), (column, doc)              # a unit, or said to have none
            assert all(column.endswith(UNIT_WORDS[u]) for u in units), (column, doc)   # in its name
        assert all(re.search(r"_(deg|kg|m)$", c) for c in header if c.startswith("pose.")), header
    printed = next(line for line in stdout.splitlines() if line.startswith("| config | mode |"))
    cells = [c.strip() for c in printed.strip("|").split("|")][2:]
    assert cells and all(re.search(r" \[(Hz|%|-)\]$", c) for c in cells), printed


def test_what_the_demo_points_a_reader_to_is_in_the_docs(demo_dir: tuple[Path, float, str]) -> None:
    """The demo named a source file (fixtures/truth_arm.py) for what its simulated arm is; it names the
    section of docs/ that describes it, and that section exists."""
    _, _, stdout = demo_dir
    pointed = re.findall(r"\((docs/[\w-]+\.md), \"([^\"]+)\"\)", stdout)
    assert pointed and "fixtures/" not in stdout, stdout
    for doc, section in pointed:
        assert re.search(rf"^#+ {re.escape(section)}\b", (REPO / doc).read_text(encoding="utf-8"), re.M), doc
