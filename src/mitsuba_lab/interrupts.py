"""Ctrl-C around whole render calls and writes (the plugins' part, Python's SIGINT handler
kept in force against Mitsuba's, is ``mitsuba_lab.plugins.interrupts``).

``rendering`` wraps a render call: it restores the handler afterwards and turns a Ctrl-C that
Dr.Jit wrapped in a RuntimeError back into KeyboardInterrupt. ``deferred`` holds Ctrl-C back
while a write that must be whole finishes. Only the main thread can set handlers: in another
thread these do nothing.
"""
from __future__ import annotations

import contextlib
import signal

from .plugins.interrupts import in_main_thread, raise_pending, restore, sticky  # noqa: F401 - sticky for callers


@contextlib.contextmanager
def rendering():
    """Around one render call (``render.render``). Afterwards, however it ends, Python's
    handler is installed again (``restore``). A Ctrl-C that arrives inside ``mi.render`` comes
    out of Dr.Jit as a RuntimeError wrapping the KeyboardInterrupt; it is raised again as
    KeyboardInterrupt, which is what a notebook or a script expects. One that was swallowed
    inside the render (``raise_pending``) is raised when the render returns."""
    from .errors import is_interrupt

    try:
        yield
    except Exception as err:
        if is_interrupt(err):
            raise KeyboardInterrupt from err
        raise
    finally:
        restore()
    raise_pending()


@contextlib.contextmanager
def deferred():
    """Hold Ctrl-C back while the block runs, then deliver it to Python's handler. Use it for
    a write that must be whole: a sweep point's images and rows, or a reference's three files.
    In the main thread only, and only while Python handles SIGINT (not ``SIG_IGN``)."""
    previous = signal.getsignal(signal.SIGINT) if in_main_thread() else None
    if previous is None or previous == signal.SIG_IGN:
        yield
        return
    received = []
    signal.signal(signal.SIGINT, lambda signum, frame: received.append(signum))
    try:
        yield
    finally:
        signal.signal(signal.SIGINT, previous)
        if received:
            signal.raise_signal(signal.SIGINT)
