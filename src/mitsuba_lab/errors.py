"""The error type whose message is shown to the user as one line (exit code 2)."""
from __future__ import annotations

import re


class LabError(Exception):
    """Bad input or an unusable environment: the message names what is wrong."""


_SOURCE_TAG = re.compile(r"\[[\w./-]+\.(?:cpp|h|py):\d+\]\s*")


def one_line(message: str) -> str:
    """Condense a Mitsuba or Python error message to its informative line.

    Mitsuba prefixes messages with "[parser.cpp:451] " and wraps exceptions
    raised inside Python plugins with their whole traceback; the user needs the
    file/line context and the final reason, not the stack.
    """
    text = _SOURCE_TAG.sub("", str(message)).strip()
    if "Traceback (most recent call last)" in text:
        head = text.split("Traceback (most recent call last)")[0].strip().rstrip(":")
        reason = text.strip().splitlines()[-1]
        reason = re.sub(r"^\w+(Error|Exception): ", "", reason)
        text = f"{head}: {reason}" if head else reason
    return " ".join(part.strip() for part in text.splitlines() if part.strip())
