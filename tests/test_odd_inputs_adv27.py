"""Odd inputs of the adv27 adversarial pass (27 Nov).  The Python API took numbers the command line
refuses: ``frf_from_arrays(decay_rate_per_s=nan)`` (or -1, or '2') was kept and removed from the
damping that ``identify`` found; ``track(window_s=nan)`` stopped with numpy's "cannot convert float NaN
to integer"; ``track(max_spread_deg=nan)``, ``plot_stabilisation(max_order=nan)``,
``plot_mode_shapes(n_fe_modes=inf)`` and ``identify(pose={'theta_deg': nan})`` ran; True passed as 1
for min_mac, report's band edges and the track options; ``compute_frf(window=5)`` was an
AttributeError.  Each is now checked by the option kind the command line uses for it
(:func:`flexmodal.checked_io.options.given`).  A refused output said "choose another --out" of
--fault-log, --uff and store=True targets too; it now names no option it did not come from.
``diagnose --out DIR`` replaced a diagnosis.json or diagnosis.html of the user's own in DIR (the user
named the folder, not the files); now only files flexmodal wrote are replaced.  A run whose responses
were stored in different units (a2 in g, the others in m/s^2) was identified with its mode shapes
mixing the units (a2 9.81 times too small, exit 0); they are now brought to m/s^2 first (identify
--track and report too).  identify
ignored options its source has no use for (config and pose with a run file, run_id and references
with FRFs in memory); each is now named, and so is an option of another model given to predict
(--model fe --masses-per-link 3 was the fe prediction, exit 0), and an option of identify --track
given without --track (or one of plain identify given with it).  A stored FRF that is zero everywhere
put matplotlib's log-scale warning on stderr under --quiet; such an axis is now linear.  A packed or
HDF5 file given as report --geometry was quoted byte by byte; it is now named.
In-process, no run files: about 3 s."""

from __future__ import annotations

import argparse
import math
import re
import shutil
from pathlib import Path

import h5py
import numpy as np
import pytest
from conftest import REPO
from hypothesis import given
from hypothesis import strategies as st

import flexmodal as fm
from flexmodal.checked_io import options as opt

RIG = REPO / "examples" / "rigs" / "demo_arm.toml"
MEASURED = REPO / "examples" / "measured" / "seed003_table3_f1f2.csv"


def _frf(decay_rate_per_s: object = 0.0) -> fm.FrfResult:
    """One mode at 40 Hz, 2 % damping (closed form), as in the identify docstring."""
    f = np.linspace(0.0, 100.0, 401)
    s, w0 = 2j * np.pi * f, 2 * np.pi * 40.0
    return fm.frf_from_arrays(f, s**2 / (s**2 + 2 * 0.02 * w0 * s + w0**2), outputs=["tip"],
                              decay_rate_per_s=decay_rate_per_s)


CALLS = {   # name of the argument in the message -> the call with the odd value
    "decay_rate_per_s": lambda v: _frf(v),
    "identify: decay_rate_per_s": lambda v: fm.identify(_frf(), decay_rate_per_s=v),
    "pose theta_deg": lambda v: fm.identify(_frf(), pose={"theta_deg": v}),
    "plot_stabilisation: max_order": lambda v: fm.plot_stabilisation(_frf(), max_order=v),
    "plot_mode_shapes: n_fe_modes": lambda v: fm.plot_mode_shapes(RIG, MEASURED, "theta0", n_fe_modes=v),
    "track: window_s": lambda v: fm.track("no-such-run.h5", window_s=v),
    "track: hop_s": lambda v: fm.track("no-such-run.h5", hop_s=v),
    "track: bin_deg": lambda v: fm.track("no-such-run.h5", bin_deg=v),
    "track: max_spread_deg": lambda v: fm.track("no-such-run.h5", max_spread_deg=v),
    "track: orders": lambda v: fm.track("no-such-run.h5", orders=[v]),
    "--min-mac": lambda v: fm.compare_modes(MEASURED, MEASURED, min_mac=v),
    "report: fmin": lambda v: fm.report("never-written.html", measured=MEASURED, fmin=v),
}


