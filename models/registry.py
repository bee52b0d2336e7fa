"""The model registry, light enough for the command line: listing its names imports no numpy.

Each entry is a solver ``solve(rig, poses, n_modes, options)`` yielding, per pose, the elastic natural
frequencies [Hz] and the shapes at the rig's sensors [n_sensors, n_modes] (or None); models.predict.predict
turns them into a modal table, and ``flexmodal predict --model`` accepts every name.  Built-ins are named
here and imported on first use.
"""

from __future__ import annotations

from collections.abc import Callable

from flexmodal.checked_io.registry import Registry
from flexmodal.models.errors import ModelError

MODELS: Registry[Callable] = Registry("model", ModelError, {
    "fe": "flexmodal.models.predict:solve_fe",
    "assumed-modes": "flexmodal.models.predict:solve_assumed_modes",
    "lumped-mass": "flexmodal.models.predict:solve_lumped_mass",
    "blevins": "flexmodal.models.predict:solve_blevins",
})


def register_model(name: str, solve: Callable) -> Callable:
    """Add (or replace) the model ``name``; ``solve(rig, poses, n_modes, options)`` yields
    ``(freq_hz, shapes)`` per pose (shapes [n_sensors, n_modes] at ``rig.sensors``, or None)."""
    return MODELS.register(name, solve)


def unregister_model(name: str) -> None:
    """Remove the model ``name``."""
    MODELS.unregister(name)


def registered_models() -> tuple[str, ...]:
    """Names of the models, in registration order."""
    return MODELS.names()
