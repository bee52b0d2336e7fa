"""A toy of each kind of extension, each the whole of it in ONE file of tests/toys/, registered by
importing that file and shown to work end to end through the public paths (docs/architecture.md, "Where
a change lands"); every toy is unregistered afterwards."""

from __future__ import annotations

import importlib
import math
import re
import sys

import h5py
import numpy as np
import pytest
from conftest import REPO

from flexmodal.app import main

sys.path.insert(0, str(REPO / "tests"))


@pytest.fixture
def toy(request):
    """Import ``toys.<name>`` (which registers it) and unregister it afterwards."""
    from flexmodal.cli.commands import COMMANDS
    from flexmodal.daq.protocols import PROTOCOLS
    from flexmodal.modal.registry import ESTIMATORS, METHODS
    from flexmodal.models.effects import REGISTRY as EFFECTS
    from flexmodal.models.registry import MODELS
    from flexmodal.reports.sections import SECTIONS

    kind = request.param
    module = importlib.import_module(f"toys.{kind}")
    registry = {"toy_estimator": ESTIMATORS, "toy_model": MODELS, "toy_protocol": PROTOCOLS,
                "toy_effect": EFFECTS, "toy_section": SECTIONS, "toy_command": COMMANDS,
                "toy_method": METHODS}[kind]
    assert module.NAME in registry
    yield module
    registry.unregister(module.NAME)
    sys.modules.pop(f"toys.{kind}")


def _random_run(path, fs=256.0, n=4096):
    from flexmodal.daq.store import Channel, RunWriter
    from flexmodal.fixtures.modal_sim import modal_response

    phi = np.array([[1.0, 0.7], [0.4, -0.8]])
    f = np.random.default_rng(1).standard_normal((n, 1))
    x = modal_response(f, fs, np.array([12.0, 31.0]), np.array([0.02, 0.01]), phi, phi[[0]])
    channels = (Channel("hammer", "force", "N"), Channel("a1", "acceleration", "m/s^2"),
                Channel("a2", "acceleration", "m/s^2"))
    with RunWriter(path, "r1", sample_rate_hz=fs, channels=channels, excitation="random", pose={}) as w:
        w.append(np.column_stack([f, x + 0.05 * np.random.default_rng(2).standard_normal(x.shape)]))
    return path


@pytest.mark.parametrize("toy", ["toy_estimator"], indirect=True)
def test_toy_estimator_from_frf_command_to_stored_frfs(toy, tmp_path, capsys):
    import flexmodal as fm

    path = _random_run(tmp_path / "run.h5")
    argv = ["--quiet", "frf", str(path), "--estimator", toy.NAME, "--nfft", "256", "--workers", "0"]
    assert main(argv) == 0
    h1, h2 = (fm.compute_frf(path, estimator=e, nfft=256) for e in ("H1", "H2"))
    with h5py.File(path, "r") as f:
        assert f["runs/r1/frf"].attrs["estimator"] == toy.NAME
        band = h1.freq_hz > 0
        np.testing.assert_allclose(f["runs/r1/frf/H"][()][..., band], (0.5 * (h1.H + h2.H))[..., band],
                                   rtol=1e-5)


@pytest.mark.parametrize("toy", ["toy_model"], indirect=True)
def test_toy_model_from_predict_command_to_the_table(toy, tmp_path, capsys):
    import flexmodal as fm

    poses = tmp_path / "poses.csv"
    poses.write_text("config,pose.theta_deg\nflat,0\nbent,90\n")
    out = tmp_path / "pred.csv"
    rig = str(REPO / "examples" / "rigs" / "seed003_two_link.toml")
    assert main(["--quiet", "predict", rig, "--model", toy.NAME, "--poses", str(poses), "--out", str(out),
                 "--modes", "1"]) == 0
    table = fm.read_table(out)
    for config, theta in (("flat", 0.0), ("bent", 90.0)):   # the CSV holds 9 significant digits
        assert math.isclose(table.freq_hz(config)[0], toy.natural_freq_hz(theta), rel_tol=1e-8)
    assert main(["predict", rig, "--model", toy.NAME, "--poses", str(poses), "--out", str(out),
                 "--modes", "2"]) == 2
    assert "has one mode" in capsys.readouterr().err


@pytest.mark.parametrize("toy", ["toy_protocol"], indirect=True)
def test_toy_protocol_from_a_session_to_the_stored_run(toy, tmp_path):
    import flexmodal as fm

    session = tmp_path / "toy.toml"
    session.write_text('sample_rate_hz = 1000.0\nexcitation = "random"\n'
                       '[[device]]\nname = "t"\nprotocol = "toy"\ngain = 2.0\n'
                       '[[channel]]\nname = "up"\nkind = "voltage"\nunit = "V"\ndevice = "t"\n'
                       '[[channel]]\nname = "down"\nkind = "voltage"\nunit = "V"\ndevice = "t"\n')
    summary = fm.acquire(session, tmp_path / "run.h5", duration_s=1.0)
    run = fm.read_run(tmp_path / "run.h5", summary.run_id)
    i = np.arange(1000.0)
    np.testing.assert_array_equal(run.samples, 2.0 * np.column_stack([i, -i]))


