"""``python -m mitsuba_lab``: the same as the ``mitsuba-lab`` command."""
import sys

from .cli import main

sys.exit(main())
