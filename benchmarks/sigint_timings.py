"""Ctrl-C, measured: how long each command takes from SIGINT to exit, its exit status, and what
it leaves behind. Covers every command that renders (render, reference, sweep, check, invert,
and ``mitsuba_lab.sweep()`` with its render process) and every integrator family (Mitsuba's
path, lab_mis, lab_photon, lab_bdpt, lab_vcm).

Each row starts ``benchmarks/sigint_cli.py`` (the command line, which also reports its renders'
progress on stderr) in a session of its own, so that it is its own process group. It waits for
a moment in that progress (a render begins, a multi-pass integrator passes a pass boundary, a
sweep point is stored), then sends SIGINT to the whole group, as a terminal's Ctrl-C does. The
time is from the signal to the exit of the process, after everything it started has ended.
Renders are 16-32 px. Each multi-pass render would run for several seconds if it were not
stopped.

    .venv/bin/python benchmarks/sigint_timings.py [--only render,sweep,...]

``tests/test_sigint.py`` runs the same commands at the same moments with this file's helpers
and checks what this table shows.
"""
from __future__ import annotations

import argparse
import json
import os
import queue
import signal
import subprocess
import sys
import tempfile
import threading
import time
from dataclasses import dataclass

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
LAUNCHER = os.path.join(ROOT, "benchmarks", "sigint_cli.py")
CORNELL = os.path.join(ROOT, "scenes", "cornell_box.xml")

#: The command's status after Ctrl-C (cli.EXIT_INTERRUPTED).
EXIT_INTERRUPTED = 130

#: One lab_* strategy or Mitsuba integrator per family, with the parameters that make its
#: 16-32 px renders take several passes: lab_photon renders one pass per sample, and a small
#: max_vertices makes lab_bdpt and lab_vcm split their samples into passes.
FAMILIES = {
    "path": {"type": "path"},
    "lab_mis": {"type": "lab_mis"},
    "lab_photon": {"type": "lab_photon", "photons_per_pass": 4000},
    "lab_bdpt": {"type": "lab_bdpt", "max_vertices": 4000},
    # (no pilot: on the Cornell box below its share it renders path tracing alone, one kernel)
    "lab_vcm": {"type": "lab_vcm", "max_vertices": 4000, "pilot": False},
}
MULTI_PASS = ("lab_photon", "lab_bdpt", "lab_vcm")
#: What sigint_cli.py writes when a render begins, and at a multi-pass integrator's pass boundary.
RENDER = "sigint-cli: render"
PASS = "sigint-cli: pass"


@dataclass
class Outcome:
    """What an interrupted command did."""
    returncode: int
    seconds: float | None       # from SIGINT to exit (None: the moment never came, no signal sent)
    stdout: str
    stderr: str

    @property
    def signalled(self) -> bool:
        return self.seconds is not None


def _read(stream, keep: list, lines: queue.Queue) -> threading.Thread:
    """Read ``stream`` line by line into ``keep`` and ``lines`` (then None, at its end)."""
    def run():
        for line in stream:
            keep.append(line)
            lines.put(line)
        lines.put(None)

    thread = threading.Thread(target=run, daemon=True)
    thread.start()
    return thread


