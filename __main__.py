"""``python -m flexmodal``: the command line of :mod:`flexmodal.app`."""

import sys

from flexmodal.app import main

sys.exit(main())
