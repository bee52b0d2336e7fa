"""Mode pairing: optimal MAC assignment with shuffled and spurious modes, frequency-order fallback."""

from __future__ import annotations

import numpy as np
import pytest

from flexmodal.compare.pairing import pair_modes
from flexmodal.contract.table import ModalTable

# clamped-free Euler-Bernoulli beam: beta_n L roots (Blevins 1979, table 8-1)
BETA_L = np.array([1.87510407, 4.69409113, 7.85475744, 10.99554073, 14.13716839])


def cantilever_shapes(x_over_l: np.ndarray) -> np.ndarray:
    """Exact clamped-free bending shapes [n_points, 5] at fractions of the length."""
    b = BETA_L[None, :]
    x = x_over_l[:, None] * b
    sigma = (np.cosh(b) + np.cos(b)) / (np.sinh(b) + np.sin(b))
    return np.cosh(x) - np.cos(x) - sigma * (np.sinh(x) - np.sin(x))


def table(config_freqs_shapes, sensors, source):
    records = []
    for config, modes in config_freqs_shapes.items():
        for mode, (f, shape) in modes.items():
            rec = {"config": config, "mode": mode, "freq_hz": f, "source": source}
            rec.update({f"shape.{s}": v for s, v in zip(sensors, shape, strict=True)})
            records.append(rec)
    return ModalTable.from_records(records, source)


def test_shuffled_measured_modes_with_a_spurious_mode_are_paired_by_mac():
    rng = np.random.default_rng(7)
    sensors = [f"s{i}" for i in range(8)]
    x = np.linspace(0.15, 1.0, 8)
    phi = cantilever_shapes(x)
    f_true = 25.3 * BETA_L**2 / BETA_L[0] ** 2
    predicted = table({"theta0": {k + 1: (f_true[k], phi[:, k]) for k in range(5)}}, sensors, "fe")

    # measured: frequencies off by up to 25 % (so frequency order would pair wrongly), noisy shapes,
    # numbered by rising measured frequency (docs/formats.md), so the 2nd and 3rd true modes swap numbers,
    # plus a spurious mode between them whose shape is orthogonal to every true one
    f_meas = f_true * np.array([1.02, 1.25, 0.80, 1.05, 0.97])
    shapes_meas = phi * rng.choice([-1.0, 1.0], 5) + 0.03 * np.abs(phi).max() * rng.standard_normal(phi.shape)
    q, _ = np.linalg.qr(np.column_stack([phi, rng.standard_normal(8)]))
    spurious = q[:, -1]
    f_spurious = 0.5 * (f_true[1] + f_true[2])
    order = np.argsort(np.argsort(np.append(f_meas, f_spurious)))  # measured mode number - 1 of each

    modes = {int(order[k]) + 1: (f_meas[k], shapes_meas[:, k]) for k in range(5)}
    modes[int(order[5]) + 1] = (f_spurious, spurious)
    measured = table({"theta0": modes}, sensors, "experiment")

    pairing = pair_modes(measured, predicted, "fe")
    got = {p.predicted.mode: p.measured.mode for p in pairing.pairs}
    assert got == {k + 1: int(order[k]) + 1 for k in range(5)}
    assert [r.mode for r in pairing.unpaired_measured] == [int(order[5]) + 1]
    assert pairing.unpaired_predicted == ()
    assert all(p.method == "mac" and p.mac > 0.98 for p in pairing.pairs)
    for p in pairing.pairs:
        k = p.predicted.mode - 1
        assert p.rel_error == pytest.approx((f_true[k] - f_meas[k]) / f_meas[k], rel=1e-12)


def test_frequency_order_without_shapes_and_lone_configs():
    measured = ModalTable.from_records(
        [{"config": "a", "mode": m, "freq_hz": f} for m, f in ((1, 10.0), (2, 30.0), (3, 50.0))]
        + [{"config": "only-measured", "mode": 1, "freq_hz": 7.0}])
    predicted = ModalTable.from_records(
        [{"config": "a", "mode": m, "freq_hz": f} for m, f in ((1, 11.0), (2, 27.0))]
        + [{"config": "only-predicted", "mode": 1, "freq_hz": 8.0}])
    p = pair_modes(measured, predicted, "m")
    assert [(q.measured.mode, q.predicted.mode, q.method) for q in p.pairs] == [
        (1, 1, "frequency"), (2, 2, "frequency")]
    assert p.pairs[0].rel_error == pytest.approx(0.1, rel=1e-14)
    assert p.pairs[1].rel_error == pytest.approx(-0.1, rel=1e-14)
    assert np.isnan(p.pairs[0].mac)
    assert {(r.config, r.mode) for r in p.unpaired_measured} == {("a", 3), ("only-measured", 1)}
    assert [(r.config, r.mode) for r in p.unpaired_predicted] == [("only-predicted", 1)]


def test_low_mac_pair_is_rejected():
    sensors = ["a", "b", "c"]
    measured = table({"c": {1: (10.0, [1.0, 0.0, 0.0])}}, sensors, "experiment")
    predicted = table({"c": {1: (10.5, [0.0, 1.0, 0.2])}}, sensors, "fe")
    p = pair_modes(measured, predicted, "fe")
    assert p.pairs == ()
    assert [r.mode for r in p.unpaired_measured] == [1] and [r.mode for r in p.unpaired_predicted] == [1]


def test_configs_without_namesake_are_matched_by_pose():
    def rows(config, theta, freqs):
        return [{"config": config, "mode": k + 1, "freq_hz": f, "pose.theta_deg": theta}
                for k, f in enumerate(freqs)]

    measured = ModalTable.from_records(rows("theta0-impact", 0, [10.0, 30.0])
                                       + rows("theta0-random", 0, [10.2])
                                       + rows("theta90-impact", 90, [12.0]))
    predicted = ModalTable.from_records(rows("theta0", 0, [11.0, 33.0, 70.0]) + rows("theta45", 45, [11.5]))
    p = pair_modes(measured, predicted, "fe")
    got = [(q.measured.config, q.measured.mode, q.predicted.config, q.predicted.mode) for q in p.pairs]
    assert got == [("theta0-impact", 1, "theta0-impact", 1), ("theta0-impact", 2, "theta0-impact", 2),
                   ("theta0-random", 1, "theta0-random", 1)]
    assert p.pairs[1].rel_error == pytest.approx(0.1, rel=1e-14)
    assert {(r.config, r.mode) for r in p.unpaired_predicted} == {
        ("theta0-impact", 3), ("theta0-random", 2), ("theta0-random", 3), ("theta45", 1)}
    assert [(r.config, r.mode) for r in p.unpaired_measured] == [("theta90-impact", 1)]