@pytest.mark.parametrize("value", [math.nan, -1.0, True, "2"], ids=["nan", "negative", "True", "text"])
@pytest.mark.parametrize("what", list(CALLS))
def test_an_api_number_the_cli_refuses_is_refused_naming_it(what: str, value: object) -> None:
    if value == -1.0 and what in ("pose theta_deg", "--min-mac"):
        value = math.inf   # a pose may be negative; min_mac -1 was refused before
    with pytest.raises(fm.FlexmodalError) as refused:
        CALLS[what](value)
    message = str(refused.value)
    assert what in message and repr(value) in message and "\n" not in message, message


@pytest.mark.parametrize(("config", "named"), [(None, "run"), ("c40", "c40")])
def test_a_bad_pose_names_the_config_its_modes_get(config: str | None, named: str) -> None:
    """identify(frf, pose={'theta_deg': nan}) said "config None": the default name, run, came later."""
    with pytest.raises(fm.ModalError) as refused:
        fm.identify(_frf(), config=config, pose={"theta_deg": math.nan})
    assert str(refused.value) == f"identify: config {named!r}: pose theta_deg = nan is not a finite number"
    assert fm.identify(_frf(), pose={"theta_deg": 40.0}).table.configs == ["run"]


@given(st.floats(allow_nan=True, allow_infinity=True) | st.integers(-10, 10))
def test_frf_from_arrays_takes_exactly_the_decay_rates_the_cli_takes(value: float) -> None:
    """The same numbers pass as on identify --exp-window-decay, and the one stored is the one given."""
    try:
        expected = opt.nonnegative(str(value))
    except argparse.ArgumentTypeError:
        with pytest.raises(fm.ModalError, match="decay_rate_per_s"):
            _frf(value)
    else:
        assert _frf(value).decay_rate_per_s == expected


@given(st.floats(allow_nan=True, allow_infinity=True))
def test_track_takes_exactly_the_windows_the_cli_takes(value: float) -> None:
    """A window --window takes reaches the input (here missing); any other is named first."""
    try:
        opt.seconds(str(value))
    except argparse.ArgumentTypeError:
        match = "track: window_s"
    else:
        match = "input not found"
    with pytest.raises(fm.ModalError, match=match):
        fm.track("no-such-run.h5", window_s=value)


@pytest.mark.parametrize("call", [lambda: fm.compute_frf("no-such-run.h5", window=5),
                                  lambda: fm.compute_frfs(["no-such-run.h5"], window=5),
                                  lambda: fm.diagnose(RIG, MEASURED, scatter="0.01")],
                         ids=["compute_frf", "compute_frfs", "diagnose"])
def test_a_window_or_scatter_of_the_wrong_type_is_a_type_error_naming_it(call) -> None:
    with pytest.raises(TypeError, match=r"(window|scatter) must be .*got ('0.01'|5)$"):
        call()


def test_a_float32_band_edge_is_a_number_for_the_report() -> None:
    """numpy's float32 is a real number: report refused it as 'not a positive number of Hz'; now it
    passes that check and reaches the next one (a band edge with no run to identify)."""
    with pytest.raises(fm.ReportError, match="fmin sets the band of the runs' identification"):
        fm.report("never-written.html", measured=MEASURED, fmin=np.float32(5.0))


# -- an output refused names the option it came from -----------------------------------------------------
@pytest.mark.parametrize("what", ["fault log (--fault-log)", "UFF file (--uff)", "run file (store=True)"])
def test_a_refused_output_is_not_sent_to_an_out_option_it_did_not_come_from(tmp_path: Path, what: str
                                                                             ) -> None:
    """'choose another --out' was said of --fault-log, --uff and store=True targets too."""
    from flexmodal.checked_io.output import hdf5_output, output_file

    store, text = tmp_path / "runs.h5", tmp_path / "notes.txt"
    with h5py.File(store, "w", libver="latest"):
        pass
    text.write_text("my notes\n", encoding="utf-8")
    for check, target in ((output_file, store), (hdf5_output, text)):
        kwargs = {"inputs": ()} if check is output_file else {}
        with pytest.raises(fm.DaqError) as refused:
            check(target, fm.DaqError, what, **kwargs)
        message = str(refused.value)
        assert what in message and "--out" not in message.replace(what, ""), message
    assert text.read_text(encoding="utf-8") == "my notes\n"


