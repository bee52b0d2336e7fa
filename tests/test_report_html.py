"""The HTML report from real stored runs: content, self-containment, CLI, and headless Chromium.

Runs are simulated on the demo arm (fixtures.rig_sim, hidden elbow compliance; two random shaker
tests and one impact test), stored with daq.store.RunWriter, their FRFs computed and stored by the modal
package (modal.compute.compute_frf, modal.runs_io.write_frf: the ``frf`` group of docs/hdf5-format.md).
The report is computed by ``flexmodal.api.report`` and rendered by ``reports.html.write_report``.
Chromium is driven over the DevTools protocol (tests/browser.py).  Chromium missing is a failure, not a
skip.
"""

from __future__ import annotations

import base64
import io
import json
import re
from pathlib import Path

import h5py
import pytest
from browser import assert_table_and_plot_visible, evaluate, page_width, render
from matplotlib import image as mpimg

from flexmodal import api
from flexmodal.app import main
from flexmodal.contract.table import ModalTable
from flexmodal.daq.store import Event, RunWriter, read_run
from flexmodal.fixtures.rig_sim import HiddenEffect, simulate
from flexmodal.modal.compute import compute_frf
from flexmodal.modal.runs_io import write_frf
from flexmodal.models.frame import frame_modes
from flexmodal.models.rig import load_rig

POSES = {"theta0": {"theta_deg": 0.0}, "theta60": {"theta_deg": 60.0}, "theta120": {"theta_deg": 120.0}}
IMPACT_CONFIG = "theta120"
RUN_IDS = ("theta0-random", "theta60-random", "theta120-impact")
FS_HZ = 1024.0
DIAGNOSIS = {
    "baseline": {"rms_rel_error": 0.12, "max_rel_error": 0.25, "per_mode": {"1": 0.04, "2": 0.21},
                 "per_config": {"theta0": 0.1}},
    "where": {"modes": [2], "configs": ["theta0", "theta60"], "region": "joint:elbow"},
    "ranking": [{"effect": "joint_stiffness", "location": "elbow", "params": {"k_Nm_per_rad": 1500.0},
                 "fit_rms_rel_error": 0.004, "heldout_rms_rel_error": 0.006, "n_params": 1, "score": 0.0,
                 "per_mode": {"1": 0.003, "2": 0.005}},
                {"effect": "grounded_spring+joint_stiffness", "location": "link2@0.75+elbow",
                 "params": {"k_N_per_m": 495.8, "k_Nm_per_rad": 5960.0}, "fit_rms_rel_error": 0.0041,
                 "heldout_rms_rel_error": 0.0065, "n_params": 2, "score": 0.1}],
    "verdict": {"effect": "joint_stiffness", "location": "elbow", "heldout_rms_rel_error_before": 0.19,
                "heldout_rms_rel_error_after": 0.006, "explained": True},
}


def _modal_table(freq_hz, shapes, sensors, config, pose, source, damping=None):
    recs = []
    for k, f in enumerate(freq_hz):
        rec = {"config": config, "mode": k + 1, "freq_hz": float(f), "source": source,
               **{f"pose.{v}": x for v, x in pose.items()},
               **{f"shape.{s}": float(shapes[i, k]) for i, s in enumerate(sensors)}}
        if damping is not None:
            rec["damping_ratio"] = float(damping[k])
        recs.append(rec)
    return recs


