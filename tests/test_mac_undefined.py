"""The one MAC (contract/mac.py) against closed forms, and what its callers make of a zero shape.

A shape that is zero at every point has no direction: its MAC is 0/0, undefined (NaN), not 0.  A
tracked-modes table shows it as NaN (like a link without shapes); pairing and tracking count it as
unlike (no evidence of likeness), so they neither fail nor pair by it.
"""

from __future__ import annotations

import numpy as np
import pytest
from test_compare_pairing import BETA_L, cantilever_shapes, table

from flexmodal.compare.modal_map import track_modes
from flexmodal.compare.pairing import pair_modes
from flexmodal.contract.mac import mac, mac_pairs


def test_mac_closed_forms_and_undefined_columns() -> None:
    a = np.array([[1.0, 1.0, 0.0], [1.0, 0.0, 0.0]])
    b = np.array([[1.0, 2.0], [1j, 0.0]])
    m = mac(a, b)
    # |a^H b|^2 / (|a|^2 |b|^2) by hand: [1,1].[1,1j] -> |1+1j|^2/(2*2) = 1/2; [1,1].[2,0] -> 4/(2*4)
    np.testing.assert_allclose(m[:2], [[0.5, 0.5], [0.5, 1.0]], rtol=1e-15)
    assert np.isnan(m[2]).all()                        # the zero column: undefined against anything
    np.testing.assert_allclose(mac_pairs(a[:, :2], np.array([[3.0, -5.0], [3.0, 0.0]])), [1.0, 1.0],
                               rtol=1e-15)
    assert np.isnan(mac_pairs(a[:, 1:], np.zeros((2, 2)))).all()
    assert np.isnan(mac(np.array([[1.0], [np.nan]]), a[:, :1]))[0, 0]


def test_modal_map_shows_an_undefined_link_and_keeps_tracking_by_frequency() -> None:
    q = np.arange(4.0)
    freqs = [np.array([10.0 + x, 20.0 + x]) for x in q]
    phi = np.array([[1.0, 1.0], [1.0, -1.0]])
    shapes = [phi.copy() for _ in q]
    shapes[2][:, 1] = 0.0                             # mode 2 has no motion at the sensors at pose 2
    m = track_modes(q, freqs, shapes)
    assert m.n_branches == 2 and m.events == ()
    np.testing.assert_allclose(m.freq_hz, np.array(freqs), rtol=1e-15)
    np.testing.assert_allclose(m.mac_link[1:, 0], 1.0, rtol=1e-15)
    assert m.mac_link[1, 1] == pytest.approx(1.0, rel=1e-15)
    assert np.isnan(m.mac_link[2, 1])                  # into the zero shape: undefined
    frame = m.to_frame()
    assert np.isnan(frame.loc[(frame.pose == 2.0) & (frame.branch == 2), "mac_link"]).all()


def test_pairing_with_a_shape_the_sensors_do_not_see() -> None:
    """A predicted mode that does not move the sensors (e.g. an axial mode under transverse
    accelerometers) is never paired by its undefined MAC; the others pair as they would alone."""
    sensors = [f"s{i}" for i in range(6)]
    phi = cantilever_shapes(np.linspace(0.2, 1.0, 6))
    f = 25.0 * BETA_L**2 / BETA_L[0] ** 2
    # numbered by rising frequency (docs/formats.md): the unseen mode, at 1.1 f2, is mode 3
    pred = {1: (f[0], phi[:, 0]), 2: (f[1], phi[:, 1]), 3: (1.1 * f[1], np.zeros(6)), 4: (f[2], phi[:, 2])}
    meas = {k + 1: (1.02 * f[k], phi[:, k]) for k in range(3)}
    pairing = pair_modes(table({"c": meas}, sensors, "test"), table({"c": pred}, sensors, "fe"), "fe")
    assert {(p.measured.mode, p.predicted.mode) for p in pairing.pairs} == {(1, 1), (2, 2), (3, 4)}
    assert all(p.mac == pytest.approx(1.0, rel=1e-12) for p in pairing.pairs)
    assert [r.mode for r in pairing.unpaired_predicted] == [3]


def test_mac_is_exact_at_any_scale_of_the_shapes() -> None:
    """Scaling a shape by a power of two changes the MAC of ordinary shapes in no bit; shapes of 1e-250
    or 1e140 (whose fourth powers under- or overflow) give the MAC of the same shapes at unit scale."""
    rng = np.random.default_rng(3)
    a = rng.standard_normal((6, 4)) + 1j * rng.standard_normal((6, 4))
    b = rng.standard_normal((6, 5))
    want = mac(a, b)
    # |a^H b|^2 / (|a|^2 |b|^2) summed by hand, at unit scale
    by_hand = np.array([[abs(np.vdot(a[:, i], b[:, j])) ** 2 / (np.vdot(a[:, i], a[:, i]).real
                                                                * np.vdot(b[:, j], b[:, j]).real)
                         for j in range(5)] for i in range(4)])
    np.testing.assert_allclose(want, by_hand, rtol=1e-13)
    assert np.array_equal(mac(a * 2.0**40, b * 2.0**-70), want)
    for scale_a, scale_b in ((1e-250, 1.0), (1e-250, 1e-250), (1e140, 1e140), (1e-250, 1e140)):
        np.testing.assert_allclose(mac(a * scale_a, b * scale_b), want, rtol=1e-14)
        np.testing.assert_allclose(mac_pairs(a[:, :4] * scale_a, b[:, :4] * scale_b),
                                   np.diag(want[:, :4]), rtol=1e-14)
