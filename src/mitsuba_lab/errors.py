"""The error type whose message is shown to the user as one line (exit code 2),
and the helpers that find the informative part of an error.

Dr.Jit (1.5) re-raises an exception thrown inside a symbolic loop, conditional,
call dispatch or custom differentiable operation (``dr.while_loop``,
``dr.if_stmt``, ``dr.switch``, ``dr.dispatch``, ``dr.custom`` and so Mitsuba's
``mi.render``, whose ``_RenderOp`` is a ``dr.custom`` op) as a RuntimeError that
only says "...: encountered an exception (see above)." / "drjit.custom(<...>):
error while performing a custom differentiable operation. (see above).". The
original exception is chained as that RuntimeError's ``__cause__`` (and
``__context__``, with ``__suppress_context__`` set), like ``raise ... from err``:
"see above" refers to Python's chained traceback, and nothing else is printed.
Nested constructs give one wrapper per level. Mitsuba's XML/dict parser instead
flattens an exception raised in a Python plugin's constructor into the message
text, with the whole traceback (handled by ``one_line`` on the text).
"""
from __future__ import annotations

import os
import re
import traceback


class LabError(Exception):
    """Bad input or an unusable environment: the message names what is wrong."""


class UnknownPlugin(LabError):
    """A plugin type that this process has not registered (``scene.make_plugin``)."""


_SOURCE_TAG = re.compile(r"\[[\w./-]+\.(?:cpp|h|py):\d+\]\s*")
#: Dr.Jit's wrapper messages all end in "(see above)." or "(see above)!"
_WRAPPER_TEXT = re.compile(r"\(see above\)[.!]?\s*$")
_INTERRUPT_TEXT = re.compile(r"\bKeyboardInterrupt\b")
#: nanobind's overload-resolution TypeError lists every signature; keep the gist.
_NB_ARGUMENTS = re.compile(r"^(?P<func>.*?\(\)): incompatible function arguments\..*?"
                           r"Invoked with types: (?P<types>.*)$", re.DOTALL)
#: Exceptions that mean a bug (in a plugin or the lab), whose bare message is
#: cryptic: shown with their type and where they were raised.
_BUG_TYPES = (TypeError, AttributeError, NameError, LookupError, AssertionError, ArithmeticError,
              NotImplementedError)


def _chained(err: BaseException) -> BaseException | None:
    """The exception ``err`` was raised from (``__cause__``), else during (``__context__``)."""
    if err.__cause__ is not None:
        return err.__cause__
    return err.__context__


def is_wrapper(err: BaseException) -> bool:
    """True for an exception that only points at a chained one: Dr.Jit's
    "... (see above)." RuntimeErrors, and message-less RuntimeErrors raised from
    another exception."""
    text = str(err).strip()
    if _WRAPPER_TEXT.search(text):
        return True
    return not text and type(err) in (RuntimeError, Exception) and _chained(err) is not None


def innermost(err: BaseException) -> BaseException:
    """The exception that names the cause of ``err``.

    Follows ``__cause__`` (else ``__context__``) past Dr.Jit/Mitsuba wrapper
    exceptions (see ``is_wrapper``) and stops at the first one that is not a
    wrapper; the lab's own errors (``LabError`` raised ``from`` another one) are
    kept, since their message already names the cause. Returns the last wrapper
    when the chain holds nothing better, and ``err`` itself when it is no wrapper.
    """
    seen = set()
    current = err
    while is_wrapper(current) and id(current) not in seen:
        seen.add(id(current))
        inner = _chained(current)
        if inner is None:
            break
        current = inner
    return current


def _chain(err: BaseException):
    """``err`` and every exception chained to it (causes and contexts), once each."""
    stack, seen = [err], set()
    while stack:
        current = stack.pop()
        if current is None or id(current) in seen:
            continue
        seen.add(id(current))
        yield current
        stack.extend((current.__context__, current.__cause__))


def is_interrupt(err: BaseException | str) -> bool:
    """True when ``err`` is, wraps or was raised during a KeyboardInterrupt (Ctrl-C),
    or when its message shows one (e.g. a traceback flattened by Mitsuba's parser)."""
    if not isinstance(err, BaseException):
        return bool(_INTERRUPT_TEXT.search(str(err)))
    return any(isinstance(e, KeyboardInterrupt) or _INTERRUPT_TEXT.search(str(e)) for e in _chain(err))


def _condense(message: str) -> str:
    text = _SOURCE_TAG.sub("", str(message)).strip()
    if "Traceback (most recent call last)" in text:
        head = text.split("Traceback (most recent call last)")[0].strip().rstrip(":")
        reason = text.strip().splitlines()[-1]
        reason = re.sub(r"^\w+(Error|Exception): ", "", reason)
        text = f"{head}: {reason}" if head else reason
    match = _NB_ARGUMENTS.match(text)
    if match:
        text = f"{match['func']}: incompatible function arguments (invoked with types: {match['types']})"
    return " ".join(part.strip() for part in text.splitlines() if part.strip())


def _raised_at(err: BaseException) -> str:
    """'file.py:LINE in FUNCTION' of the frame that raised ``err`` ('' if unknown)."""
    frames = traceback.extract_tb(err.__traceback__) if err.__traceback__ is not None else []
    if not frames:
        return ""
    frame = frames[-1]
    path = frame.filename
    try:
        relative = os.path.relpath(path)
        path = relative if not relative.startswith("..") else os.path.basename(path)
    except ValueError:
        path = os.path.basename(path)
    return f"{path}:{frame.lineno} in {frame.name}"


def describe(err: BaseException) -> str:
    """One line for one exception (not its chain): its condensed message; the type
    name when the message is empty; type and origin for bug-like exceptions."""
    if isinstance(err, KeyboardInterrupt):
        return "interrupted"
    text = _condense(str(err))
    name = type(err).__name__
    if not text:
        return name
    if isinstance(err, _BUG_TYPES):
        where = _raised_at(err)
        return f"{name}: {text}" + (f" (at {where})" if where else "")
    return text


def one_line(message: BaseException | str) -> str:
    """Condense a Mitsuba, Dr.Jit or Python error to its informative line.

    For an exception, describes ``innermost(message)``: the real cause behind
    Dr.Jit's "(see above)" wrappers. For an exception or a string, Mitsuba's
    "[parser.cpp:451] " source tags are dropped and an embedded Python traceback
    (Mitsuba flattens those of plugin constructors into the message) is reduced
    to the file/line context and the final reason, not the stack.
    """
    if isinstance(message, BaseException):
        return describe(innermost(message))
    return _condense(message)
