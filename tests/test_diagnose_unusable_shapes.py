"""`diagnose` on measured mode shapes no MAC can use, the class `compare` handles (test_shape_values.py):
tiny shapes are refused when the table is read (exit 2, one line); shapes zero, empty or NaN at the rig's
sensors in some or all configurations pair those configurations' modes by frequency order, and one warning
per reason names the file, its shape columns and the configurations (stderr; ``Diagnosis.warnings``).

Known answers: a zero shape carries no more than an empty one, and a table whose every shape is zero or
empty carries none -- its diagnosis is that of the table without shape columns; the nominal model's MAC
per mode (``where.mac_per_mode``) is the mean over the other configurations of contract.mac's MAC of the
measured shapes with the FE model's.  Before: zero shapes were read as MAC 0 with no word (one zero
configuration of six: the fitted model's mean MAC 0.83 and ``where.mac_per_mode`` null for every mode;
all six: mean MAC 0.0), empty ones passed in silence.
"""

from __future__ import annotations

import html
import json

import numpy as np
import pandas as pd
import pytest
from conftest import RIGS, one_line

from flexmodal.api import diagnose, read_diagnosis, write_diagnosis
from flexmodal.app import main
from flexmodal.contract.mac import mac_pairs
from flexmodal.models.frame import frame_modes
from flexmodal.models.rig import load_rig

RIG = RIGS / "seed003_two_link.toml"
POSES_DEG = (0.0, 30.0, 60.0, 90.0, 120.0, 150.0)
N_MODES = 3
EFFECTS = "joint_stiffness"   # one candidate: a diagnosis in 0.2 s
ZERO = "every measured mode shape is zero at the common sensors (MAC undefined)"
EMPTY = "fewer than two common sensors hold a shape value (not empty, not NaN) for every mode"
INCOMPLETE = "a measured mode shape is empty or NaN at one or more sensors"
ZERO_MODE = "a measured mode shape is zero at every sensor that gives it (MAC undefined)"
APART = "both tables give mode shapes, but at fewer than two sensors of the same name"


@pytest.fixture(scope="module")
def measured() -> tuple[pd.DataFrame, np.ndarray]:
    """The nominal arm's FE modes at six poses, 0.2 % frequency and 1 % shape noise (sensors a1-a3), and
    the FE model's own shapes [config, sensor, mode]."""
    rig, rng = load_rig(RIG), np.random.default_rng(6)
    rows, model = [], []
    for i, theta in enumerate(POSES_DEG):
        m = frame_modes(rig, {"theta_deg": theta}, N_MODES)
        freq_hz = m.freq_hz * (1 + 0.002 * rng.standard_normal(N_MODES))
        phi = m.sensor_shapes + 0.01 * np.abs(m.sensor_shapes).max(axis=0) * rng.standard_normal((3, N_MODES))
        model.append(m.sensor_shapes)
        rows += [{"config": f"c{i}", "mode": k + 1, "freq_hz": freq_hz[k], "pose.theta_deg": theta,
                  **{f"shape.{s}": phi[j, k] for j, s in enumerate(m.sensor_names)}} for k in range(N_MODES)]
    return pd.DataFrame(rows), np.array(model)


def _with(df: pd.DataFrame, configs, value: float, sensors=("a1", "a2", "a3")) -> pd.DataFrame:
    out = df.copy()
    out.loc[out.config.isin(configs), [f"shape.{s}" for s in sensors]] = value
    return out


def _diagnose_cli(tmp_path, df: pd.DataFrame, capsys, name: str = "modes.csv") -> tuple[dict, list[str]]:
    """`flexmodal diagnose` on ``df`` written as a CSV file: diagnosis.json and the stderr lines."""
    path = tmp_path / name
    df.to_csv(path, index=False)   # NaN: an empty cell
    out = tmp_path / f"out_{path.stem}"
    assert main(["--quiet", "diagnose", "--rig", str(RIG), "--measured", str(path), "--out", str(out),
                 "--effects", EFFECTS]) == 0
    return json.loads((out / "diagnosis.json").read_text()), capsys.readouterr().err.splitlines()


def _reference(tmp_path, df: pd.DataFrame) -> dict:
    path = tmp_path / "reference.csv"
    df.to_csv(path, index=False)
    return diagnose(RIG, path, effects=EFFECTS).to_dict()