# -- diagnose --out DIR: the files it names itself replace only its own ------------------------------------
@pytest.mark.parametrize("name", ["diagnosis.json", "diagnosis.html"])
def test_a_diagnosis_file_of_the_users_own_in_the_folder_is_kept(tmp_path: Path, name: str, capsys) -> None:
    """The user named the folder, not the files: their diagnosis.json or .html there was replaced."""
    from flexmodal.app import main

    result = fm.read_diagnosis(REPO / "tests" / "data" / "diagnosis" / "seed003_holdout.json")
    fm.write_diagnosis(result, tmp_path / "ours")
    fm.write_diagnosis(result, tmp_path / "ours")   # its own files: replaced
    theirs = tmp_path / "theirs"
    theirs.mkdir()
    (theirs / name).write_text("<p>my notes</p>\n", encoding="utf-8")
    with pytest.raises(fm.CompareError, match=f"{name}: exists and is not a {name} flexmodal wrote"):
        fm.write_diagnosis(result, theirs)
    assert main(["diagnose", "--rig", str(RIG), "--measured", str(MEASURED), "--out", str(theirs)]) == 2
    assert f"{name}: exists and is not a {name} flexmodal wrote" in capsys.readouterr().err
    assert sorted(p.name for p in theirs.iterdir()) == [name]
    assert (theirs / name).read_text(encoding="utf-8") == "<p>my notes</p>\n"


OLDER = REPO / "tests" / "data" / "diagnosis" / "older"


@pytest.mark.parametrize("page", ["diagnosis_report_template.html", "diagnosis_render_html.html"])
def test_a_diagnosis_page_an_older_flexmodal_wrote_is_replaced(tmp_path: Path, page: str) -> None:
    """diagnose --out into the folder of an earlier run was refused ("not a diagnosis.html flexmodal
    wrote") when the page predates the versions footer (67daf75).  The pages are what flexmodal wrote
    before it, on demo.json: the report template of 67daf75^ (its figures' PNG data cut out) and
    compare.diagnosis.render_html of 7d23b90^."""
    result = fm.read_diagnosis(REPO / "tests" / "data" / "diagnosis" / "demo.json")
    shutil.copyfile(OLDER / page, tmp_path / "diagnosis.html")
    fm.write_diagnosis(result, tmp_path)
    assert "<p>Versions: flexmodal " in (tmp_path / "diagnosis.html").read_text(encoding="utf-8")


@pytest.mark.parametrize("edit", [("by flexmodal ", "by hand "),
                                  ("Sim-to-real gap diagnosis</title>", "</title>")])
def test_a_page_like_an_older_diagnosis_page_but_not_flexmodals_is_kept(tmp_path: Path, edit) -> None:
    """A page of the user's own that starts as the older pages do (the report template's head without
    "by flexmodal", a render_html-like page with another title) is not replaced."""
    page = "diagnosis_report_template.html" if "flexmodal" in edit[0] else "diagnosis_render_html.html"
    theirs = (OLDER / page).read_text(encoding="utf-8").replace(*edit)
    (tmp_path / "diagnosis.html").write_text(theirs, encoding="utf-8")
    result = fm.read_diagnosis(REPO / "tests" / "data" / "diagnosis" / "demo.json")
    with pytest.raises(fm.CompareError, match="diagnosis.html: exists and is not a diagnosis.html flexmodal"):
        fm.write_diagnosis(result, tmp_path)
    assert (tmp_path / "diagnosis.html").read_text(encoding="utf-8") == theirs


# -- responses stored in different units -------------------------------------------------------------------
def _restated(path: Path, channel: str, unit: str, per_si: float) -> None:
    """Channel ``channel`` of the one run of ``path`` restated in ``unit`` (``per_si`` units per m/s^2)."""
    with h5py.File(path, "a") as f:
        run = f["runs"][next(iter(f["runs"]))]
        table = run["channels"][()]
        j = [n.decode() for n in table["name"]].index(channel)
        table["unit"][j] = unit.encode()
        del run["channels"]
        run.create_dataset("channels", data=table)
        run["samples"][:, j] = run["samples"][:, j] * per_si