def interrupt(args: list[str], moment: tuple[str, ...], group: bool = True, timeout: float = 180.0,
              cwd: str = ROOT) -> Outcome:
    """Run ``sigint_cli.py ARGS`` and wait for ``moment``: lines of its output (stderr, or
    stdout, where Dr.Jit logs) that contain each of its texts, in order, one line each
    (("points to run", "sigint-cli: pass", "sigint-cli: pass"): the second pass boundary after
    the points began). Then send SIGINT, to its process group (``group``: as Ctrl-C does) or to
    it alone, and wait until every process of the group has ended."""
    proc = subprocess.Popen([sys.executable, LAUNCHER, *args], cwd=cwd, stdin=subprocess.DEVNULL,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            start_new_session=True)
    out: list[str] = []
    err: list[str] = []
    lines: queue.Queue = queue.Queue()
    readers = [_read(proc.stdout, out, lines), _read(proc.stderr, err, lines)]
    watchdog = threading.Timer(timeout, lambda: os.killpg(proc.pid, signal.SIGKILL))
    watchdog.start()
    sent = None
    try:
        waiting, streams = list(moment), len(readers)
        while waiting and streams:
            line = lines.get()
            if line is None:
                streams -= 1
            elif waiting[0] in line:
                waiting.pop(0)
        if not waiting:
            sent = time.perf_counter()
            (os.killpg if group else os.kill)(proc.pid, signal.SIGINT)
        proc.wait()
        wait_for_group(proc.pid, timeout)
        ended = time.perf_counter()
        for reader in readers:
            reader.join()
    finally:
        watchdog.cancel()
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGKILL)
            proc.wait()
    return Outcome(proc.returncode, None if sent is None else ended - sent, "".join(out), "".join(err))


def wait_for_group(pgid: int, timeout: float) -> None:
    """Wait until no process of group ``pgid`` is left (a sweep's render process included)."""
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        try:
            os.killpg(pgid, 0)
        except ProcessLookupError:
            return
        except PermissionError:     # (a zombie of another user's group: not ours)
            return
        time.sleep(0.005)
    raise TimeoutError(f"processes of group {pgid} still run {timeout} s after the signal")


def leftovers(folder: str) -> list[str]:
    """Temporary files under ``folder`` (``images.atomic_path``'s ``.NAME.*.tmp.EXT``)."""
    found = []
    for where, _, names in os.walk(folder):
        found += [os.path.relpath(os.path.join(where, n), folder) for n in names if ".tmp" in n]
    return sorted(found)


def stored(folder: str) -> tuple[list[tuple[str, int]], list[str]]:
    """(the (point, seed) of each run row in force, image files no run row names) of a sweep
    folder."""
    path = os.path.join(folder, "results.jsonl")
    rows = [json.loads(line) for line in open(path)] if os.path.exists(path) else []
    runs = [r for r in rows if r.get("kind") == "run"]
    named = {os.path.normpath(r["image"]) for r in runs}
    folder_images = os.path.join(folder, "images")
    images = os.listdir(folder_images) if os.path.isdir(folder_images) else []
    orphans = [n for n in images if os.path.join("images", n) not in named]
    return [(r["point"], r["seed"]) for r in runs], orphans


def toml_value(value) -> str:
    if isinstance(value, str):
        return json.dumps(value)
    if isinstance(value, dict):
        return "{ " + ", ".join(f"{k} = {toml_value(v)}" for k, v in value.items()) + " }"
    return json.dumps(value)


def sweep_config(folder: str, families=tuple(FAMILIES), spp: int = 16) -> str:
    """A sweep of the Cornell box at 16 px with one strategy per family (named as the family),
    two seeds of one spp level each, against a path reference cached under ``folder``;
    written to ``folder``/sweep.toml, whose path is returned."""
    strategies = "\n".join(f"{name} = {toml_value(FAMILIES[name])}" for name in families)
    text = f"""[experiment]
name = "sigint"
spp = [{spp}]
repetitions = 2
progressive = false
max_depth = 4
metrics = []

[reference]
integrator = {{ type = "path" }}
spp = 256
chunks = 4
cache = {toml_value(os.path.join(folder, "cache"))}

[scenes.cornell]
path = {toml_value(CORNELL)}
resolution = 16

[strategies]
{strategies}
"""
    path = os.path.join(folder, "sweep.toml")
    with open(path, "w") as f:
        f.write(text)
    return path


#: ``render``'s film (px) and spp for a multi-pass family (minutes, uninterrupted) and for one
#: whose render is one kernel.
RENDER_RES, MULTI_PASS_SPP, ONE_KERNEL_SPP = 32, 1024, 128