@pytest.fixture(scope="module")
def inputs(rigs_dir, tmp_path_factory):
    """Stored runs with FRFs, measured and predicted tables, a diagnosis: what the demo hands over."""
    tmp = tmp_path_factory.mktemp("report")
    rig = load_rig(rigs_dir / "demo_arm.toml")
    runs = tmp / "runs.h5"
    measured, predicted = [], []
    effect = (HiddenEffect("joint_stiffness", "elbow", {"k_Nm_per_rad": 1500.0}),)
    for i, (config, pose) in enumerate(POSES.items()):
        excitation = "impact" if config == IMPACT_CONFIG else "random"
        test = simulate(rig, pose, excitation=excitation, duration_s=4.0, sample_rate_hz=FS_HZ,
                        effects=effect, seed=i, n_modes=4, hit_period_s=1.0)
        run_id = f"{config}-{excitation}"
        with RunWriter(runs, run_id, sample_rate_hz=FS_HZ, channels=test.channels, excitation=excitation,
                       pose=dict(pose)) as w:
            w.append(test.samples)
            w.add_events(test.events)
            # one clipped stretch inside the second hit's record: the impact processing rejects that hit
            w.add_event(Event("overload", int(1.15 * FS_HZ), 3, "a3 clipped"))
        write_frf(runs, run_id, compute_frf(read_run(runs, run_id), nfft=512))
        measured += _modal_table(test.natural_freq_hz[:4], test.shapes[:, :4], test.sensor_names, config,
                                 pose, "experiment", test.damping_ratio[:4])
        fe = frame_modes(rig, pose, 4)
        predicted += _modal_table(fe.freq_hz, fe.sensor_shapes, fe.sensor_names, config, pose, "fe")
    paths = {"runs": runs, "measured": tmp / "modes.csv", "pred": tmp / "fe.csv",
             "diag": tmp / "diagnosis.json",
             "rig": rigs_dir / "demo_arm.toml", "dir": tmp}
    ModalTable.from_records(measured, "experiment").to_csv(paths["measured"])
    ModalTable.from_records(predicted, "fe").to_csv(paths["pred"])
    paths["diag"].write_text(json.dumps(DIAGNOSIS))
    return paths


@pytest.fixture(scope="module")
def report(inputs):
    return api.report(inputs["dir"] / "report.html", runs=[inputs["runs"]],
                      measured=ModalTable.read_csv(inputs["measured"]),
                      predictions=[ModalTable.read_csv(inputs["pred"])], diagnosis=DIAGNOSIS,
                      rig=load_rig(inputs["rig"]), title="demo arm validation",
                      progress=inputs.setdefault("told", []).append)


def test_report_progress_is_one_line_per_run(inputs, report):
    # it was two per run (reading and identifying each, then plotting each): 25 lines for the demo's 10
    told = inputs["told"]
    runs = [m for m in told if "run" in m]
    plotted = [f"plotting run {k}/{len(RUN_IDS)}: runs.h5::{run_id}" for k, run_id in enumerate(RUN_IDS, 1)]
    assert runs == [f"reading and identifying {len(RUN_IDS)} runs of runs.h5", *plotted], told


def test_report_is_self_contained_and_holds_every_section(report):
    html = report.read_text()
    assert "<script src" not in html and "<link" not in html
    assert not re.search(r"""(src|href)\s*=\s*["'](?!data:|#)""", html)  # nothing fetched
    assert "http://" not in html and "https://" not in html
    for heading in ("Measured and predicted modes", "Sim-to-real gap diagnosis", "Stored runs", "Channels",
                    "Data quality", "Gap before and after the diagnosed effect", "Modes across poses"):
        assert heading in html
    positions = [html.index(f"<td>runs.h5::{run}</td>") for run in RUN_IDS]
    assert positions == sorted(positions)  # data-quality rows in pose order: 0, 60, 120 deg
    assert html.count(">1 / 3<") == 3  # one overload event of three samples per run
    images = re.findall(r'src="data:image/png;base64,([A-Za-z0-9+/=]+)"', html)
    # freq vs pose, test-model MAC, 2 mode-shape figures; per run: FRF, stabilisation diagram with the
    # selected poles, synthesis overlay, AutoMAC; the gap plot
    assert len(images) == 17
    for b64 in images:
        pixels = mpimg.imread(io.BytesIO(base64.b64decode(b64)), format="png")
        assert pixels.std() > 0.02


def test_report_shows_the_identification_of_each_run(report):
    html = report.read_text()
    for run in RUN_IDS:
        label = f"runs.h5::{run}"
        # what the figure shows first (axes with units, symbols, the stability criteria), then how the
        # model order was chosen, in sentences (it quoted identify's dense order note)
        assert re.search(re.escape(label) + r": stabilisation diagram of the pLSCF identification\. "
                         r"Horizontal: frequency \[Hz\]; left: model order \[-\], .*; right: the CMIF .* "
                         r"\[\(m/s²\)/N\], log scale, .* Filled dots: poles stable from one order to the "
                         r"next \(frequency within 1 %, damping ratio within 5 %, shape MAC ≥ 0\.98\); .*"
                         r"black crosses: the poles of the \d+ selected modes, at .* Hz \(dotted lines\); "
                         r"shaded: the identification band, .* Hz\. Model order \d+ used", html)
        assert "basis exp(" not in html and "w dt" not in html
        assert f"{label}: measured FRFs and the FRFs synthesised from the identified modes" in html
        assert f"{label}: AutoMAC of the identified shapes" in html
    assert "theta0: MAC of the measured shapes against fe&#39;s at the" in html


