"""The diagnosis on rigs that set shear deformation (``shear_coefficient``, models/rig.py ``Shear``)."""

from __future__ import annotations

import html
import json
import math

import numpy as np
import pytest
from conftest import REPO, RIGS

from flexmodal.app import main
from flexmodal.compare.diagnosis import POISSON, _beam_theory_form
from flexmodal.compare.verdict_text import SHEAR_UNCALIBRATED
from flexmodal.models.rig import parse_rig

E, RHO, H = 70e9, 2700.0, 0.01      # Pa, kg/m^3, m: a solid 10 mm x 10 mm aluminium bar
SOLID = {"shape": "solid_rect", "width_m": H, "height_m": H}
SHEARED = {**SOLID, "shear_coefficient": 0.85}
MEASURED = REPO / "examples" / "measured" / "seed003_table3_f1f2.csv"


def _bar(section: dict, segments: list[tuple[float, float, dict]]) -> object:
    return parse_rig({"name": "bar", "material": {"al": {"E_Pa": E, "rho_kg_m3": RHO, "nu": 0.33}},
                      "link": [{"name": "l", "length_m": 1.0, "material": "al", "section": section,
                                "segments": [{"from": a, "to": b, "section": s} for a, b, s in segments]}]},
                     "<test>")


@pytest.mark.parametrize(("section", "segments", "unsheared"), [
    (SOLID, [(0.2, 0.5, SHEARED)], 0.7),                   # segments set shear on 0.3 m of a plain link
    (SHEARED, [(0.0, 0.4, SOLID)], 0.4),                   # a plain segment on a sheared link
    (SOLID, [(0.0, 0.6, SHEARED), (0.6, 1.0, SHEARED)], 0.0),   # segments set shear on all of it
    (SOLID, [(0.1, 0.3, SOLID)], 1.0),                     # no shear anywhere
])
def test_the_shear_term_counts_on_the_part_of_the_link_without_shear(section, segments, unsheared):
    """The beam-theory level of a bar whose segments override its section's shear is Timoshenko's
    first-order term ``(k r)^2 (1 + w E / (kappa G)) / 2`` at 100 Hz (``(k r)^2 = omega r / c``, ``r^2 =
    h^2 / 12``, ``c = sqrt(E / rho)``, kappa 5/6, ``E / G = 2 (1 + nu)``) with ``w`` the length fraction
    of the bar without shear: before, only the link section was read (0.3 m of shear in segments kept
    the whole term, a plain segment on a sheared link none)."""
    level = _beam_theory_form(_bar(section, segments), np.array([[100.0]]))
    kr2 = 2 * math.pi * 100.0 * (H / math.sqrt(12)) / math.sqrt(E / RHO)
    assert level == pytest.approx(0.5 * kr2 * (1 + unsheared * 2 * (1 + POISSON) / (5 / 6)), rel=1e-12)


def test_segments_without_shear_leave_the_level_bit_for_bit():
    """Segments that set no shear (of another section too) leave the level exactly that of the link
    section alone (``==``), as before segments were read: the Euler-Bernoulli path is unchanged; and
    on a sheared link, so do sheared segments."""
    other = {"shape": "round_tube", "outer_m": 0.02, "wall_m": 0.002}
    freq = np.array([[3.7, 41.0, 130.0], [5.1, 47.0, np.nan]])
    for section in (SOLID, SHEARED):
        alone = _beam_theory_form(_bar(section, []), freq)
        assert _beam_theory_form(_bar(section, [(0.1, 0.3, section), (0.3, 0.35, section)]), freq) == alone
    plain = _beam_theory_form(_bar(SOLID, []), freq)
    assert _beam_theory_form(_bar(SOLID, [(0.0, 0.5, other)]), freq) == plain


@pytest.mark.parametrize("shear", [True, False], ids=["segment with shear", "none"])
def test_the_cli_says_once_that_the_none_gate_was_not_calibrated_with_shear(tmp_path, capsys, shear):
    """``flexmodal diagnose`` on seed 003's rig whose second link has a segment with
    ``shear_coefficient``: one warning line on stderr, the same line in diagnosis.json's ``warnings``
    and in the report (docs/formats.md's wording: the ``none`` gate and beam-theory allowance were
    calibrated on Euler-Bernoulli frames); without shear, no warning."""
    text = (RIGS / "seed003_two_link.toml").read_text()
    if shear:
        text = text.replace("rho_kg_m3 = 2700", "rho_kg_m3 = 2700\nnu = 0.33").replace(
            'name = "link2"', 'name = "link2"\nsegments = [{ from = 0.0, to = 0.3, section = { shape = '
            '"square_tube", outer_m = 0.040, wall_m = 0.0011, shear_coefficient = 0.5 } }]')
    rig = tmp_path / "rig.toml"
    rig.write_text(text)
    code = main(["--quiet", "diagnose", "--rig", str(rig), "--measured", str(MEASURED), "--out",
                 str(tmp_path / "out"), "--effects", "joint_stiffness", "--holdout",
                 "theta30,theta90,theta150"])
    line = f"{rig}: {SHEAR_UNCALIBRATED}"
    err = capsys.readouterr().err.splitlines()
    assert code == 0 and err == ([f"flexmodal: warning: {line}"] if shear else [])
    warnings = json.loads((tmp_path / "out" / "diagnosis.json").read_text()).get("warnings")
    assert warnings == ([line] if shear else None)
    page = (tmp_path / "out" / "diagnosis.html").read_text()
    assert (f'<th>not calibrated with shear</th><td class="warn">{html.escape(line)}</td>' in page) == shear