def render_args(family: str, output: str) -> list[str]:
    """``render`` of the Cornell box with ``family``'s integrator (``--kernels``: Dr.Jit's
    kernel launches on stderr, for ``render_moment``)."""
    spec = dict(FAMILIES[family])
    spp = MULTI_PASS_SPP if family in MULTI_PASS else ONE_KERNEL_SPP
    args = ["--kernels", "render", CORNELL, "--integrator", spec.pop("type"), "-D", f"res={RENDER_RES}",
            "--spp", str(spp), "-o", output]
    for key, value in spec.items():
        args += ["--param", f"{key}={value}"]
    return args


def render_moment(family: str) -> tuple[str, tuple[str, ...]]:
    """(moment, stderr lines to wait for) of ``render_args``: the second pass boundary of a
    multi-pass render, the launch of the render's kernel otherwise."""
    if family in MULTI_PASS:
        return "mid-pass (pass 2)", (PASS, PASS)
    return "in its kernel", (f"(n={RENDER_RES * RENDER_RES * ONE_KERNEL_SPP},",)


def invert_config(folder: str, iterations: int = 200) -> str:
    """An inverse-rendering config at 16 px (the red wall's albedo), optimisation only."""
    text = f"""[experiment]
name = "sigint_invert"

[scene]
path = {toml_value(CORNELL)}
resolution = 16

[render]
max_depth = 3
spp = 4
target_spp = 64

[optimise]
iterations = {iterations}
learning_rate = 0.05

[parameters."red.reflectance.value"]
init = 0.5
min = 0.0
max = 1.0
"""
    path = os.path.join(folder, "invert.toml")
    with open(path, "w") as f:
        f.write(text)
    return path


# -- The table -------------------------------------------------------------------------------


def sweep_moments() -> list[tuple[str, str, tuple[str, ...]]]:
    """(family, moment, stderr lines to wait for) of each interrupted run of one sweep folder,
    resumed each time: points run in the order of ``FAMILIES``, each run first redoing the
    point the run before it interrupted."""
    moments = [("-", "in the reference (chunk 2)", ("reference for", RENDER, RENDER)),
               ("path", "in the first point", ("points to run", RENDER, RENDER)),
               ("lab_mis", "between points (path's stored)", ("/path/",))]
    families = tuple(FAMILIES)
    for before, family in zip(families[1:], families[2:]):
        moments.append((family, "mid-pass (pass 2)", (f"/{before}/", PASS, PASS)))
    return moments


def _temp(folder: str) -> str:
    return f"{len(leftovers(folder))} temporary"


def _row(command, family, moment, outcome: Outcome, left: str) -> tuple:
    seconds = f"{outcome.seconds:.2f}" if outcome.signalled else "(no signal sent)"
    return command, family, moment, str(outcome.returncode), seconds, left


def render_rows(tmp: str):
    for family in FAMILIES:
        exr = os.path.join(tmp, f"render_{family}.exr")
        moment, wait = render_moment(family)
        outcome = interrupt(render_args(family, exr), wait)
        written = [n for n in os.listdir(tmp) if n.startswith(f"render_{family}")]
        yield _row("render", family, moment, outcome, f"{len(written)} outputs, {_temp(tmp)}")


def reference_rows(tmp: str):
    for family in ("path", "lab_bdpt"):
        cache = os.path.join(tmp, f"cache_{family}")
        spec = dict(FAMILIES[family])
        args = ["reference", CORNELL, "--integrator", spec.pop("type"), "--res", "32", "--spp", "4096",
                "--chunks", "8", "--cache", cache] + [f"--param={k}={v}" for k, v in spec.items()]
        outcome = interrupt(args, (RENDER, RENDER))
        files = os.listdir(cache) if os.path.isdir(cache) else []
        yield _row("reference", family, "in chunk 2 of 8", outcome, f"{len(files)} cache files, {_temp(tmp)}")


