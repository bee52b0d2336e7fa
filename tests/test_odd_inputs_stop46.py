"""Odd inputs found by Review 47: documents given as Python dicts (the API path, which the TOML file
reader's integer-size guard does not see) with an integer beyond a float's range."""
from __future__ import annotations

import pytest

from flexmodal.checked_io.toml_fields import DOTTED_PATH, Fields
from flexmodal.daq.errors import DaqError
from flexmodal.models.errors import ModelError
from flexmodal.models.rig import parse_rig

HUGE = 10**400   # a TOML integer has no size limit; float(HUGE) raises OverflowError


def _rig(kappa: object, nu: object) -> dict:
    return {"name": "bar", "material": {"al": {"E_Pa": 70e9, "rho_kg_m3": 2700, "nu": nu}},
            "link": [{"name": "l", "length_m": 1.0, "material": "al",
                      "section": {"shape": "solid_rect", "width_m": 0.01, "height_m": 0.01,
                                  "shear_coefficient": kappa}}]}


@pytest.mark.parametrize("kappa, nu, field", [(HUGE, 0.3, "shear_coefficient"), (0.85, HUGE, "nu")])
def test_a_huge_integer_in_a_rig_dict_is_one_model_error_naming_its_field(kappa, nu, field) -> None:
    with pytest.raises(ModelError, match=field):
        parse_rig(_rig(kappa, nu), "<doc>")


def test_a_huge_integer_for_a_float_field_is_not_finite() -> None:
    with pytest.raises(DaqError, match=r"s\.toml: rate_hz: .*not a finite number|s\.toml: rate_hz"):
        Fields({"rate_hz": HUGE}, "s.toml", DaqError, wording=DOTTED_PATH).number("rate_hz", lo=0.0)
