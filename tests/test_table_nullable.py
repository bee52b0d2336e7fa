"""Modal tables built from pandas frames whose number columns have pandas' own dtypes.

A boolean is no number: ``True`` in any numeric field (mode, freq_hz, damping_ratio, the uncertainties,
a pose variable, a shape) is refused naming the column, whether the column is numpy ``bool``, pandas'
nullable ``boolean`` (which pandas counts as a numeric dtype) or ``object`` holding Python booleans.
A nullable ``Float64`` or ``Int64`` column holding ``NA`` reads as the same column of numpy floats with
NaN would (the independent answer: the frame converted by hand): the same table, or the same one-line
error.  Through the command line, the frame written to CSV compares as the plain float table does.
"""

from __future__ import annotations

import csv
import io

import numpy as np
import pandas as pd
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from flexmodal.app import main
from flexmodal.contract.errors import ContractError
from flexmodal.contract.table import ModalTable

NUMERIC = ("mode", "freq_hz", "damping_ratio", "freq_std_hz", "damping_std", "pose.theta_deg", "shape.s1")


def _frame() -> pd.DataFrame:
    """Two modes of one configuration, every numeric field given."""
    return pd.DataFrame({"config": ["a", "a"], "mode": [1, 2], "freq_hz": [10.0, 20.0],
                         "damping_ratio": [0.01, 0.02], "freq_std_hz": [0.1, 0.2],
                         "damping_std": [0.001, 0.002],
                         "pose.theta_deg": [30.0, 30.0], "shape.s1": [0.5, 1.0], "shape.s2": [1.0, -2.0]})


BOOLEANS = {
    "bool": lambda: np.array([True, False]),
    "boolean": lambda: pd.array([True, False], dtype="boolean"),
    "boolean_na": lambda: pd.array([True, None], dtype="boolean"),
    "object": lambda: pd.array([True, 0.5], dtype=object),
}


@pytest.mark.parametrize("kind", list(BOOLEANS))
@pytest.mark.parametrize("col", NUMERIC)
def test_a_boolean_in_any_numeric_field_is_refused_naming_the_column(col, kind) -> None:
    df = _frame()
    df[col] = BOOLEANS[kind]()
    with pytest.raises(ContractError, match=f"column '{col}' (is not a|holds a value that is not a)"):
        ModalTable.from_frame(df, "x")


@pytest.mark.parametrize("col", NUMERIC)
def test_a_boolean_column_of_a_csv_file_is_refused_by_the_cli_in_one_line(tmp_path, capsys, col) -> None:
    df = _frame()
    df[col] = [True, True]
    path = tmp_path / "measured.csv"
    df.to_csv(path, index=False)   # cells 'True': pandas reads the column back as bool
    code = main(["--quiet", "compare", str(path), str(path), "--format", "csv"])
    out, err = capsys.readouterr()
    assert (code, out) == (2, "")
    assert err.count("\n") == 1 and "Traceback" not in err
    assert str(path) in err and f"'{col}'" in err


def _outcome(df: pd.DataFrame) -> pd.DataFrame | str:
    try:
        return ModalTable.from_frame(df, "x").frame
    except ContractError as e:
        return str(e)


def _as_numpy(df: pd.DataFrame, cols: list[str]) -> pd.DataFrame:
    """The frame with its nullable ``cols`` turned by hand into numpy floats, NA -> NaN."""
    return df.assign(**{c: np.array([np.nan if v is pd.NA else float(v) for v in df[c]]) for c in cols})


@settings(max_examples=60)
@given(cols=st.lists(st.sampled_from(NUMERIC + ("shape.s2",)), min_size=1, max_size=3, unique=True),
       dtype=st.sampled_from(["Float64", "Int64"]), missing=st.lists(st.booleans(), min_size=2, max_size=2),
       scale=st.sampled_from([1, 3, 10**6]))
def test_nullable_number_columns_read_as_numpy_floats_with_nan(cols, dtype, missing, scale) -> None:
    df = _frame()
    for col in cols:
        values = (df[col].to_numpy() * scale).round() if dtype == "Int64" else df[col].to_numpy() * scale
        df[col] = pd.array([None if m else v for v, m in zip(values, missing, strict=True)], dtype=dtype)
    got, want = _outcome(df), _outcome(_as_numpy(df, cols))
    if isinstance(want, str):
        assert got == want
    else:
        pd.testing.assert_frame_equal(got, want, check_dtype=False)


@pytest.mark.parametrize("dtype", ["Float64", "Int64"])
def test_nullable_shapes_with_na_compare_through_the_cli_as_plain_floats(tmp_path, capsys, dtype) -> None:
    phi = np.array([[1, 2], [3, -1], [2, 5]])   # [sensor, mode], whole numbers for Int64
    rows = {"config": ["a", "a"], "mode": [1, 2], "pose.theta_deg": [0.0, 0.0]}
    shapes = {f"shape.s{k + 1}": phi[k] for k in range(3)}
    predicted = pd.DataFrame({**rows, "freq_hz": [10.0, 20.0], **shapes})
    measured = pd.DataFrame({**rows, "freq_hz": [10.3, 20.6],
                             **{c: pd.array(v, dtype=dtype) for c, v in shapes.items()}})
    measured.loc[1, "shape.s1"] = pd.NA   # mode 2 has no value at s1
    table = ModalTable.from_frame(measured, "m")
    np.testing.assert_array_equal(table.shapes("a"), [[1, np.nan], [3, -1], [2, 5]])
    m_path, p_path = tmp_path / "measured.csv", tmp_path / "fe.csv"
    table.to_csv(m_path)
    predicted.to_csv(p_path, index=False)
    code = main(["--quiet", "compare", str(m_path), str(p_path), "--format", "csv"])
    out, err = capsys.readouterr()
    assert (code, err) == (0, "")
    got = list(csv.DictReader(io.StringIO(out)))
    assert [r["mode"] for r in got] == ["1", "2"]
    np.testing.assert_allclose([float(r["fe_err_pct"]) for r in got], 100 * (1 / 1.03 - 1), rtol=1e-12)
    np.testing.assert_allclose([float(r["fe_mac"]) for r in got], 1.0, rtol=1e-12)
