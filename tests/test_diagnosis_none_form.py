"""The ``none`` test's model-form level takes the fallback scatter as the measurement's (compare/diagnosis.py
``_model_form(split=True)``, ``_none_margin``): blind draw 1892 case 16, a weak sensor mass, stored."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

import flexmodal.compare.diagnosis as diagnosis
from flexmodal.contract.table import ModalTable
from flexmodal.models.rig import parse_rig

CASE = Path(__file__).parent / "data" / "blind_cases" / "draw1892_case16"


@pytest.mark.slow   # ~3 s CPU per diagnosis, two diagnoses
def test_a_weak_effect_under_the_fallback_scatter_is_not_none(monkeypatch):
    """Blind draw 1892 #16 (three-link arm, a 1.8 g sensor mass, 3 configurations x 3 modes with shapes, no
    repeats: the 0.5 % fallback scatter).  The sensor mass is held out 0.226 % better than the nominal
    model, beyond the paired noise margin (0.166 %).  With the fallback the ranking takes the lowest
    held-out error (0.571 %) as all model form, and so did the ``none`` test: its model-form part
    ``sqrt(h^2 + m^2) - h`` was 0.226 % and the verdict ``none``.  The ``none`` test now takes the
    model form beyond the fallback (0.276 %), as with a measured scatter.  Asserted: the hidden
    sensor mass is the verdict; with the old level (the ranking's) it is ``none``."""
    doc = json.loads(CASE.with_suffix(".json").read_text())
    truth = (doc["truth"]["effect"], doc["truth"]["location"])
    assert truth == ("sensor_mass", "sensors")
    rig, table = parse_rig(doc["rig"], "<draw 1892 case 16>"), ModalTable.read_csv(CASE.with_suffix(".csv"))
    assert table.frame["config"].nunique() == 3
    d = diagnosis.diagnose(rig, table)
    assert (d.verdict.effect, d.verdict.location) == truth, d.verdict.summary
    assert d.scatter_source.source == diagnosis.FALLBACK_SOURCE
    model_form = diagnosis._model_form
    monkeypatch.setattr(diagnosis, "_model_form", lambda noise, ranked, theory=0.0, split=False:
                        model_form(noise, ranked, theory))
    old = diagnosis.diagnose(rig, table)
    assert old.verdict.effect == "none", old.verdict.summary
