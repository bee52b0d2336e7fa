"""One registry shape (checked_io.registry): every family offers register_x / unregister_x /
registered_x(), its built-ins are named once (imported on first use), and the command line's choices are
the registry itself, so --help lists exactly what is registered, toys included."""

from __future__ import annotations

import pytest
from cli_help import choices, help_text

from flexmodal.daq import protocols
from flexmodal.daq.devices import Driver
from flexmodal.fixtures import simulators
from flexmodal.modal import registry as modal_registry
from flexmodal.models import effects
from flexmodal.models import registry as model_registry

# (family, register, unregister, registered, command path, option)
FAMILIES = [
    ("estimator", modal_registry.register_estimator, modal_registry.unregister_estimator,
     modal_registry.registered_estimators, ("frf",), "--estimator"),
    ("model", model_registry.register_model, model_registry.unregister_model,
     model_registry.registered_models, ("predict",), "--model"),
    ("method", modal_registry.register_method, modal_registry.unregister_method,
     modal_registry.registered_methods, ("identify",), "--method"),
    ("simulator", simulators.register_simulator, simulators.unregister_simulator,
     simulators.registered_simulators, ("sim", "serve"), "--protocol"),
]


@pytest.mark.parametrize("family", FAMILIES, ids=[f[0] for f in FAMILIES])
def test_help_choices_are_the_registry_toys_included(family):
    _, register, unregister, registered, path, option = family
    assert choices(path, option) == registered()
    register("toy-entry", modal_registry.Method("frf", print, "a toy") if family[0] == "method"
             else lambda *args: None)
    try:
        assert registered()[-1] == "toy-entry" and choices(path, option) == registered()
        assert "toy-entry" in help_text(*path)
    finally:
        unregister("toy-entry")
    assert "toy-entry" not in registered() and "toy-entry" not in choices(path, option)


def test_built_ins_resolve_to_what_their_family_needs():
    assert all(callable(modal_registry.ESTIMATORS[n]) for n in modal_registry.registered_estimators())
    assert all(callable(model_registry.MODELS[n]) for n in model_registry.registered_models())
    assert all(callable(simulators.SIMULATORS[n]) for n in simulators.registered_simulators())
    assert all(callable(modal_registry.METHODS[n].runner()) for n in modal_registry.registered_methods())
    assert all(issubclass(protocols.PROTOCOLS[n], Driver) for n in protocols.registered_protocols())
    assert set(simulators.registered_simulators()) <= set(protocols.registered_protocols())
    assert all(isinstance(effects.REGISTRY[n], effects.Effect) for n in effects.registered_effects())


def test_unknown_names_are_the_familys_one_line_error():
    from flexmodal.daq.errors import DaqError
    from flexmodal.models.errors import ModelError

    with pytest.raises(ModelError, match=r"unknown model 'nope' \(expected one of fe, assumed-modes"):
        model_registry.MODELS.entry("nope")
    with pytest.raises(DaqError, match="unknown protocol 'nope'"):
        protocols.unregister_protocol("nope")
    with pytest.raises(ModelError, match="unknown effect 'nope'"):
        effects.get_effect("nope")