def test_report_tables_carry_units_and_numbers(report, inputs):
    html = report.read_text()
    for header in ("experiment f [Hz]", "experiment ζ [%]", "fe Δf [%]", "fe MAC [-]", "sample rate [Hz]",
                   "duration [s]", "mean coherence [-]", "held-out RMS error before / after [%]"):
        assert header in html
    measured = ModalTable.read_csv(inputs["measured"])
    first = measured.frame.iloc[0]
    assert f"{first['freq_hz']:.2f}" in html
    assert "19 / 0.6" in html  # verdict 0.19 -> 0.006 as percent
    assert "modes 2; configurations theta0, theta60; region joint:elbow" in html
    # the runs share their channels, so one table lists them all: its peak is the largest of the runs
    # (it showed the first run's peaks under every run's name)
    with h5py.File(inputs["runs"], "r") as f:
        force = [float(abs(f[f"runs/{r}/samples"][:, 0]).max()) for r in RUN_IDS]
    assert f"largest peak |x| of the {len(RUN_IDS)} runs [unit]" in html
    assert '<td>F</td>' in html and f'<td class="num">{max(force):.4g} N</td>' in html
    # units as on the figures' axes (m/s²), not as the run file stores them (m/s^2): the channel table
    # showed m/s^2 beside figures labelled m/s²
    shown = re.sub(r"<script.*?</script>|<[^>]+>", " ", html, flags=re.S)
    assert "<td>m/s²</td>" in html and not re.search(r"(\^|\*\*)-?\d", shown)


def test_data_quality_counts_the_impact_hits_the_frf_processing_kept(report, inputs):
    with h5py.File(inputs["runs"], "r") as f:
        prov = json.loads(f[f"runs/{RUN_IDS[2]}/frf"].attrs["provenance"])
    hits = prov["hits"]
    rejected = [h for h in hits if not h["accepted"]]
    assert len(hits) == 4 and len(rejected) == 1  # hits at 0.1, 1.1, 2.1, 3.1 s; the clipped one rejected
    html = report.read_text()
    quality = html[html.index('id="quality"'):]   # the run's row in the data quality table
    row = quality[quality.index(f"<td>runs.h5::{RUN_IDS[2]}</td>"):]
    row = row[:row.index("</tr>")]
    cells = re.findall(r"<td[^>]*>(.*?)</td>", row, flags=re.S)
    assert cells[1:5] == ["4", "3 / 4", "1", rejected[0]["reason"]]


def test_report_cli_writes_the_same_sections(inputs, capsys):
    out = inputs["dir"] / "cli-report.html"
    argv = ["report", str(inputs["runs"]), "--measured", str(inputs["measured"]),
            "--pred", str(inputs["pred"]),
            "--diagnosis", str(inputs["diag"]), "--rig", str(inputs["rig"]), "--out", str(out), "--quiet"]
    assert main(argv) == 0
    captured = capsys.readouterr()
    assert captured.out.strip() == str(out) and captured.err == ""
    html = out.read_text()
    assert "joint_stiffness at elbow" in html and html.count("data:image/png;base64,") == 17


