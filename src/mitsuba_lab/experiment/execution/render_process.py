"""The worker process of ``executors.ProcessExecutor``: ``python -m
mitsuba_lab.experiment.execution.render_process FD`` executes each point task it receives on the
connection at file descriptor FD and sends back ("result", PointResult) or ("error", the
exception for the sweep's process to raise), until the sweep's end closes."""
from __future__ import annotations

import signal
import sys
import traceback

from ...errors import LabError, UnknownPlugin, innermost, one_line
from .worker import PointTask, execute


class RenderProcessError(RuntimeError):
    """A point failed in the sweep's render process: the message is that error's one line
    (``errors.one_line``), ``traceback`` its traceback there."""

    def __init__(self, message: str, traceback: str = ""):
        super().__init__(message)
        self.traceback = traceback


def portable(err: BaseException, task: PointTask) -> Exception:
    """What the sweep's process raises for ``err``: a LabError for bad input (a plugin this
    process does not have: how to render it), else a RenderProcessError, with ``err``'s one line:
    Dr.Jit's wrappers and chained causes do not survive pickling, so they are resolved here."""
    line = one_line(err)
    if isinstance(innermost(err), UnknownPlugin):
        return LabError(f"point {task.point.id}: {line.split(';')[0]} in the sweep's render process, which "
                        f"has mitsuba_lab's and Mitsuba's plugins but not those registered only in the calling "
                        f"process: run the sweep with in_process=True")
    if isinstance(innermost(err), LabError):
        return LabError(line)
    return RenderProcessError(line, "".join(traceback.format_exception(err)))


def serve(connection) -> None:
    """Execute tasks from ``connection`` until it closes. Ctrl-C is the sweep's process's to
    handle: it ends this one."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    while True:
        try:
            task = connection.recv()
        except (EOFError, ConnectionResetError):
            return
        try:
            reply = ("result", execute(task))
        except Exception as err:  # noqa: BLE001 - every failure goes back to the sweep's process
            reply = ("error", portable(err, task))
        try:
            connection.send(reply)
        except OSError:                        # the sweep's process is gone
            return


if __name__ == "__main__":
    from multiprocessing.connection import Connection

    # (this module's classes by their importable name, not __main__'s, so the sweep can unpickle them)
    from mitsuba_lab.experiment.execution.render_process import serve as serve_importable

    serve_importable(Connection(int(sys.argv[1])))
