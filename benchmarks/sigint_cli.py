"""``python benchmarks/sigint_cli.py ARGS``: ``mitsuba-lab ARGS`` (``cli.main``) that reports
where its renders are, so that a test or a benchmark (``sigint_timings.py``) can send SIGINT at
a chosen moment instead of after a sleep. ``sigint_cli.py api-sweep CONFIG OUTPUT`` runs
``mitsuba_lab.sweep(CONFIG, OUTPUT)`` instead. On KeyboardInterrupt it writes
``sigint-cli: KeyboardInterrupt`` and exits with status 130.

It writes one line to stderr:

* ``sigint-cli: render`` when a render call begins (``render.render``, through
  ``interrupts.rendering``);
* ``sigint-cli: pass`` at each pass boundary of a multi-pass integrator (``checkpoint``).

``--kernels`` as the first argument also turns Dr.Jit's log to Info. Dr.Jit then writes a line
``-> launching HASH (n=SIZE, ...`` just before each kernel runs, so a signal can be sent while
a render's kernel runs (its SIZE is width x height x spp).

Otherwise it is the command line as installed.
"""
import contextlib
import sys

from mitsuba_lab import cli, interrupts
from mitsuba_lab.plugins import interrupts as plugin_interrupts

PREFIX = "sigint-cli:"


def _say(event: str) -> None:
    sys.stderr.write(f"{PREFIX} {event}\n")
    sys.stderr.flush()


def _instrument() -> None:
    checkpoint, rendering = plugin_interrupts.checkpoint, interrupts.rendering

    def reported_checkpoint(*integrators):
        _say("pass")
        checkpoint(*integrators)

    @contextlib.contextmanager
    def reported_rendering():
        _say("render")
        with rendering():
            yield

    plugin_interrupts.checkpoint, interrupts.rendering = reported_checkpoint, reported_rendering


def api_sweep(config: str, output: str) -> int:
    import mitsuba_lab

    try:
        mitsuba_lab.sweep(config, output)
    except KeyboardInterrupt:
        _say("KeyboardInterrupt")
        return 130
    return 0


if __name__ == "__main__":
    _instrument()
    args = sys.argv[1:]
    if args[:1] == ["--kernels"]:
        import drjit as dr

        dr.set_log_level(dr.LogLevel.Info)
        args = args[1:]
    if args[:1] == ["api-sweep"]:
        sys.exit(api_sweep(*args[1:]))
    sys.exit(cli.main(args))
