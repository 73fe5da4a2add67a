"""pytest over benchmarks/agreement and benchmarks/power: the checks that left the suite (the
full agreement matrices, the expensive power proofs) run with the suite's own fixtures and
helpers. `python -m pytest -q` (testpaths = tests) never collects them; run them by path:

    PYTHONPATH=src .venv/bin/python -m pytest -q -p no:cacheprovider benchmarks/agreement
    PYTHONPATH=src .venv/bin/python -m pytest -q -p no:cacheprovider benchmarks/power
"""
import importlib.util
import os
import sys

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
TESTS = os.path.join(ROOT, "tests")
for folder in (os.path.join(TESTS, "plugins"), TESTS):
    if folder not in sys.path:
        sys.path.insert(0, folder)

# The suite's conftest (chdir to the project root, SIGINT kept Python's, module scenes dropped),
# loaded under a name of its own: its fixtures and hook become this conftest's.
_spec = importlib.util.spec_from_file_location("_suite_conftest", os.path.join(TESTS, "conftest.py"))
_suite = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(_suite)
_run_from_project_root = _suite._run_from_project_root
_sigint_stays_pythons = _suite._sigint_stays_pythons
_drop_the_module_scenes = _suite._drop_the_module_scenes
pytest_sessionstart = _suite.pytest_sessionstart
holds_mitsuba = _suite.holds_mitsuba