@pytest.mark.parametrize("method", ["lscf", "ssi"])
def test_responses_in_g_and_m_s2_give_the_shapes_of_the_same_test_in_si(tmp_path: Path, method: str) -> None:
    """a2 stored in g beside a1, a3-a5 in m/s^2 had its mode-shape entry 9.81 times too small (exit 0):
    the shapes (and so MAC pairing and the diagnosis) mixed units.  The reference is the same test
    stored in SI."""
    from flexmodal.fixtures.examples import impact_run

    si, mixed = impact_run(tmp_path), tmp_path / "mixed.h5"
    shutil.copyfile(si, mixed)
    _restated(mixed, "a2", "g", 1 / 9.80665)
    want = fm.identify(si, method=method, fmax=400.0).table
    got = fm.identify(mixed, method=method, fmax=400.0).table
    assert got.frame["freq_hz"].to_numpy() == pytest.approx(want.frame["freq_hz"].to_numpy(), rel=1e-6)
    for sensor in ("a1", "a2", "a5"):
        shape = f"shape.{sensor}"
        assert got.frame[shape].to_numpy() == pytest.approx(want.frame[shape].to_numpy(), rel=1e-4, abs=1e-6)


def test_responses_in_units_with_no_factor_to_m_s2_are_named(tmp_path: Path) -> None:
    from flexmodal.fixtures.examples import impact_run

    path = impact_run(tmp_path)
    _restated(path, "a3", "ft/s^2", 1.0)
    with pytest.raises(fm.ModalError, match=r"runs.h5:theta30: the response channels are in different "
                                            r"units \(a1 \(m/s\^2: acceleration\), "
                                            r"a2 \(m/s\^2: acceleration\), a3 \(ft/s\^2: no known "):
        fm.identify(path, fmax=400.0)


# -- identify options the source has no use for -------------------------------------------------------------
@pytest.mark.parametrize(("source", "option"), [
    ("file", {"config": "mine"}), ("file", {"pose": {"theta_deg": 45.0}}),
    ("memory", {"run_id": "theta30"}), ("memory", {"references": ["tip"]})])
def test_an_identify_option_the_source_has_no_use_for_is_named(tmp_path: Path, source: str,
                                                                option: dict) -> None:
    """identify('runs.h5', config='mine', pose={'theta_deg': 45}) wrote the run id and the stored pose
    (0 deg), and an FrfResult took run_id and references: all ignored in silence, exit 0."""
    from flexmodal.fixtures.examples import impact_run

    given = impact_run(tmp_path) if source == "file" else _frf()
    (name, value), = option.items()
    with pytest.raises(fm.ModalError, match=rf"identify: {name} = {re.escape(repr(value))} has no use with"):
        fm.identify(given, **option)
    assert fm.identify(_frf(), config="c40", pose={"theta_deg": 40.0}).table.configs == ["c40"]


# -- predict: an option of another model -----------------------------------------------------------------
SEED003 = REPO / "examples" / "rigs" / "seed003_two_link.toml"


@pytest.mark.parametrize(("model", "option", "words"), [
    ("fe", ["--masses-per-link", "3"], "masses_per_link = 3 is an option of model 'lumped-mass'"),
    ("fe", ["--coordinates", "transverse"], "coordinates = 'transverse' is an option of model 'lumped-mass'"),
    ("lumped-mass", ["--elements", "5"], "elements_per_link = 5 is an option of model 'fe'"),
    ("lumped-mass", ["--lumped-mass-matrix"], "lumped_mass = True is an option of model 'fe'")])
def test_an_option_of_another_model_is_named_not_ignored(tmp_path: Path, capsys, model: str,
                                                         option: list[str], words: str) -> None:
    """predict --model fe --masses-per-link 3 (and the like) wrote the fe prediction, exit 0."""
    from flexmodal.app import main

    out = tmp_path / "p.csv"
    argv = ["predict", str(SEED003), "--model", model, "--poses", str(MEASURED), "--out", str(out),
            "--modes", "2"]
    assert main([*argv, *option]) == 2
    assert f"{words}; model '{model}' does not use it" in capsys.readouterr().err and not out.exists()
    assert main(argv) == 0   # the model's own options, or none, still predict
    lumped = fm.predict(SEED003, MEASURED, "lumped-mass", 2, masses_per_link=3, coordinates="transverse")
    assert lumped.configs == fm.read_table(MEASURED).configs


# -- identify: options of the other mode (--track or not) ----------------------------------------------
@pytest.mark.parametrize("option", [["--window", "2"], ["--hop", "1"], ["--bin", "5"], ["--max-spread", "3"],
                                    ["--orders", "2"], ["--pose-from", "theta_deg=enc"]])
