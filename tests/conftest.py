import gc
import os

import mitsuba as mi
import pytest

import mitsuba_lab  # noqa: F401  (selects the variant, registers the lab plugins)

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
SCENES = os.path.join(ROOT, "scenes")


@pytest.fixture(autouse=True)
def _run_from_project_root(monkeypatch):
    """Tests name scenes relative to the project root, wherever pytest was started."""
    monkeypatch.chdir(ROOT)


def pytest_sessionstart(session):
    """A suite started in the background of a script (``pytest &`` in a non-interactive shell)
    inherits SIGINT ignored, and so would every CLI process its Ctrl-C tests start: those tests
    would then test the shell, not the lab (17 failed this way in a full run of 2026-11-28, each
    file passing alone). The suite runs as a user at a terminal would: Python's default handler."""
    import signal

    if signal.getsignal(signal.SIGINT) is signal.SIG_IGN:
        signal.signal(signal.SIGINT, signal.default_int_handler)


@pytest.fixture(autouse=True)
def _sigint_stays_pythons(request):
    """After each test SIGINT is handled by Python's default handler again. A test that leaves
    another handler behind (SIG_IGN, or a C handler of Mitsuba's: getsignal gives None) would make
    every later Ctrl-C test fail, in this process and in the CLI processes it starts (an ignored
    SIGINT is inherited). The handler is put back and the test named in a warning."""
    import signal
    import warnings

    yield
    handler = signal.getsignal(signal.SIGINT)
    if handler is not signal.default_int_handler:
        signal.signal(signal.SIGINT, signal.default_int_handler)
        warnings.warn(f"{request.node.nodeid} left SIGINT handled by {handler!r}; Python's default put back")


@pytest.fixture(autouse=True, scope="module")
def _drop_the_module_scenes(request):
    """Scenes a test module keeps in a dict of its own (a cache shared by its tests) are dropped
    when the module ends: Dr.Jit traces a virtual call for every BSDF, emitter and shape alive
    in the process, so scenes held for the whole session made every later render slower (lab_vcm's
    pilot measured 107 ms per pass late in a full run, ~15 ms fresh)."""
    yield
    for value in list(vars(request.module).values()):
        if isinstance(value, dict) and any(holds_mitsuba(v) for v in list(value.values())):
            value.clear()
    gc.collect()


def holds_mitsuba(value) -> bool:
    """A Mitsuba object, or a tuple or list holding one."""
    if isinstance(value, (tuple, list)):
        return any(holds_mitsuba(v) for v in value)
    return isinstance(value, mi.Object)
