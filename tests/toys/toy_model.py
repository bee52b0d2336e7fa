"""A toy model, the whole of it: the arm as one mass on one spring whose stiffness follows the elbow
angle, k = K0 (1 + theta/90 deg), m = M; f = sqrt(k/m) / 2 pi, no shapes."""

import math

from flexmodal.models.registry import register_model

NAME = "toy-sdof"
K0_N_PER_M, M_KG = 4.0e4, 2.5


def natural_freq_hz(theta_deg: float) -> float:
    return math.sqrt(K0_N_PER_M * (1.0 + theta_deg / 90.0) / M_KG) / (2.0 * math.pi)


def solve(rig, poses, n_modes, options):
    """One mode per pose (asking for more is the model's one-line error)."""
    import numpy as np

    from flexmodal.models.errors import ModelError

    if n_modes != 1:
        raise ModelError(f"model {NAME!r} has one mode (asked for {n_modes})")
    for pose in poses:
        yield np.array([natural_freq_hz(pose.get("theta_deg", 0.0))]), None


register_model(NAME, solve)