def test_a_track_option_without_track_is_named(tmp_path: Path, capsys, option: list[str]) -> None:
    """identify RUN.h5 --window 2 (--track forgotten) identified the whole record, exit 0."""
    from flexmodal.app import main

    assert main(["identify", str(tmp_path / "run.h5"), "--out", str(tmp_path / "m.csv"), *option]) == 2
    assert f"identify: {option[0]} is an option of identify --track" in capsys.readouterr().err


@pytest.mark.parametrize("option", [["--poles", "30"], ["--uff", "m.uff"], ["--need-min", "5"],
                                    ["--mpc-min", "0.9"], ["--method", "lscf"], ["--references", "a1"],
                                    ["--exp-window-decay", "2"], ["--from-diagram"]])
def test_an_identify_option_with_track_is_named(tmp_path: Path, capsys, option: list[str]) -> None:
    """identify --track --uff M.uff wrote no UFF file, and the other options changed nothing, exit 0."""
    from flexmodal.app import main

    argv = ["identify", str(tmp_path / "run.h5"), "--track", "--out", str(tmp_path / "m.csv"), *option]
    assert main(argv) == 2
    assert f"identify --track does not read {option[0]}" in capsys.readouterr().err


@pytest.mark.parametrize(("track", "option", "words"), [
    (False, ["--max-spread", "0"], "identify: --max-spread is an option of identify --track"),
    (False, ["--orders", ""], "identify: --orders is an option of identify --track"),
    (False, ["--pose-from", ""], "identify: --pose-from is an option of identify --track"),
    (False, ["--window", "0"], "argument --window: expected a finite duration in seconds > 0"),
    (False, ["--hop", "0"], "argument --hop: expected a finite duration in seconds > 0"),
    (False, ["--bin", "0"], "argument --bin: expected a finite number > 0"),
    (True, ["--poles", ""], "identify --track does not read --poles"),
    (True, ["--uff", ""], "identify --track does not read --uff"),
    (True, ["--need-min", "0"], "identify --track does not read --need-min"),
    (True, ["--mpc-min", "0"], "identify --track does not read --mpc-min"),
    (True, ["--exp-window-decay", "0"], "identify --track does not read --exp-window-decay"),
    (True, ["--references", ""], "argument --references: expected NAME[,NAME...] with no empty name")])
def test_a_zero_or_empty_value_of_the_other_modes_option_is_named(tmp_path: Path, capsys, track: bool,
                                                                 option: list[str], words: str) -> None:
    """A zero was taken for "not given" (0 == False): identify --max-spread 0 without --track, and
    --track --need-min 0, --mpc-min 0 or --exp-window-decay 0 were ignored in silence.  Every option of
    both lists (cli/modal.py TRACK_ONLY, IDENTIFY_ONLY; --from-diagram, a flag, has no falsy value) with
    a zero or empty value: named, or refused by its own type."""
    from flexmodal.app import main
    from flexmodal.cli.modal import IDENTIFY_ONLY, TRACK_ONLY

    listed = IDENTIFY_ONLY if track else TRACK_ONLY
    assert option[0][2:].replace("-", "_") in listed
    argv = ["identify", str(tmp_path / "run.h5"), *(["--track"] if track else []), "--out",
            str(tmp_path / "m.csv"), *option]
    assert main(argv) == 2
    assert words in capsys.readouterr().err


# -- log axes of data that is zero everywhere --------------------------------------------------------------
def test_an_frf_of_zeros_is_drawn_without_a_warning_on_stderr() -> None:
    """report on a stored FRF that is zero everywhere printed matplotlib's 'Data has no positive values,
    and therefore cannot be log-scaled' and a source line on stderr (under --quiet too); its axis is now
    linear, and an FRF with positive values keeps the log axis and its tick labels."""
    import warnings

    from flexmodal.reports import plots

    f = np.linspace(0.0, 100.0, 11)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        zero = plots.plot_frf(f, np.zeros((2, 1, 11), complex), np.ones((2, 11)))
        plots.figure_png(zero)
    some = plots.plot_frf(f, np.ones((2, 1, 11), complex), np.ones((2, 11)))
    assert zero.axes[0].get_yscale() == "linear" and some.axes[0].get_yscale() == "log"
    assert isinstance(some.axes[0].yaxis.get_major_formatter(), plots.LogTicks)


# -- a packed or HDF5 file where Universal File text is expected ------------------------------------------
@pytest.mark.parametrize(("packing", "words"), [("gzip", "gzip-compressed: unpack it first"),
                                                ("zip", "zip-compressed: unpack it first"),
                                                ("hdf5", "an HDF5 file")])