@pytest.mark.parametrize("toy", ["toy_effect"], indirect=True)
def test_toy_effect_is_a_candidate_and_changes_the_rig(toy):
    import flexmodal as fm
    from flexmodal.compare.candidates import parse_effects
    from flexmodal.models import effects as fx
    from flexmodal.models.frame import frame_modes

    rig = fm.load_rig(REPO / "examples" / "rigs" / "seed003_two_link.toml")
    assert toy.NAME in parse_effects("all") and fx.effect_locations(rig, toy.NAME) == ["tip"]
    stiff = fx.apply_effect(rig, toy.NAME, "tip", {"k_N_per_m": 3e5})
    pose = {"theta_deg": 90.0}
    assert frame_modes(stiff, pose, 4).freq_hz[1] > 1.05 * frame_modes(rig, pose, 4).freq_hz[1]


@pytest.mark.parametrize("toy", ["toy_section"], indirect=True)
def test_toy_report_section_in_the_report_and_its_contents(toy, tmp_path):
    import flexmodal as fm

    out = fm.report(tmp_path / "report.html", measured=REPO / "examples" / "measured" /
                    "seed003_table3_f1f2.csv")
    html = out.read_text()
    assert f'<h2 id="section-{toy.NAME}">{toy.TITLE}</h2>' in html
    assert f'href="#section-{toy.NAME}"' in html and "one bar per row of the modal table" in html


BUILT_IN_SECTIONS = ("comparison", "diagnosis", "modes", "animations", "identified", "runs", "gap")


def test_the_built_in_report_sections_are_entries_of_the_same_registry(tmp_path):
    """The report's own sections are registry entries like the toy's: in the page's order, and one left
    out of the registry is left out of the page (figures renumbered)."""
    import flexmodal as fm
    from flexmodal.reports.sections import SECTIONS, register_section, registered_sections, unregister_section

    assert registered_sections()[:7] == BUILT_IN_SECTIONS
    measured = REPO / "examples" / "measured" / "seed003_table3_f1f2.csv"
    rig = REPO / "examples" / "rigs" / "seed003_two_link.toml"
    diagnosis = fm.diagnose(rig, measured, effects="joint_stiffness", holdout="theta30,theta90,theta150")
    html = fm.report(tmp_path / "all.html", measured=measured, diagnosis=diagnosis).read_text()
    assert html.index('<h2 id="diagnosis">') < html.index('<h2 id="modes">') < html.index('<h2 id="gap">')
    assert 'href="#modes"' in html and "Figure 2." in html
    before = {name: SECTIONS[name] for name in registered_sections()}
    unregister_section("modes")
    try:
        html = fm.report(tmp_path / "less.html", measured=measured, diagnosis=diagnosis).read_text()
    finally:   # the registry as it was, in its order
        for name in registered_sections():
            unregister_section(name)
        for name, section in before.items():
            register_section(name, section)
    assert 'id="modes"' not in html and 'href="#modes"' not in html
    gap = html[html.index('<h2 id="gap">'):]   # its figures (the bars, the gap against pose) come first
    assert re.findall(r"Figure (\d+)\.", html) == re.findall(r"Figure (\d+)\.", gap) == ["1", "2"]
    assert registered_sections()[:7] == BUILT_IN_SECTIONS


@pytest.mark.parametrize("toy", ["toy_command"], indirect=True)
def test_toy_command_in_help_and_run(toy, capsys):
    with pytest.raises(SystemExit):
        main(["--help"])
    assert "count the modes of each configuration" in capsys.readouterr().out
    assert main([toy.NAME, str(REPO / "examples" / "measured" / "seed003_table3_f1f2.csv")]) == 0
    lines = capsys.readouterr().out.split("\n")
    assert "theta0 2" in lines and "theta150 2" in lines


@pytest.mark.parametrize("toy", ["toy_method"], indirect=True)
def test_toy_identification_method_from_identify_command_to_the_modal_table(toy, tmp_path, capsys):
    import flexmodal as fm

    path = _random_run(tmp_path / "run.h5")
    out = tmp_path / "modes.csv"
    assert main(["--quiet", "identify", str(path), "--method", toy.NAME, "--out", str(out)]) == 0
    frf = fm.compute_frf(path)
    expected = frf.freq_hz[np.argmax(np.abs(frf.H).sum(axis=(0, 1)))]
    table = fm.read_table(out)
    line_hz = frf.freq_hz[1] - frf.freq_hz[0]   # identify refines the pole within its line
    assert len(table.freq_hz("r1")) == 1 and abs(table.freq_hz("r1")[0] - expected) < line_hz
    with pytest.raises(SystemExit):
        main(["identify", "--help"])
    assert "the line of the largest summed FRF magnitude" in " ".join(capsys.readouterr().out.split())
