"""``python -m mitsuba_lab``: the ``mitsuba-lab`` command, after the package's own import has
selected its variant (``$MITSUBA_LAB_VARIANT``, else ``llvm_ad_rgb``; ``--variant`` then
switches). ``python -m mitsuba_lab_command`` is the command exactly as installed."""
import sys

from .cli import main

sys.exit(main())
