"""Sweeps from Python: ``mitsuba_lab.sweep(config)`` in a notebook or a script.

It runs the pipeline of ``mitsuba-lab sweep`` (validate, plan, references, points, strategy
grid, report; ``experiment.sweep``) and returns the results table that the report writes to
``results.csv``, read back from that file: a pandas DataFrame when pandas is installed, else a
list of dicts. Either way ``table.attrs["report"]`` holds the report's paths.
"""
from __future__ import annotations

import csv
import os
import time

from ..errors import LabError

__all__ = ["sweep", "results_table", "ResultRows"]


class ResultRows(list):
    """The results as a list of dicts (one per render, or per checkpoint of a progressive run),
    with a DataFrame's ``columns`` (those of results.csv, in order) and ``attrs``
    (``attrs["report"]`` = {"csv", "html", "md"} paths)."""

    def __init__(self, rows=(), columns=(), attrs=None):
        super().__init__(rows)
        self.columns = list(columns)
        self.attrs = dict(attrs or {})


def _have_pandas() -> bool:
    import importlib.util

    return importlib.util.find_spec("pandas") is not None


def _cell(text: str):
    """A CSV cell back as the value the store held: None (empty), bool, int, float or str."""
    from ..values import parse_value

    return None if text == "" else parse_value(text)


def results_table(folder: str, as_frame: bool | None = None, paths: dict[str, str] | None = None):
    """The rows of ``folder``/results.csv (a finished or resumed sweep's report must have written
    it): a DataFrame (``as_frame`` True, or None with pandas installed) or ``ResultRows``.
    Empty cells are NaN in a DataFrame and None in the list."""
    csv_path = os.path.join(folder, "results.csv")
    if not os.path.isfile(csv_path):
        raise LabError(f"{folder} holds no results.csv: run the sweep (or `mitsuba-lab report {folder}`) first")
    attrs = {"report": dict(paths or {"csv": csv_path})}
    if as_frame is None:
        as_frame = _have_pandas()
    if as_frame:
        import pandas as pd

        frame = pd.read_csv(csv_path)
        frame.attrs.update(attrs)
        return frame
    with open(csv_path, newline="") as f:
        reader = csv.DictReader(f)
        rows = [{name: _cell(text) for name, text in row.items()} for row in reader]
        columns = list(reader.fieldnames or [])
    return ResultRows(rows, columns, attrs)


def sweep(config, output=None, *, progress: bool = True, cluster: str | None = None,
          as_frame: bool | None = None, in_process: bool = False):
    """Run a strategy sweep, as ``mitsuba-lab sweep CONFIG -o OUTPUT`` does, and return its results.

    Parameters
    ----------
    config : str, os.PathLike or dict
        An experiment TOML file (experiments/README.md), or a dict of the same tables. In a
        dict, relative paths (scene paths, regions files) resolve against the current directory,
        and ``experiment.name`` defaults to "sweep".
    output : str or os.PathLike, optional
        Output folder (default: the config's ``experiment.output``, else out/NAME, relative to
        the current directory). A folder that holds part of this sweep is resumed: only missing
        or changed renders run.
    progress : bool
        Show progress: a tqdm bar in a terminal or a notebook (a widget with ipywidgets), plain
        lines in a log; messages (references, resumed runs, the final summary) on stderr.
    cluster : str, optional
        A Dask scheduler address (overrides the config's ``[executor] cluster``).
    as_frame : bool, optional
        True: a pandas DataFrame; False: a list of dicts (``ResultRows``); None (default):
        a DataFrame when pandas is installed.
    in_process : bool
        False (default): the points render in a worker process of the sweep's own, so that
        their times do not depend on what this process holds (every scene and plugin alive in
        a process slows each of its renders: ``executors``). True: in this process, as
        ``mitsuba-lab sweep`` does (needed for plugins registered only here).

    Returns
    -------
    The rows of the sweep's results.csv, one per render in force or per checkpoint of a
    progressive run (point, scene, strategy, sampler, spp, budget_s, seed, wall_s, kernel_s, compile_s, mse, rel_mse, flip, ciede2000,
    finite, negative, peak_rss_mib, host, image, rays_*, region_*). ``table.attrs["report"]``
    maps "csv", "html" and "md" to the report's files.

    Raises
    ------
    LabError
        For a bad config (missing file, unknown key, bad value, unknown plugin, missing scene, a
        reference integrator that ignores part of a scene) or a plan with nothing to run (every
        strategy left out), with the message ``mitsuba-lab sweep`` prints (several problems: one
        line each); nothing is rendered then.
    """
    from .. import interrupts
    from ..progress import NoProgress, ProgressBar
    from .sweep import done_line, prepare_sweep, run_sweep

    if as_frame and not _have_pandas():
        raise LabError("as_frame=True needs pandas (pip install pandas); as_frame=False gives a list of dicts")
    config, plan = prepare_sweep(config)
    folder = os.fspath(output) if output is not None else config.output
    bar = ProgressBar() if progress else NoProgress()
    start = time.perf_counter()
    with interrupts.sticky():             # a Ctrl-C swallowed on the way still stops the sweep
        paths = run_sweep(config, plan, folder, bar, cluster, in_process=in_process)
    bar.message(done_line(config, time.perf_counter() - start, paths))
    return results_table(folder, as_frame, paths)
