"""`flexmodal compare` on the seed tables: reproduces seed 001 Table 3.1 and seed 000 Table 2.

The seed CSVs are wide tables, not ModalTables; ``seed_to_modal_tables`` converts them (one ModalTable
CSV per source, the experiment carrying the damping ratio) and the CLI is run on those files.
"""

from __future__ import annotations

import csv
import io
import json
import re
from html.parser import HTMLParser
from pathlib import Path

import pandas as pd
import pytest

from flexmodal.app import main

TABLE31 = {"assumed_modes_hz": "assumed-modes", "simplified_fem_hz": "simplified-fem",
           "detailed_fem_hz": "detailed-fem"}


def seed_to_modal_tables(frame: pd.DataFrame, freq_columns: dict[str, str], out: Path,
                         config: str = "nominal") -> dict[str, Path]:
    """Write one ModalTable CSV per source from a wide seed table {column: source name}."""
    paths = {}
    for column, source in freq_columns.items():
        df = pd.DataFrame({"config": config, "mode": frame["mode"], "freq_hz": frame[column],
                           "source": source})
        if source == "experiment" and "damping_ratio" in frame:
            df["damping_ratio"] = frame["damping_ratio"]
        paths[source] = out / f"{source}.csv"
        df.to_csv(paths[source], index=False)
    return paths


def run_cli(argv: list[str], capsys) -> str:
    assert main(argv) == 0
    return capsys.readouterr().out


@pytest.fixture()
def table31(data_dir, tmp_path):
    seed = pd.read_csv(data_dir / "seeds/seed001_table3_1_system_frequencies.csv")
    paths = seed_to_modal_tables(seed, {**TABLE31, "experiment_hz": "experiment"}, tmp_path)
    return seed, paths


def test_table_3_1_csv_reproduces_every_number(table31, capsys):
    seed, paths = table31
    out = run_cli(["compare", str(paths["experiment"]), *(str(paths[s]) for s in TABLE31.values()),
                   "--format", "csv"], capsys)
    rows = list(csv.DictReader(io.StringIO(out)))
    assert len(rows) == 6
    for row, (_, ref) in zip(rows, seed.iterrows(), strict=True):
        assert int(row["mode"]) == ref["mode"]
        assert float(row["experiment_freq_hz"]) == pytest.approx(ref["experiment_hz"], abs=5e-3)
        assert float(row["experiment_damping_pct"]) == pytest.approx(100 * ref["damping_ratio"], abs=5e-3)
        for column, source in TABLE31.items():
            assert float(row[f"{source}_freq_hz"]) == ref[column]            # full precision, exact
            expected = 100 * (ref[column] - ref["experiment_hz"]) / ref["experiment_hz"]
            assert float(row[f"{source}_err_pct"]) == pytest.approx(expected, rel=1e-12)
    assert float(rows[1]["assumed-modes_err_pct"]) == pytest.approx(40.8333333333, rel=1e-10)  # 16.90/12.00
    assert float(rows[3]["detailed-fem_err_pct"]) == pytest.approx(5.63012027192, rel=1e-10)  # 60.60/57.37
    assert not rows[1]["assumed-modes_err_pct"].startswith("+")       # a plain number, not display text


def test_json_rows_carry_full_precision_and_md_rounds(table31, capsys):
    seed, paths = table31
    argv = ["compare", str(paths["experiment"]), str(paths["detailed-fem"])]
    rows = json.loads(run_cli([*argv, "--format", "json"], capsys),
                      parse_constant=lambda c: pytest.fail(f"non-standard JSON {c}"))
    assert rows[3]["detailed-fem_freq_hz"] == seed["detailed_fem_hz"][3]
    assert rows[3]["detailed-fem_err_pct"] == pytest.approx(100 * (60.60 - 57.37) / 57.37, rel=1e-12)
    assert "| +5.6 |" in run_cli(argv, capsys)


def test_table_3_1_markdown_has_units_in_every_header(table31, capsys):
    _, paths = table31
    out = run_cli(["compare", str(paths["experiment"]), *(str(paths[s]) for s in TABLE31.values())], capsys)
    lines = out.strip().splitlines()
    head = [h.strip() for h in lines[0].strip("|").split("|")]
    assert head == ["mode", "assumed-modes f [Hz]", "simplified-fem f [Hz]", "detailed-fem f [Hz]",
                    "experiment f [Hz]", "experiment ζ [%]", "assumed-modes Δf [%]",
                    "simplified-fem Δf [%]", "detailed-fem Δf [%]"]
    assert len(lines) == 2 + 6
    assert "| 2 | 16.90 | 15.24 | 12.78 | 12.00 | 1.30 | +40.8 | +27.0 | +6.5 |" in lines


def _tex_rows(tex: str) -> list[str]:
    body = tex.split(r"\toprule")[1].split(r"\bottomrule")[0]
    return [r for r in body.replace(r"\midrule", "").split(r"\\") if r.strip()]


