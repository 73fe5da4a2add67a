"""The ``mitsuba-lab`` command's entry point (``python -m mitsuba_lab_command`` is the same).

It lives outside the ``mitsuba_lab`` package because it must run before the package is
imported: importing ``mitsuba_lab`` selects a Mitsuba variant and registers the lab plugins
unless ``MITSUBA_LAB_ACTIVATE`` is ``0``, and the command selects the variant itself, after
reading ``--variant`` (so that ``--help`` loads no Mitsuba, a bad environment is reported in
one line, and a GPU-only machine never starts the LLVM backend).
"""
from __future__ import annotations

import os
import sys

#: ``mitsuba_lab.ACTIVATE_ENV`` (the package cannot be imported to read it before it is set).
ACTIVATE_ENV = "MITSUBA_LAB_ACTIVATE"


def main(argv: list[str] | None = None) -> int:
    """Import the package without selecting a variant, then run the command line."""
    previous = os.environ.get(ACTIVATE_ENV)
    os.environ[ACTIVATE_ENV] = "0"
    try:
        from mitsuba_lab.cli import main as run
    finally:
        # The processes the command starts import the package as a library again.
        if previous is None:
            del os.environ[ACTIVATE_ENV]
        else:
            os.environ[ACTIVATE_ENV] = previous
    return run(argv)


if __name__ == "__main__":
    sys.exit(main())
