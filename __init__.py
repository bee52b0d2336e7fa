"""flexmodal: experimental modal analysis and data acquisition for flexible robot arms.

The installed distribution has this one import name; its sub-packages are the repository's top-level
folders (``flexmodal.daq`` is ``daq/``, ``flexmodal.modal`` is ``modal/`` ...).  The public Python API
is re-exported here lazily from :mod:`flexmodal.api`, so ``import flexmodal`` stays cheap.
"""

from __future__ import annotations

from flexmodal.api import __all__ as _api_names
from flexmodal.daq.hooks import set_simulator_launcher

__version__ = "0.1.0"

# The built-in device simulators (flexmodal.fixtures) start a session's ``[simulator]``: registered here,
# where the packages are put together, by name, so `daq` never imports `fixtures` and nothing is loaded
# until a session asks for a simulator (``fm.acquire`` on an example session needs no extra import).
set_simulator_launcher("flexmodal.fixtures.sim_serve:launch")

# The public API (flexmodal.api), re-exported on first use: ``flexmodal.identify(...)`` works after a bare
# ``import flexmodal`` without importing numpy, h5py or matplotlib up front (flexmodal.api imports its
# dependencies inside its functions, so reading its list of names here costs nothing).
__all__ = list(_api_names)


def __getattr__(name: str):
    """Resolve a public API name from :mod:`flexmodal.api` on first access (PEP 562)."""
    if name in __all__:
        from flexmodal import api

        value = getattr(api, name)
        globals()[name] = value
        return value
    raise AttributeError(f"module 'flexmodal' has no attribute {name!r}")


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(__all__))
