"""The registries of `modal`, light enough for the command line: listing their names imports no numpy.

``ESTIMATORS``: FRF estimators, each a function of the averaged spectra (modal.spectra.Spectra) returning
H [n_out, n_in, n_freq]; ``flexmodal frf --estimator``, the stored ``estimator`` attribute and
modal.frf.estimate all read it.  Built-ins are named here and imported on first use.
"""

from __future__ import annotations

from collections.abc import Callable

from flexmodal.checked_io.registry import Registry
from flexmodal.modal.errors import ModalError

ESTIMATORS: Registry[Callable] = Registry(
    "FRF estimator", ModalError,
    {"H1": "flexmodal.modal.frf:h1", "H2": "flexmodal.modal.frf:h2", "Hv": "flexmodal.modal.frf:hv"},
    fold_case=True)


def register_estimator(name: str, func: Callable) -> Callable:
    """Add (or replace) the FRF estimator ``name`` (matched without regard to case): ``func(spectra)``
    returns H [n_out, n_in, n_freq] from modal.spectra.Spectra."""
    return ESTIMATORS.register(name, func)


def unregister_estimator(name: str) -> None:
    """Remove the FRF estimator ``name``."""
    ESTIMATORS.unregister(name)


def registered_estimators() -> tuple[str, ...]:
    """Names of the FRF estimators, in registration order (H1, H2, Hv first)."""
    return ESTIMATORS.names()