@pytest.mark.parametrize("value, why", [(0.0, ZERO), (np.nan, EMPTY)], ids=["zero", "empty"])
def test_no_usable_shape_in_any_configuration_is_a_table_without_shapes(tmp_path, capsys, measured, value,
                                                                        why) -> None:
    df, _ = measured
    doc, err = _diagnose_cli(tmp_path, _with(df, df.config, value), capsys)
    assert err == [f"flexmodal: warning: {RIG}: {why} in 6 configurations (c0, c1, c2 and 3 more) of "
                   f"{tmp_path / 'modes.csv'} (shape.a1, shape.a2, shape.a3): paired by frequency order, "
                   "not by MAC"]
    assert doc.pop("warnings") == [err[0].removeprefix("flexmodal: warning: ")]
    reference = _reference(tmp_path, df.drop(columns=["shape.a1", "shape.a2", "shape.a3"]))
    assert doc == json.loads(json.dumps(reference))
    assert "mac_mean" not in doc["ranking"][0] and "mac_per_mode" not in doc["where"]


def test_a_zero_configuration_is_an_empty_one(tmp_path, capsys, measured) -> None:
    """Configuration c2's shapes zero: the diagnosis is the one with c2's cells empty, and the nominal
    model's MAC per mode is the mean over the other five configurations (before: MAC 0 in the mean)."""
    df, model = measured
    doc, err = _diagnose_cli(tmp_path, _with(df, ["c2"], 0.0), capsys)
    assert len(err) == 1 and f"{ZERO} in 1 configuration (c2) of " in err[0]
    empty, err_empty = _diagnose_cli(tmp_path, _with(df, ["c2"], np.nan), capsys, "empty.csv")
    assert len(err_empty) == 1 and f"{EMPTY} in 1 configuration (c2) of " in err_empty[0]
    doc.pop("warnings"), empty.pop("warnings")
    assert doc == empty
    phi = df[["shape.a1", "shape.a2", "shape.a3"]].to_numpy().reshape(len(POSES_DEG), N_MODES, 3)
    macs = np.array([mac_pairs(phi[c].T, model[c]) for c in (0, 1, 3, 4, 5)])   # independent of compare/
    assert [doc["where"]["mac_per_mode"][str(k + 1)] for k in range(N_MODES)] == pytest.approx(
        macs.mean(axis=0), rel=1e-7)   # the reduced model: FE to 1e-8
    assert doc["ranking"][0]["mac_mean"] == pytest.approx(macs.mean(), abs=2e-4)   # 0.83 before


def test_a_zero_mode_is_an_empty_one(tmp_path, capsys, measured) -> None:
    """Mode 2 of c2 zero at every sensor, its other modes as measured: the diagnosis is the one with that
    mode's cells empty, one warning names c2, and the MAC of mode 2 is the mean over the other five
    configurations (before: no warning, MAC 0 in the mean, mean MAC 0.944)."""
    df, model = measured
    cols = ["shape.a1", "shape.a2", "shape.a3"]
    zero, empty = df.copy(), df.copy()
    zero.loc[(df.config == "c2") & (df["mode"] == 2), cols] = 0.0
    empty.loc[(df.config == "c2") & (df["mode"] == 2), cols] = np.nan
    doc, err = _diagnose_cli(tmp_path, zero, capsys)
    assert err == [f"flexmodal: warning: {RIG}: {ZERO_MODE} in 1 configuration (c2) of "
                   f"{tmp_path / 'modes.csv'} (shape.a1, shape.a2, shape.a3): paired by frequency order, "
                   "not by MAC"]
    reference, err_empty = _diagnose_cli(tmp_path, empty, capsys, "empty.csv")
    assert len(err_empty) == 1 and f"{EMPTY} in 1 configuration (c2) of " in err_empty[0]
    doc.pop("warnings"), reference.pop("warnings")
    assert doc == reference
    phi = df[cols].to_numpy().reshape(len(POSES_DEG), N_MODES, 3)
    macs = np.array([mac_pairs(phi[c].T, model[c]) for c in (0, 1, 3, 4, 5)])   # independent of compare/
    assert doc["where"]["mac_per_mode"]["2"] == pytest.approx(macs[:, 1].mean(), rel=1e-7)


