"""The hook a package above `daq` plugs in to start a session's ``[simulator]``.

`daq` never imports the simulators (they live in ``flexmodal.fixtures``); the root package
``flexmodal`` registers their launcher here by name, imported on first use.  A launcher is called as
``launch(simulator, session, quiet)`` with the validated :class:`flexmodal.daq.session.Simulator`
(``fault_log`` already an absolute path inside the run's folder, or empty) and returns
``(endpoint, stop)``: the endpoint replacing the ``"@simulator"`` placeholder (a pty path, or
``host:port``; None when nothing needs replacing) and a function that stops the simulator.
"""

from __future__ import annotations

import importlib
from collections.abc import Callable

from flexmodal.daq.errors import DaqError

Launcher = Callable[..., tuple[str | None, Callable[[], None]]]
_launcher: str | Launcher | None = None


def set_simulator_launcher(launcher: str | Launcher) -> None:
    """Register the simulator launcher: a callable or ``"module:function"`` (imported on first use)."""
    global _launcher
    _launcher = launcher


def simulator_launcher() -> Launcher:
    """The registered launcher; DaqError when there is none."""
    global _launcher
    if _launcher is None:
        raise DaqError("the session has a [simulator] but no simulator launcher is registered "
                       "(set_simulator_launcher)")
    if isinstance(_launcher, str):
        module, _, name = _launcher.partition(":")
        _launcher = getattr(importlib.import_module(module), name)
    return _launcher
