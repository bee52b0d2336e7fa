"""flexmodal: experimental modal analysis and data acquisition for flexible robot arms.

The installed distribution has this one import name; its sub-packages are the repository's top-level
folders (``flexmodal.daq`` is ``daq/``, ``flexmodal.modal`` is ``modal/`` ...).  The public Python API
is re-exported here lazily from :mod:`flexmodal.api`, so ``import flexmodal`` stays cheap.
"""

from __future__ import annotations

__version__ = "0.1.0"
