"""The vectorised fast model of the diagnosis (compare/parametric.py: grouped ``reduce_family``,
sliced ``solve_family`` without gradients where only frequencies are used, one pose basis per
distinct pose) gives the previous implementation's numbers bit for bit (benchmarks/diagnosis_speed.py
holds that implementation and measures the CPU it saves)."""

from __future__ import annotations

import importlib.util
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from flexmodal.compare import parametric
from flexmodal.compare.diagnosis import _Context
from flexmodal.compare.gap import prepare
from flexmodal.compare.parametric import pose_basis
from flexmodal.contract.table import ModalTable
from flexmodal.models.rig import load_rig

REPO = Path(__file__).resolve().parents[1]


@pytest.fixture(scope="module")
def bench():
    path = REPO / "benchmarks" / "diagnosis_speed.py"
    spec = importlib.util.spec_from_file_location("diagnosis_speed", path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


@pytest.mark.parametrize(("rig_name", "n_configs"), [("demo_arm", 5), ("wrist_arm", 3)])
def test_the_vectorised_model_equals_the_previous_one_bit_for_bit(bench, rig_name, n_configs, monkeypatch):
    monkeypatch.setattr(parametric, "CHUNK_BYTES", 1)        # one point per slice: the slicing is exercised
    rig = load_rig(REPO / "fixtures" / "rigs" / f"{rig_name}.toml")
    times, differs = bench.stages(rig, n_configs, grid=3)
    assert differs == []
    assert set(times) == {"reduce", "grid", "refine"}


def test_repeated_poses_share_one_pose_basis(bench):
    rig = load_rig(bench.RIG)
    table = bench.measured_table(rig, 3)
    again = table.frame[table.frame["config"] == "c0001"].assign(config="c0001b")
    meas = prepare(rig, ModalTable.from_frame(pd.concat([table.frame, again]), "repeats"))
    ctx = _Context(rig, meas, np.ones((1, len(meas.configs)), bool))
    first, second = (meas.configs.index(c) for c in ("c0001", "c0001b"))
    assert ctx.bases[first] is ctx.bases[second]
    fresh = pose_basis(rig, ctx.handles, meas.poses[second], meas.freq_hz.shape[1])
    for key in ("K0", "M0", "Kh", "Mh"):
        assert np.array_equal(getattr(ctx.bases[second], key), getattr(fresh, key))