def test_tex_is_a_balanced_booktabs_table(table31, tmp_path, capsys):
    _, paths = table31
    out_file = tmp_path / "t31.tex"
    printed = run_cli(["compare", str(paths["experiment"]), *(str(paths[s]) for s in TABLE31.values()),
                       "--format", "tex", "--out", str(out_file)], capsys)
    assert printed.strip() == str(out_file)
    tex = out_file.read_text()
    for env in ("table", "tabular"):
        assert tex.count(rf"\begin{{{env}}}") == tex.count(rf"\end{{{env}}}") == 1
    assert tex.index(r"\toprule") < tex.index(r"\midrule") < tex.index(r"\bottomrule")
    assert tex.count("{") == tex.count("}")
    assert tex.count("$") % 2 == 0
    n_cols = len(re.search(r"\\begin\{tabular\}\{([lrc]+)\}", tex).group(1))
    rows = _tex_rows(tex)
    assert len(rows) == 1 + 6
    for row in rows:
        assert len(re.findall(r"(?<!\\)&", row)) == n_cols - 1
    assert re.search(r"(?<!\\)%", tex) is None  # every percent sign escaped
    assert r"+40.8" in rows[2] and r"$\zeta$ [\%]" in rows[0]


class _Cells(HTMLParser):
    def __init__(self):
        super().__init__()
        self.rows: list[list[str]] = []
        self._cell: list[str] | None = None

    def handle_starttag(self, tag, attrs):
        if tag == "tr":
            self.rows.append([])
        elif tag in ("td", "th"):
            self._cell = []

    def handle_endtag(self, tag):
        if tag in ("td", "th") and self._cell is not None:
            self.rows[-1].append("".join(self._cell))
            self._cell = None

    def handle_data(self, data):
        if self._cell is not None:
            self._cell.append(data)


def test_table_2_sources_layout(data_dir, tmp_path, capsys):
    freq = pd.read_csv(data_dir / "seeds/seed000_table2_frequencies.csv")
    damping = pd.read_csv(data_dir / "seeds/seed000_damping_logdec.csv")
    wide = freq.pivot(index="mode", columns="source", values="freq_hz").reset_index()
    wide = wide.merge(damping, on="mode")
    paths = seed_to_modal_tables(wide, {"impact_experiment": "experiment", "fe_undamped": "fe-undamped",
                                        "fe_damped": "fe-damped"}, tmp_path)
    out = run_cli(["compare", str(paths["experiment"]), str(paths["fe-undamped"]), str(paths["fe-damped"]),
                   "--layout", "sources", "--format", "html"], capsys)
    parser = _Cells()
    parser.feed(out)
    head, *body = parser.rows
    assert head == ["source", "quantity"] + [f"mode {m} [Hz, %]" for m in range(1, 5)]
    by_line = {(r[0], r[1]): r[2:] for r in body}
    assert by_line[("fe-undamped", "f [Hz]")] == ["9.16", "20.70", "26.70", "57.20"]
    assert by_line[("experiment", "f [Hz]")] == ["8.30", "17.60", "24.90", "50.70"]
    assert by_line[("fe-damped", "f [Hz]")] == ["8.83", "17.60", "26.70", "50.50"]
    assert by_line[("experiment", "ζ [%]")] == ["13.00", "6.00", "7.00", "6.00"]
    # (9.16 - 8.30)/8.30 = 10.4 %, (20.7 - 17.6)/17.6 = 17.6 %, (26.7 - 24.9)/24.9 = 7.2 %, (57.2 - 50.7)/50.7
    assert by_line[("fe-undamped", "Δf [%]")] == ["+10.4", "+17.6", "+7.2", "+12.8"]
    assert by_line[("fe-damped", "Δf [%]")] == ["+6.4", "+0.0", "+7.2", "-0.4"]
    assert out.lstrip().startswith("<!DOCTYPE html>") and "<script" not in out and "http" not in out


def test_unpaired_modes_are_listed_not_dropped(tmp_path, capsys):
    meas, pred = tmp_path / "m.csv", tmp_path / "p.csv"
    meas.write_text("config,mode,freq_hz\nc,1,10\nc,2,20\nc,3,30\n")
    pred.write_text("config,mode,freq_hz,source\nc,1,11\nc,2,19\nd,1,5\n".replace("\n", ",fe\n")
                    .replace("source,fe", "source"))
    out = run_cli(["compare", str(meas), str(pred)], capsys)
    assert "fe: no predicted mode pairs with measured mode 3 of c (30.00 Hz)" in out
    assert "fe: mode 1 of d (5.00 Hz) pairs with no measured mode" in out
    assert "| d |  | 5.00 |" in out  # its own row, experiment cell empty


def test_bad_input_exits_2_with_one_line(tmp_path, capsys):
    meas = tmp_path / "m.csv"
    meas.write_text("config,mode\nc,1\n")
    assert main(["compare", str(meas), str(meas)]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "freq_hz" in err
    assert main(["compare", str(tmp_path / "missing.csv"), str(meas)]) == 2


def test_configurations_follow_pose_order_not_text_order(tmp_path, capsys):
    meas, pred = tmp_path / "m.csv", tmp_path / "p.csv"
    rows = [("theta120", 120, 40.0), ("theta60", 60, 30.0), ("theta0", 0, 25.0)]
    meas.write_text("config,mode,freq_hz,pose.theta_deg\n" + "".join(f"{c},1,{f},{t}\n" for c, t, f in rows))
    pred.write_text("config,mode,freq_hz,source\n" + "".join(f"{c},1,{1.1 * f},fe\n" for c, _, f in rows))
    out = run_cli(["compare", str(meas), str(pred), "--format", "csv"], capsys)
    got = [(r["config"], float(r["fe_err_pct"])) for r in csv.DictReader(io.StringIO(out))]
    assert [c for c, _ in got] == ["theta0", "theta60", "theta120"]
    assert [e for _, e in got] == pytest.approx([10.0] * 3, rel=1e-12)