def test_report_without_runs_or_poses_notes_what_it_cannot_draw(inputs, tmp_path):
    measured = ModalTable.read_csv(inputs["measured"])
    no_pose = ModalTable.from_frame(measured.frame.drop(columns=["pose.theta_deg"]), "no-pose")
    told: list[str] = []
    out = api.report(tmp_path / "r.html", measured=no_pose, rig=load_rig(inputs["rig"]),
                     predictions=[ModalTable.read_csv(inputs["pred"])], progress=told.append)
    html = out.read_text()
    # each figure section is told before it is drawn (the slow part); one with nothing to draw then says
    # so and what it is drawn from, on the next line
    assert "plotting modes across poses" in told
    for title, needs in (("gap before and after the diagnosed effect", "a diagnosis (--diagnosis)"),
                         ("modal map of the moving arm",
                          "a measured table of identify --track (--measured)")):
        k = told.index(f"plotting {title}")
        assert told[k + 1] == f"no {title}: it is drawn from {needs}", told
    assert "No mode shapes drawn for theta0: the measured table gives no pose.theta_deg for the rig" in html
    assert "Stored runs" not in html and "fe Δf [%]" in html
    # nothing varies with pose, no shapes drawn: the one figure is the test-model MAC (needs no pose)
    assert html.count("data:image/png") == 1
    assert "theta0: MAC of the measured shapes against fe&#39;s" in html


def test_report_cli_bad_inputs_exit_2(inputs, tmp_path, capsys):
    bad = tmp_path / "diagnosis.json"
    bad.write_text("{not json")
    assert main(["report", "--diagnosis", str(bad), "--out", str(tmp_path / "r.html")]) == 2
    assert "not valid JSON" in capsys.readouterr().err
    assert main(["report", str(tmp_path / "missing.h5"), "--out", str(tmp_path / "r.html")]) == 2
    assert main(["report", str(bad), "--out", str(tmp_path / "r.html")]) == 2
    assert "not a readable HDF5 run file" in capsys.readouterr().err
    assert main(["report", "--out", str(tmp_path / "r.html")]) == 2
    assert "nothing to report" in capsys.readouterr().err


def test_report_renders_in_headless_chromium_without_errors(report, tmp_path, chromium):
    page = render(chromium, report, tmp_path / "profile")
    assert_table_and_plot_visible(page)
    assert len(page.layout["tables"]) >= 5 and len(page.layout["images"]) == 17


def test_no_table_makes_the_page_scroll_sideways_in_a_narrow_window(report, tmp_path, chromium):
    """At 1000 px (narrower than the body's 1100 px) the data-quality table (13 columns) pushed the page
    wider than the window; now a wide table scrolls in its own box."""
    assert page_width(chromium, report, tmp_path / "profile", 1000) <= 1000


QUALITY_JS = """(() => {
  const t = document.querySelector('#quality').nextElementSibling;
  const cell = t.querySelector('td[data-label]');
  return {table: [t.scrollWidth, t.clientWidth], page: document.documentElement.scrollWidth,
          head: getComputedStyle(t.querySelector('thead')).display,
          label: getComputedStyle(cell, '::before').content, value: cell.textContent,
          cut: [...document.querySelectorAll('table')].filter(t => t.scrollWidth > t.clientWidth)
                 .map(t => t.querySelector('caption').textContent)};
})()"""


def test_every_table_is_read_whole_at_800_px_the_data_quality_one_as_blocks(report, tmp_path, chromium):
    # it scrolled in its own box with five of its twelve columns out of sight (a screenshot showed it cut
    # after "gaps"): in a narrow window each run is one block of "column: value" pairs
    seen = evaluate(chromium, report, tmp_path / "profile", 800, QUALITY_JS)
    assert seen["table"][0] <= seen["table"][1] and seen["page"] <= 800, seen
    assert seen["head"] == "none" and seen["label"] == '"triggers [count]: "', seen
    # no other table is cut either: the candidate effects scrolled with their last columns out of sight
    # (grounded_spring+joint_stiffness at link2@0.75+elbow were one word each; a line now breaks after +)
    assert seen["cut"] == [], seen