def test_a_packed_or_hdf5_geometry_file_is_named_not_quoted(tmp_path: Path, packing: str, words: str) -> None:
    """report --geometry geo.uff.gz quoted the gzip bytes as 'line 1: text outside any dataset
    ('\\x1f\\x8b\\x08...')'; identify said what it was, the geometry reader now does too."""
    import gzip
    import zipfile

    from flexmodal.reports.geometry import read_uff_geometry

    text = (REPO / "tests" / "data" / "uff" / "massif_geometry.uff").read_bytes()
    path = tmp_path / "geo.uff"
    if packing == "gzip":
        path.write_bytes(gzip.compress(text))
    elif packing == "zip":
        with zipfile.ZipFile(path, "w") as z:
            z.writestr("geo.uff", text)
    else:
        with h5py.File(path, "w", libver="latest"):
            pass
    with pytest.raises(fm.ReportError) as refused:
        read_uff_geometry(path)
    assert str(refused.value) == f"{path}: not Universal File text ({words})"


def test_track_takes_responses_in_g_and_m_s2_as_the_same_test_in_si(tmp_path: Path) -> None:
    """identify --track mixed the units as identify did (class E): the moving arm's map against the same
    record stored in SI.  SSI in 2 s windows moves by up to 0.21 % when a2 is rounded differently (stored
    in float32 as a2 / 9.80665), its shape entries by up to 1.8 %: the tolerances are 1 % and 5 %, the
    mixed units were off by a factor 9.81 at a2."""
    from flexmodal.fixtures.examples import moving_run

    si, mixed = moving_run(tmp_path), tmp_path / "mixed.h5"
    shutil.copyfile(si, mixed)
    _restated(mixed, "a2", "g", 1 / 9.80665)
    want, got = (fm.track(p, fmax=400.0, window_s=2.0, hop_s=1.0).table.frame for p in (si, mixed))
    assert got["freq_hz"].to_numpy() == pytest.approx(want["freq_hz"].to_numpy(), rel=1e-2)
    assert got["shape.a2"].to_numpy() == pytest.approx(want["shape.a2"].to_numpy(), rel=0.05, abs=0.01)


@pytest.mark.parametrize("record", ["impact", "moving"])
def test_report_takes_responses_in_g_and_m_s2_as_the_same_test_in_si(tmp_path: Path, monkeypatch,
                                                                    record: str) -> None:
    """report identified a run's stored FRFs (and an output-only run's samples) in the units stored: with
    a2 in g beside m/s^2 its shapes were off by 9.81 at a2 (exit 0), as identify's were (class E).  The
    references are the same records stored in SI: the impact test's stored FRFs (lscf, shapes within
    1e-4 as identify's) and the moving arm's record (SSI of the whole record; a2 rounded differently in
    float32, tolerances 1 % and 5 % as track's)."""
    import flexmodal.reports.html as html
    from flexmodal.fixtures.examples import impact_run, moving_run

    drawn = []

    def keep(out, *, runs, **kw):
        drawn.extend(runs)
        return write_report(out, runs=runs, **kw)

    write_report = html.write_report
    monkeypatch.setattr(html, "write_report", keep)
    si = impact_run(tmp_path) if record == "impact" else moving_run(tmp_path, duration_s=4.0)
    mixed = tmp_path / "mixed.h5"
    shutil.copyfile(si, mixed)
    _restated(mixed, "a2", "g", 1 / 9.80665)
    if record == "impact":
        fm.compute_frfs([si, mixed])
    fm.report(tmp_path / "r.html", runs=[si, mixed], fmax=400.0, oma_fmax=400.0)
    want, got = drawn
    if record == "impact":
        assert got.frf_unit == want.frf_unit == "(m/s²)/N"
        assert got.modes.freq_hz == pytest.approx(want.modes.freq_hz, rel=1e-6)
        assert got.modes.shapes == pytest.approx(want.modes.shapes, rel=1e-4, abs=1e-6)
    else:
        assert got.oma.ssi.modes.freq_hz == pytest.approx(want.oma.ssi.modes.freq_hz, rel=1e-2)
        assert np.abs(got.oma.ssi.modes.shapes) == pytest.approx(np.abs(want.oma.ssi.modes.shapes), rel=0.05,
                                                                 abs=0.01)
