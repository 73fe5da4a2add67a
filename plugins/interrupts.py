"""Ctrl-C while Mitsuba renders: Python's SIGINT handler kept in force.

Mitsuba 3.9 runs each bound render call (``Integrator.render``, ``render_forward``,
``render_backward``) under a SIGINT handler of its own (C++ ``ScopedSignalHandler``,
src/render/python/integrator_v.cpp). On Ctrl-C it logs "Received interrupt signal, winding
down..", cancels the integrator (its ``should_stop()`` turns True, which a JIT render does not
read), puts back the handler it replaced and raises SIGINT again for that one. Two things go
wrong:

* It keeps the replaced handler in one static variable. A render call made inside another
  one records Mitsuba's own handler as the one to put back, and the lab's Python integrators
  do this on every render: their ``render`` calls Mitsuba's, which calls the Python ``render``
  back, which calls Mitsuba's again. After that, Ctrl-C only prints that line twice and is lost
  for the rest of the process. The plugins' ``integrators.common.support.base_render`` calls ``restore``
  before the inner call, so it finds Python's handler.
* It puts a handler back with C ``signal()``, which restarts interrupted system calls. A
  process blocked in ``recv``, like a sweep waiting for its render process, then does not see
  Ctrl-C until the call returns.

``restore`` installs Python's handler again as ``signal.signal`` does (no restart).
``checkpoint`` is the multi-pass integrators' check between passes.

A third thing loses Ctrl-C outside Mitsuba: Python's ``hasattr`` (and C code that calls
``PyObject_HasAttr``, as Dr.Jit's loop recording does on every loop state) swallows any
exception raised while it runs, KeyboardInterrupt included. A SIGINT that arrives then is gone.
Inside ``sticky()`` the handler also notes that Ctrl-C came, and ``raise_pending`` (called by
``checkpoint``, after each render and between optimisation steps) raises it again. (The orchestration layer's
``mitsuba_lab.interrupts`` wraps whole render calls and writes.)

Only the main thread can set handlers: in another thread these do nothing.
"""
from __future__ import annotations

import contextlib
import signal
import threading

_pending = [False]          # inside ``sticky()``: a Ctrl-C arrived (it may have been swallowed)


def in_main_thread() -> bool:
    return threading.current_thread() is threading.main_thread()


def restore() -> None:
    """Install Python's SIGINT handler (``signal.getsignal``) again, in place of whatever
    Mitsuba left: the default raises KeyboardInterrupt, ``SIG_IGN`` ignores it. Costs one
    system call. Does nothing outside the main thread, or if the handler was not set from
    Python."""
    if not in_main_thread():
        return
    handler = signal.getsignal(signal.SIGINT)
    if handler is not None:
        signal.signal(signal.SIGINT, handler)


def _note_and_raise(signum, frame):
    _pending[0] = True
    raise KeyboardInterrupt


@contextlib.contextmanager
def sticky():
    """Ctrl-C that cannot be lost, for a whole command (``mitsuba-lab``, ``mitsuba_lab.sweep``).
    While Python's default handler is in force, it is replaced by one that raises
    KeyboardInterrupt as before and also notes the signal for ``raise_pending``. Afterwards the
    default handler is back and the note cleared. Elsewhere (another thread, Ctrl-C ignored, a
    handler of the caller's own) it changes nothing."""
    if not in_main_thread() or signal.getsignal(signal.SIGINT) is not signal.default_int_handler:
        yield
        return
    _pending[0] = False
    signal.signal(signal.SIGINT, _note_and_raise)
    try:
        yield
    finally:
        signal.signal(signal.SIGINT, signal.default_int_handler)
        _pending[0] = False


def raise_pending() -> None:
    """Raise KeyboardInterrupt if a Ctrl-C came inside ``sticky()`` since the last call: one that
    was swallowed on the way (see the module's doc) stops the work here instead of never."""
    if _pending[0]:
        _pending[0] = False
        raise KeyboardInterrupt


def checkpoint(*integrators) -> None:
    """The cheap check between two passes of a multi-pass render (lab_photon, lab_bdpt, lab_vcm).

    It installs Python's handler again (``restore``), and if Mitsuba's handler cancelled one of
    ``integrators`` (``should_stop()``) it delivers the SIGINT again, to Python's handler. A
    Ctrl-C that reached Python has already raised KeyboardInterrupt by this point. This catches
    one that Mitsuba took but did not pass on. Outside the main thread it does nothing."""
    if not in_main_thread():
        return
    restore()
    if any(integrator.should_stop() for integrator in integrators):
        signal.raise_signal(signal.SIGINT)
    raise_pending()
