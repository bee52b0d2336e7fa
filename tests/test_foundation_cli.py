"""Foundation: CLI error handling (exit 2, one line naming the field) and rig validation."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest
from conftest import REPO

GOOD_LINK = """
[[link]]
name = "beam"
length_m = 1.0
section = { shape = "solid_rect", width_m = 0.02, height_m = 0.01 }
material = "steel"
"""
MATERIAL = """
[material.steel]
E_Pa = 210e9
rho_kg_m3 = 7850
"""


def run_cli(*args: str, cwd: Path | None = None) -> subprocess.CompletedProcess[str]:
    return subprocess.run([sys.executable, str(REPO / "app.py"), *args], capture_output=True, text=True,
                          cwd=cwd, timeout=600)


@pytest.mark.parametrize(
    ("rig_text", "field"),
    [
        (MATERIAL + GOOD_LINK.replace('length_m = 1.0\n', ''), "link[0].length_m: missing required field"),
        (MATERIAL + GOOD_LINK.replace('length_m = 1.0', 'length_m = -0.5'), "link[0].length_m: must be > 0"),
        (MATERIAL + GOOD_LINK.replace('"solid_rect"', '"hexagon"'), "link[0].section.shape: unknown value"),
        (MATERIAL.replace("E_Pa = 210e9\n", "") + GOOD_LINK, "material.steel.E_Pa: missing required field"),
    ],
)
def test_bad_rig_exits_2_with_one_line_naming_the_field(tmp_path: Path, rig_text: str, field: str,
                                                        warm_cli) -> None:
    """The console script in a process of its own, started warm (tests/conftest.py warm_cli: the demo
    command's cold start, 1.5 s of CPU each, is run by tests/test_cli_interrupt.py)."""
    rig = tmp_path / "bad.toml"
    rig.write_text(rig_text)
    code, stderr = warm_cli.run(["demo", "--rig", str(rig), "--out", str(tmp_path / "out")], tmp_path,
                                timeout_s=600)
    assert code == 2, stderr
    lines = stderr.strip().splitlines()
    assert len(lines) == 1, stderr
    assert str(rig) in lines[0] and field in lines[0]
    assert "Traceback" not in stderr


def test_unknown_command_and_option_value_exit_2_with_one_line(tmp_path: Path) -> None:
    for args in (["bogus"], ["demo", "--no-such-option"], ["frf", "x.h5", "--estimator", "H9"]):
        result = run_cli(*args, cwd=tmp_path)
        assert result.returncode == 2, (args, result.stderr)
        assert len(result.stderr.strip().splitlines()) == 1, result.stderr
        assert "Traceback" not in result.stderr


def test_help_lists_every_contract_command() -> None:
    result = run_cli("--help")
    assert result.returncode == 0
    for command in ("demo", "acquire", "sim", "frf", "identify", "predict", "compare", "diagnose", "report"):
        assert command in result.stdout
