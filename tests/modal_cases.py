"""Simulated records shared by several modal tests (known modes from fixtures.modal_sim)."""

from __future__ import annotations

import numpy as np

from flexmodal.fixtures.modal_sim import modal_response

FOUR_MODES_HZ = np.array([31.0, 77.0, 140.0, 230.0])


def four_mode_random_record(rng: np.random.Generator, fs_hz: float = 1024.0,
                            duration_s: float = 300.0) -> np.ndarray:
    """[n, 4] record (force N, three accelerations) of a 4-mode system (FOUR_MODES_HZ, ζ 1-2 %, driving
    point at the first sensor) under white-noise force, with 1 % response noise."""
    zeta = np.array([0.02, 0.012, 0.01, 0.015])
    phi = np.array([[1.0, 0.7, 0.4, -0.5], [0.5, -0.8, 0.9, 0.6], [0.3, 0.9, -0.6, 0.8]])
    force = rng.standard_normal((int(duration_s * fs_hz), 1))
    y = modal_response(force, fs_hz, FOUR_MODES_HZ, zeta, phi, phi[[0]])
    y += 0.01 * y.std(axis=0) * rng.standard_normal(y.shape)
    return np.column_stack([force, y])
