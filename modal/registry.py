"""The registries of `modal`, light enough for the command line: listing their names imports no numpy.

``ESTIMATORS``: FRF estimators, each a function of the averaged spectra (modal.spectra.Spectra) returning
H [n_out, n_in, n_freq]; ``flexmodal frf --estimator``, the stored ``estimator`` attribute and
modal.frf.estimate all read it.  ``METHODS``: identification methods (:class:`Method`), read by
``identify --method``, api.identify and the identification of a run or UFF file.  Built-ins are named
here and imported on first use.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

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


@dataclass(frozen=True)
class Method:
    """An identification method.

    ``input``: ``"frf"`` (FRFs with a force reference; ``run(inputs)`` takes a
    modal.identify.FrfInputs and returns a modal.identify.Poles) or ``"response"`` (output-only:
    ``run(inputs)`` takes a modal.oma.ResponseInputs and returns the method's result, with ``.modes``);
    ``run`` the function (``"module:function"``, imported on first use); ``caption`` one line for
    ``--help`` and reports."""

    input: str
    run: Callable | str
    caption: str

    def runner(self) -> Callable:
        """The run function, imported on first use."""
        if isinstance(self.run, str):
            import importlib

            module, _, name = self.run.partition(":")
            return getattr(importlib.import_module(module), name)
        return self.run


METHODS: Registry[Method] = Registry("identification method", ModalError, {
    "lscf": Method("frf", "flexmodal.modal.identify:lscf_poles",
                   "pLSCF + stabilisation + LSFD (default with a force channel)"),
    "peak": Method("frf", "flexmodal.modal.identify:peak_poles",
                   "CMIF peaks, half-power damping, quadrature shapes"),
    "ssi": Method("response", "flexmodal.modal.oma:run_ssi",
                  "output-only SSI-cov + stabilisation (default for excitation=operational or no force "
                  "channel)"),
    "fdd": Method("response", "flexmodal.modal.oma:run_fdd",
                  "output-only frequency-domain decomposition, EFDD damping"),
})


def register_method(name: str, method: Method) -> Method:
    """Add (or replace) the identification method ``name``."""
    return METHODS.register(name, method)


def unregister_method(name: str) -> None:
    """Remove the identification method ``name``."""
    METHODS.unregister(name)


def registered_methods() -> tuple[str, ...]:
    """Names of the identification methods, in registration order."""
    return METHODS.names()


def output_only(method: str) -> bool:
    """Whether ``method`` identifies from responses alone (no force reference)."""
    return METHODS.entry(method).input == "response"