def sweep_rows(tmp: str):
    folder = os.path.join(tmp, "sweep")
    os.makedirs(folder)
    out = os.path.join(folder, "out")
    args = ["sweep", sweep_config(folder), "-o", out]
    for family, moment, wait in sweep_moments():
        before = len(stored(out)[0])
        outcome = interrupt(args, wait)
        runs, orphans = stored(out)
        yield _row("sweep", family, moment, outcome,
                   f"{len(runs) - before:+d} runs, {len(orphans)} orphan images, {_temp(out)}")
    done = subprocess.run([sys.executable, LAUNCHER, *args], cwd=ROOT, capture_output=True, text=True)
    runs, orphans = stored(out)
    yield ("sweep", "-", "resumed to the end", str(done.returncode), "-",
           f"{len(runs)} runs ({len(set(runs))} distinct), {len(orphans)} orphan images")


def api_rows(tmp: str):
    """``mitsuba_lab.sweep()``: its points in its render process (the default)."""
    folder = os.path.join(tmp, "api")
    os.makedirs(folder)
    out = os.path.join(folder, "out")
    config = sweep_config(folder, ("lab_mis", "lab_bdpt"), spp=256)
    for family, moment, wait, group in (("lab_mis", "in the first point, Ctrl-C", ("points to run",), True),
                                        ("lab_bdpt", "in a point, SIGINT to the caller", ("/lab_mis/",), False)):
        before = len(stored(out)[0])
        outcome = interrupt(["api-sweep", config, out], wait, group=group)
        runs, orphans = stored(out)
        raised = "KeyboardInterrupt" if "sigint-cli: KeyboardInterrupt" in outcome.stderr else "?"
        yield _row("sweep()", family, moment, outcome,
                   f"raised {raised}, {len(runs) - before:+d} runs, {len(orphans)} orphan images, {_temp(out)}")


def check_args(folder: str) -> list[str]:
    """``check`` of one stiff scene at 16 px, 2 splits (its path reference first, in 2 chunks)."""
    scene = os.path.join(ROOT, "scenes", "stiff", "tiny_bright_light.xml")
    return ["check", scene, "--res", "16", "--spp", "256", "--ref-spp", "256", "--splits", "2",
            "--cache", os.path.join(folder, "cache"), "-o", os.path.join(folder, "check")]


def check_rows(tmp: str):
    for family, moment, wait in (("first strategy", "its first render", (RENDER,) * 3),
                                 ("first multi-pass", "mid-pass (pass 2)", (PASS, PASS))):
        folder = os.path.join(tmp, family)
        os.makedirs(folder)
        outcome = interrupt(check_args(folder), wait)
        written = [n for n in os.listdir(folder) if n.startswith("check.")]
        yield _row("check", family, moment, outcome, f"{len(written)} outputs, {_temp(folder)}")


def invert_rows(tmp: str):
    out = os.path.join(tmp, "invert")
    outcome = interrupt(["invert", invert_config(tmp), "-o", out], ("| 2/",))
    files = [f for _, _, names in os.walk(out) for f in names]
    yield _row("invert", "prb", "iteration 3", outcome, f"{len(files)} outputs, {_temp(out)}")


SECTIONS = {"render": render_rows, "reference": reference_rows, "sweep": sweep_rows, "api": api_rows,
            "check": check_rows, "invert": invert_rows}


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--only", help=f"comma-separated sections of {', '.join(SECTIONS)} (default: all)")
    args = parser.parse_args(argv)
    chosen = args.only.split(",") if args.only else list(SECTIONS)
    header = ("command", "family", "moment", "exit", "s to exit", "left behind")
    print(" | ".join(header))
    print(" | ".join("---" for _ in header))
    with tempfile.TemporaryDirectory(prefix="sigint_") as tmp:
        for name in chosen:
            section = os.path.join(tmp, name)
            os.makedirs(section)
            for row in SECTIONS[name](section):
                print(" | ".join(row), flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
