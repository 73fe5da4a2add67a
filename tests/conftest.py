import os

import pytest

import mitsuba_lab  # noqa: F401  (selects the variant, registers the lab plugins)

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
SCENES = os.path.join(ROOT, "scenes")


@pytest.fixture(autouse=True)
def _run_from_project_root(monkeypatch):
    """Tests name scenes relative to the project root, wherever pytest was started."""
    monkeypatch.chdir(ROOT)
