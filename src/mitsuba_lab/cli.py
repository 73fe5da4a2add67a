"""``mitsuba-lab``: the command line. The CLI owns the terminal; library code never prints.

Every user error (bad scene, unknown plugin, bad value, unwritable output)
ends in one line on stderr (one per problem when a config has several) and exit
status 2; ``--debug`` shows the traceback. Ctrl-C ends with "interrupted" and
status 130, a closed output pipe quietly with status 141.

Each command is a module of ``mitsuba_lab.commands`` (``add_arguments(parser)``,
``run(args, out) -> int``), named in ``COMMANDS`` and imported only when its
subparser is built (its verb is on the command line) or it runs: ``mitsuba-lab
--help`` imports none of them, nor Mitsuba, Dr.Jit or numpy.
"""
from __future__ import annotations

import argparse
import importlib
import os
import sys
import traceback

from .commands.args import (  # noqa: F401 (re-exported: cli.parse_assignments, cli.positive_int, ...)
    EXIT_USAGE, OneLineParser, parse_assignments, parse_value, positive_int, project_root, seed_int)

EXIT_INTERRUPTED = 130        # 128 + SIGINT, as shells report Ctrl-C
EXIT_PIPE = 141               # 128 + SIGPIPE, as for any command whose reader closed the pipe

#: verb -> (module under mitsuba_lab, help line), in --help order. Each module has
#: ``add_arguments(parser)`` and ``run(args, out)``.
COMMANDS = {
    "render": ("commands.render", "render one scene with one integrator"),
    "demo": ("commands.demo", "render the Cornell box with every lab integrator"),
    "sweep": ("commands.sweep", "run a strategy sweep and write its report"),
    "reference": ("commands.reference", "build (or find) one cached high-spp reference"),
    "report": ("commands.report", "rebuild a sweep's report from its stored results"),
    "check": ("commands.check", "render the stiff scenes with every applicable lab strategy against path"),
    "invert": ("commands.invert", "prb inverse-rendering demos and gradient variance against time"),
    "theory": ("commands.theory", "reproduce seven worked Monte Carlo problems (P1-P7)"),
    "plugins": ("commands.plugins", "list the lab's plugins, or one plugin's declared parameters"),
}
#: Commands that never render, so never select a Mitsuba variant (``activate``).
NO_VARIANT = frozenset({"theory", "report", "plugins"})


def command_module(verb: str):
    """The module implementing ``verb`` (imported on first use)."""
    return importlib.import_module(f"{__package__}.{COMMANDS[verb][0]}")


class CommandParser(OneLineParser):
    """A subcommand's parser whose arguments are added (its module imported) when it is
    first used: to parse its arguments or to print its help."""

    def __init__(self, *args, verb: str | None = None, **kwargs):
        super().__init__(*args, **kwargs)
        self._pending_verb = verb

    def _configure(self) -> None:
        verb, self._pending_verb = self._pending_verb, None
        if verb is not None:
            command_module(verb).add_arguments(self)

    def parse_known_args(self, args=None, namespace=None):
        self._configure()
        return super().parse_known_args(args, namespace)

    def format_usage(self):
        self._configure()
        return super().format_usage()

    def format_help(self):
        self._configure()
        return super().format_help()


def build_parser() -> argparse.ArgumentParser:
    parser = OneLineParser(
        prog="mitsuba-lab",
        description="A Monte Carlo light-transport laboratory on Mitsuba 3 and Dr.Jit.")
    parser.add_argument("--variant", help="Mitsuba variant (default: $MITSUBA_LAB_VARIANT or "
                                          "llvm_ad_rgb), e.g. cuda_ad_rgb on an NVIDIA GPU")
    parser.add_argument("--debug", action="store_true", help="show tracebacks of errors")
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND",
                                parser_class=CommandParser)
    for verb, (_, help_line) in COMMANDS.items():
        sub.add_parser(verb, help=help_line, verb=verb)
    return parser


def main(argv: list[str] | None = None, out=None) -> int:
    out = out or sys.stdout
    parser = build_parser()
    args = parser.parse_args(argv)
    try:
        from . import activate, interrupts

        command = command_module(args.command)
        if args.command not in NO_VARIANT:
            activate(args.variant)
        with interrupts.sticky():         # a Ctrl-C swallowed on the way still stops the command
            return command.run(args, out)
    except KeyboardInterrupt:
        return interrupted()
    except BrokenPipeError:
        return closed_pipe()
    except Exception as err:  # noqa: BLE001 - every failure becomes one line (see module doc)
        from .errors import is_interrupt, one_line

        if is_interrupt(err):                 # Ctrl-C inside a Dr.Jit loop arrives wrapped
            return interrupted()
        if args.debug:
            traceback.print_exc()
        for line in getattr(err, "problems", None) or [one_line(err)]:
            print(f"mitsuba-lab: error: {line}", file=sys.stderr)
        return EXIT_USAGE


def interrupted() -> int:
    print("mitsuba-lab: interrupted", file=sys.stderr)
    return EXIT_INTERRUPTED


def closed_pipe() -> int:
    """The reader of our output went away (``| head``): stop quietly. Python would report the
    failed flush of stdout at exit, so stdout is pointed at /dev/null first."""
    try:
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())
    except (OSError, ValueError, AttributeError):     # a stdout without a file descriptor
        pass
    return EXIT_PIPE


if __name__ == "__main__":
    sys.exit(main())
