"""``mitsuba_lab.interrupts``, in this process: after a lab integrator's render, SIGINT still
raises KeyboardInterrupt (Mitsuba 3.9's handler used to swallow it for good). Also the pieces:
``rendering``, ``checkpoint``, ``deferred``. Real Ctrl-C to the commands is in test_sigint.py."""
import ctypes
import signal

import mitsuba as mi
import pytest

from mitsuba_lab import interrupts
from mitsuba_lab.plugins.interrupts import checkpoint


def sigint_raises() -> bool:
    """Deliver SIGINT to this process: True if Python raised KeyboardInterrupt for it."""
    try:
        signal.raise_signal(signal.SIGINT)
    except KeyboardInterrupt:
        return True
    return False


@pytest.fixture(scope="module")
def cornell():
    return mi.load_file("scenes/cornell_box.xml", res=16)


@pytest.mark.slow
@pytest.mark.parametrize("kind", ["path", "lab_mis", "lab_photon", "lab_bdpt", "lab_vcm"])
def test_sigint_raises_keyboard_interrupt_after_a_render(cornell, kind):
    # through mi.render itself, as a user's script renders with the lab's plugins
    params = {"photons_per_pass": 2000} if kind == "lab_photon" else {}
    integrator = mi.load_dict({"type": kind, **params})
    mi.render(cornell, integrator=integrator, spp=2)
    assert sigint_raises()


def test_rendering_raises_a_wrapped_interrupt_as_keyboard_interrupt():
    with pytest.raises(KeyboardInterrupt) as caught:
        with interrupts.rendering():
            try:
                raise KeyboardInterrupt
            except KeyboardInterrupt as err:
                raise RuntimeError("drjit.custom(<_RenderOp>): error (see above).") from err
    assert isinstance(caught.value.__cause__, RuntimeError)
    with pytest.raises(ValueError):                 # any other error passes unchanged
        with interrupts.rendering():
            raise ValueError("bad")


class Cancelled:
    def __init__(self, stop: bool):
        self.stop = stop

    def should_stop(self) -> bool:
        return self.stop


def test_checkpoint_raises_when_mitsuba_cancelled_the_render():
    checkpoint(Cancelled(False))         # nothing to do
    with pytest.raises(KeyboardInterrupt):
        checkpoint(Cancelled(False), Cancelled(True))


def test_checkpoint_respects_an_ignored_sigint():
    """The sweep's render process ignores SIGINT (its caller handles Ctrl-C): so does the check."""
    previous = signal.signal(signal.SIGINT, signal.SIG_IGN)
    try:
        checkpoint(Cancelled(True))
    finally:
        signal.signal(signal.SIGINT, previous)


def test_deferred_holds_sigint_until_the_block_ends():
    steps = []
    with pytest.raises(KeyboardInterrupt):
        with interrupts.deferred():
            signal.raise_signal(signal.SIGINT)
            steps.append("after the signal")          # the block goes on
    assert steps == ["after the signal"]
    assert signal.getsignal(signal.SIGINT) is signal.default_int_handler
    with interrupts.deferred():                       # no signal: nothing raised
        steps.append("quiet")
    assert sigint_raises()                            # and Python's handler is back


class _Swallower:
    """An attribute during whose lookup SIGINT arrives."""

    def __getattr__(self, name):
        signal.raise_signal(signal.SIGINT)
        raise AttributeError(name)


def c_hasattr(obj, name: str) -> bool:
    """``PyObject_HasAttr``, as Dr.Jit's C++ calls it on loop state (Python's own ``hasattr``
    passes KeyboardInterrupt on; this C function, before Python 3.13, clears any error)."""
    return bool(ctypes.pythonapi.PyObject_HasAttr(ctypes.py_object(obj), ctypes.py_object(name)))


def test_hasattr_swallows_a_sigint_outside_sticky():
    # the failure sticky() exists for: without it, this Ctrl-C is gone
    assert not c_hasattr(_Swallower(), "state")
    interrupts.raise_pending()                             # nothing noted: nothing raised


def test_sticky_raises_a_swallowed_sigint_at_the_next_checkpoint():
    with interrupts.sticky():
        assert not c_hasattr(_Swallower(), "state")          # swallowed as before ...
        with pytest.raises(KeyboardInterrupt):             # ... and raised again here
            checkpoint()
        checkpoint()                                       # once only
    assert signal.getsignal(signal.SIGINT) is signal.default_int_handler


def test_sticky_raises_a_sigint_swallowed_inside_a_render_when_it_returns():
    with interrupts.sticky():
        with pytest.raises(KeyboardInterrupt):
            with interrupts.rendering():
                c_hasattr(_Swallower(), "state")
        assert sigint_raises()                             # Ctrl-C still raises as usual ...
        with pytest.raises(KeyboardInterrupt):             # ... and stays noted: caught and
            interrupts.raise_pending()                     # dropped somewhere, it comes again


def test_sticky_leaves_an_ignored_or_custom_handler_alone():
    for handler in (signal.SIG_IGN, lambda signum, frame: None):
        previous = signal.signal(signal.SIGINT, handler)
        try:
            with interrupts.sticky():
                assert signal.getsignal(signal.SIGINT) is handler
        finally:
            signal.signal(signal.SIGINT, previous)
