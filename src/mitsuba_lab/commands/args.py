"""Argument types and helpers shared by the commands: no Mitsuba, no numpy."""
from __future__ import annotations

import argparse
import os

from ..values import parse_value  # noqa: F401 (KEY=VALUE values; re-exported as cli.parse_value)

EXIT_USAGE = 2


def parse_assignments(items: list[str] | None, option: str) -> dict:
    params = {}
    for item in items or []:
        key, sep, value = item.partition("=")
        if not sep or not key:
            raise ValueError(f"{option} expects KEY=VALUE, got '{item}'")
        params[key.strip()] = parse_value(value.strip())
    return params


def positive_int(text: str) -> int:
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"must be a positive integer, got '{text}'") from None
    if value <= 0:
        raise argparse.ArgumentTypeError(f"must be a positive integer, got {text}")
    return value


def resolution_arg(text: str):
    """--res: "N" sets the film's larger side and keeps the scene's aspect ratio, "WxH" both sides
    (``mitsuba_lab.film``)."""
    from ..film import parse_resolution_text

    try:
        return parse_resolution_text(text)
    except ValueError as err:
        raise argparse.ArgumentTypeError(str(err)) from None


def seed_int(text: str) -> int:
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"must be an integer in [0, 2^32), got '{text}'") from None
    if not 0 <= value < 2 ** 32:
        raise argparse.ArgumentTypeError(f"must be an integer in [0, 2^32), got {text}")
    return value


class OneLineParser(argparse.ArgumentParser):
    """Usage errors as one line (plus where to look), exit status 2."""

    def error(self, message):
        self.exit(EXIT_USAGE, f"{self.prog}: error: {message} (see {self.prog} --help)\n")


def project_root() -> str:
    """The source checkout holding scenes/ (the package is installed editable from it)."""
    here = os.path.dirname(os.path.abspath(__file__))           # src/mitsuba_lab/commands
    return os.path.dirname(os.path.dirname(os.path.dirname(here)))