@pytest.mark.parametrize("columns, why", [
    ({"shape.a2": None, "shape.a3": None}, EMPTY),                          # one rig sensor: every MAC is 1
    ({"shape.a1": "shape.x1", "shape.a2": "shape.x2", "shape.a3": "shape.x3"}, APART),   # renamed
], ids=["one_sensor", "renamed"])
def test_shapes_at_fewer_than_two_rig_sensors_are_a_table_without_shapes(tmp_path, capsys, measured, columns,
                                                                        why) -> None:
    """Shape columns at one rig sensor, or at none (names the rig does not know): one warning naming the
    columns, and the diagnosis of the table without shape columns (before: no warning; one sensor: mean
    MAC 1.0 from single-value "shapes")."""
    df, _ = measured
    table = df.drop(columns=[c for c, new in columns.items() if new is None]).rename(
        columns={c: new for c, new in columns.items() if new})
    doc, err = _diagnose_cli(tmp_path, table, capsys)
    named = ", ".join(c for c in table.columns if c.startswith("shape."))
    assert err == [f"flexmodal: warning: {RIG}: {why} in 6 configurations (c0, c1, c2 and 3 more) of "
                   f"{tmp_path / 'modes.csv'} ({named}): paired by frequency order, not by MAC"]
    assert doc.pop("warnings") == [err[0].removeprefix("flexmodal: warning: ")]
    reference = _reference(tmp_path, df.drop(columns=["shape.a1", "shape.a2", "shape.a3"]))
    assert doc == json.loads(json.dumps(reference))


def test_one_warning_per_reason_and_none_for_usable_shapes(tmp_path, capsys, measured) -> None:
    """c1 zero, c3 empty at sensor a3 only (complete at a1, a2: the fit still pairs c3 by frequency, and
    says so), c4 and c5 NaN at every sensor: three lines; the table as measured: none."""
    df, _ = measured
    mixed = _with(_with(_with(df, ["c1"], 0.0), ["c3"], np.nan, ["a3"]), ["c4", "c5"], np.nan)
    _, err = _diagnose_cli(tmp_path, mixed, capsys)
    assert [line.partition(f"{RIG}: ")[2].partition(" in ")[0] for line in err] == [ZERO, INCOMPLETE + (
        " (the diagnosis pairs by MAC only shapes given at every sensor)"), EMPTY]
    assert ["(c1)" in err[0], "(c3)" in err[1], "(c4, c5)" in err[2]] == [True] * 3
    doc, err = _diagnose_cli(tmp_path, df, capsys, "usable.csv")
    assert err == [] and "warnings" not in doc and doc["ranking"][0]["mac_mean"] > 0.999


def test_the_api_carries_the_warning_through_diagnosis_json(tmp_path, measured) -> None:
    df, _ = measured
    path = tmp_path / "modes.csv"
    _with(df, ["c0", "c5"], 0.0).to_csv(path, index=False)
    result = diagnose(RIG, path, effects=EFFECTS)
    assert result.warnings == (f"{RIG}: {ZERO} in 2 configurations (c0, c5) of {path} (shape.a1, shape.a2, "
                               "shape.a3): paired by frequency order, not by MAC",)
    from flexmodal.compare.diagnosis import diagnose as library_diagnose
    from flexmodal.contract.table import ModalTable

    assert library_diagnose(load_rig(RIG), ModalTable.read_csv(path), effects=EFFECTS) == result   # not api's
    write_diagnosis(result, tmp_path / "out")
    assert read_diagnosis(tmp_path / "out" / "diagnosis.json").warnings == result.warnings
    page = (tmp_path / "out" / "diagnosis.html").read_text()
    assert f'<th>measured shapes not used</th><td class="warn">{html.escape(result.warnings[0])}</td>' in page


@pytest.mark.parametrize("configs", [["c3"], list(f"c{i}" for i in range(6))], ids=["one", "all"])
def test_tiny_shapes_are_refused_when_read(tmp_path, capsys, measured, configs) -> None:
    """A shape at most 1e-100 at every sensor (its squares underflow): one line, exit 2, as in compare."""
    df, _ = measured
    tiny = df.copy()
    rows = tiny.config.isin(configs)
    tiny.loc[rows, ["shape.a1", "shape.a2", "shape.a3"]] *= 1e-200
    path = tmp_path / "tiny.csv"
    tiny.to_csv(path, index=False)
    code = main(["--quiet", "diagnose", "--rig", str(RIG), "--measured", str(path), "--out",
                 str(tmp_path / "out"), "--effects", EFFECTS])
    first = int(np.flatnonzero(rows.to_numpy())[0]) + 2   # header = row 1
    one_line(capsys, code, str(path), f"row {first}: the mode shape (shape.a1, shape.a2, shape.a3)",
             "below 1e-100")
    assert not (tmp_path / "out").exists()