def test_report_cli_pdf_prints_beside_the_html_and_a_bad_geometry_is_one_line(inputs, tmp_path, capsys):
    out = tmp_path / "printed.html"
    assert main(["report", "--measured", str(inputs["measured"]), "--pred", str(inputs["pred"]),
                 "--out", str(out), "--pdf", "--quiet"]) == 0
    lines = capsys.readouterr().out.split()
    assert lines == [str(out), str(out.with_suffix(".pdf"))]
    assert out.with_suffix(".pdf").read_bytes().startswith(b"%PDF-")
    bad = tmp_path / "bad.uff"
    bad.write_text("not a universal file\n")
    assert main(["report", "--measured", str(inputs["measured"]), "--geometry", str(bad),
                 "--out", str(tmp_path / "g.html")]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "bad.uff" in err and "Traceback" not in err


REFERENCE = Path(__file__).parent / "data" / "outputs_reference.json"


@pytest.mark.parametrize("part", ["tour", "demo"])
def test_the_verdict_table_spells_out_what_remains_the_rivals_and_the_advice(tmp_path, part):
    """The diagnosis page of a recorded verdict (README tour and demo: no pose advised, each for its own
    reason) shows the largest held-out errors, the candidates as good within noise and the next
    measurement (or why none) as rows of their own, and the scatter as the quadrature sum it is."""
    recorded = json.loads(REFERENCE.read_text())[part]["diagnosis.json"]
    (tmp_path / "recorded.json").write_text(json.dumps(recorded))
    result = api.read_diagnosis(tmp_path / "recorded.json")
    _, page = api.write_diagnosis(result, tmp_path / "out")
    html = page.read_text()
    v = result.verdict
    row = re.search(r"<th>next measurement</th><td>(.*?)</td>", html).group(1)
    if v.next_measurements:
        assert row.startswith(f"{v.next_measurements[0].pose} (model mode {v.next_measurements[0].mode}, ")
    else:      # demo: every alternative only adds a component; tour: no pose has a 5 % chance to decide
        assert row.startswith("no pose is advised: " if part == "demo" else
                              "none: no untested pose is likely to decide")
    assert f"<th>fit as well within noise</th><td>{v.alternatives[0].effect} at " in html
    assert "<th>largest held-out errors</th><td>mode " in html
    assert "√(m² + f²); measurement scatter m = " in html
    assert ("all 10 configurations" in html) == (part == "demo")
    # both are 'largely explained' (what remains is 4 and 7 times the scatter, not noise): not green
    assert v.grade == "largely explained" and \
        '<th>how much of the gap is explained</th><td class="partial">largely explained: ' in html
    assert not re.search(r"\b(nan|None)\b|\{'", re.sub(r"<[^>]+>", " ", html))


def test_the_scatter_line_adds_in_quadrature_or_says_the_least_the_ranking_uses(tmp_path):
    """0.377 % and 0.668 % make 0.767 % (in quadrature, not a sum); when that is below the least scatter
    the ranking uses, the line says so instead of an equation that does not hold."""
    import dataclasses
    import math

    from flexmodal.compare.verdict_text import scatter_line

    (tmp_path / "d.json").write_text(json.dumps(json.loads(REFERENCE.read_text())["demo"]["diagnosis.json"]))
    result = api.read_diagnosis(tmp_path / "d.json")
    src = result.scatter_source
    assert math.isclose(result.scatter, math.hypot(src.measurement, src.model_form_floor), rel_tol=1e-9)
    assert scatter_line(result).startswith(f"scatter: {100 * result.scatter:.3g} % = sqrt(m^2 + f^2); ")
    floored = dataclasses.replace(result, scatter=0.01)
    assert scatter_line(floored).startswith("scatter: 1 %, the least the ranking uses (sqrt(m^2 + f^2) = "
                                            f"{100 * result.scatter:.3g} % is below it)")
    from flexmodal.compare.diagnosis import MIN_SCATTER  # the key table states the floor it has
    formats = (Path(api.__file__).parent / "docs" / "formats.md").read_text(encoding="utf-8")
    assert f"max(√(measurement² + floor²), {MIN_SCATTER:g})" in formats


def test_a_file_in_the_reports_folder_is_named_relative_to_it_even_inside_the_package(tmp_path):
    """The demo run inside a clone writes flexmodal-demo/ inside the package: its report named its own
    runs.h5 'flexmodal:flexmodal-demo/runs.h5' as if shipped with flexmodal."""
    from flexmodal.reports.html import relative_name

    package = Path(api.__file__).resolve().parent
    rig = package / "fixtures" / "rigs" / "demo_arm.toml"
    assert relative_name(rig, package / "fixtures") == "rigs/demo_arm.toml"
    assert relative_name(rig, tmp_path) == "flexmodal:fixtures/rigs/demo_arm.toml"


def test_a_users_file_inside_a_clone_is_not_named_as_shipped_with_flexmodal():
    """In a clone, diag/diagnosis.html named its inputs 'flexmodal:examples/rigs/demo_arm.toml,
    flexmodal:modes.csv': the user's own modes.csv read as a file of flexmodal's."""
    from flexmodal.reports.html import relative_name

    package = Path(api.__file__).resolve().parent
    assert relative_name(package / "examples" / "rigs" / "demo_arm.toml", package / "diag") == \
        "../examples/rigs/demo_arm.toml"
    assert relative_name(package / "README.md", package / "diag") == "../README.md"


def test_report_draws_shapes_at_the_configurations_asked_for(inputs, capsys):
    # default: first and last configuration; --shapes-at (repeatable) picks others, in the order given
    out = inputs["dir"] / "shapes-at.html"
    base = ["report", "--measured", str(inputs["measured"]), "--rig", str(inputs["rig"]), "--quiet"]
    assert main([*base, "--shapes-at", "theta60", "--out", str(out)]) == 0
    captions = re.findall(r"(theta\d+) \([^)]*\): each measured mode animated on the arm", out.read_text())
    assert captions == ["theta60"]
    capsys.readouterr()
    assert main([*base, "--shapes-at", "theta60", "--shapes-at", "theta45", "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "Traceback" not in err, err
    assert "--shapes-at 'theta45': no such configuration in modes.csv (it has 3 configurations: " in err
    assert main(["report", "--measured", str(inputs["measured"]), "--shapes-at", "theta0",
                 "--out", str(out), "--quiet"]) == 2
    assert "give --rig too" in capsys.readouterr().err
    # a table without shapes at two of the rig's sensors draws none: said, not silently ignored
    no_shapes = inputs["dir"] / "no-shapes.csv"
    ModalTable.read_csv(inputs["measured"]).frame.filter(regex="^(?!shape\\.)").to_csv(no_shapes, index=False)
    assert main([*base[:2], str(no_shapes), *base[3:], "--shapes-at", "theta60", "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "Traceback" not in err, err
    assert ("report --shapes-at: no-shapes.csv has mode shapes at none of the rig's sensors (" in err
            and "two or more are needed to draw them" in err), err


def test_report_tells_a_figure_section_before_drawing_it(tmp_path):
    """The step line comes first, so a terminal shows what the report is busy with (it came after)."""
    from flexmodal.reports.sections import Section, register_section, unregister_section

    told: list[str] = []
    register_section("probe", Section("Probe figures", lambda _inputs: told.append("drawing") or []))
    try:
        api.report(tmp_path / "r.html", progress=told.append,
                   measured=Path(__file__).parents[1] / "examples" / "measured" / "seed003_table3_f1f2.csv")
    finally:
        unregister_section("probe")
    k = told.index("plotting probe figures")
    assert told[k + 1:k + 3] == ["drawing", "no probe figures: nothing in these inputs to draw it from"], told



def test_the_fallback_scatter_reads_as_words_and_is_stored_as_before(tmp_path):
    """The stored source ``--scatter (fallback)`` (docs/formats.md) was printed as is, ``(--scatter
    (fallback): the data carry ...``; the line now names it ``the --scatter fallback``, and the file
    keeps the stored value (read back from a diagnosis.json written before the change)."""
    from flexmodal.compare.gap import FALLBACK_SOURCE
    from flexmodal.compare.verdict_text import scatter_line

    stored = Path(__file__).parent / "data" / "diagnosis" / "seed003_holdout.json"
    result = api.read_diagnosis(stored)
    assert result.scatter_source.source == FALLBACK_SOURCE == "--scatter (fallback)"
    line = scatter_line(result)
    assert "(the --scatter fallback: the data carry no repeats and no freq_std_hz column)" in line, line
    assert "(--scatter (fallback)" not in line
    js, page = api.write_diagnosis(result, tmp_path)
    assert json.loads(js.read_text())["scatter_source"]["source"] == FALLBACK_SOURCE
    assert "(the --scatter fallback: " in page.read_text(encoding="utf-8")      # the page says it alike
