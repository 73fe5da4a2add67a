"""Where a sweep's points run: in this process (the command's default), in one worker process
of the sweep's own (``mitsuba_lab.sweep``'s default) or on a Dask distributed cluster.

All yield ``worker.PointResult`` objects as points finish; the runner stores
them. A render's time depends on what else its process holds: Dr.Jit traces a
virtual call (a BSDF's, an emitter's, a shape's) for every instance of that
kind alive in the process, so every scene and plugin a notebook has loaded
adds Python tracing time to each render, more to an integrator with more
virtual calls (20 small scenes alive: lab_mis's 1-spp render on a 64x64 scene
4.6 -> 22 ms, lab_vcm's 16.5 -> 77 ms). ``ProcessExecutor`` renders where only
the sweep's own scene is loaded.

On a cluster each worker should run one task at a time (``--nthreads 1``):
Dr.Jit already uses every core of its machine, and two renders sharing cores
would time each other. A worker that dies loses only the tasks it was running;
the scheduler gives them to another worker, and since workers return results
instead of writing them, a retried task cannot leave a duplicate row.
"""
from __future__ import annotations

from ...plugins import interrupts
from ...errors import LabError
from .worker import PointResult, PointTask, execute


class LocalExecutor:
    """Runs tasks one after another in this process."""

    def map(self, tasks: list[PointTask]):
        for task in tasks:
            yield execute(task)


class ProcessExecutor:
    """Runs tasks one after another in one worker process of the sweep's own (``python -m
    mitsuba_lab.experiment.execution.render_process``: it holds nothing of this process, nor imports the
    caller's script), started with the first task and ended with the sweep: its renders are
    timed with only their own scene loaded, whatever this process holds. What it prints
    (Mitsuba's log, a plugin's warnings) is passed on to this process's ``sys.stderr``, so a
    notebook shows it. Plugins registered in this process alone (``mi.register_integrator``)
    do not exist there."""

    def map(self, tasks: list[PointTask]):
        import socket
        import subprocess
        import sys
        import threading
        from multiprocessing.connection import Connection

        if not tasks:                          # (a resumed sweep with nothing left to render)
            return
        ours, theirs = socket.socketpair()
        process = subprocess.Popen([sys.executable, "-m", "mitsuba_lab.experiment.execution.render_process",
                                    str(theirs.fileno())], pass_fds=(theirs.fileno(),), stdin=subprocess.DEVNULL,
                                   stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True, errors="replace")
        theirs.close()
        relay = threading.Thread(target=pass_on, args=(process.stdout,), daemon=True)
        relay.start()
        connection = Connection(ours.detach())
        interrupts.restore()                   # Ctrl-C interrupts recv(): not left restarting by Mitsuba
        try:
            for task in tasks:
                connection.send(task)
                try:
                    kind, payload = connection.recv()
                except (EOFError, ConnectionResetError):
                    raise LabError(f"the sweep's render process ended (exit code {process.wait()}) while "
                                   f"rendering point {task.point.id}") from None
                if kind == "error":
                    raise payload
                yield payload
        except BaseException:                  # Ctrl-C, or the sweep stopped: no render to wait for
            process.kill()
            raise
        finally:
            connection.close()                 # (a worker between tasks reads the end and returns)
            process.wait()
            relay.join()


def pass_on(stream) -> None:
    """Write each line of ``stream`` (the render process's output) to ``sys.stderr`` as it comes."""
    import sys

    for line in stream:
        sys.stderr.write(line)
        sys.stderr.flush()


class DaskExecutor:
    """Runs tasks on a Dask cluster: an address (``tcp://host:8786``) or a ``distributed.Client``."""

    def __init__(self, cluster, retries: int = 3):
        try:
            from distributed import Client
        except ImportError as err:
            raise LabError("running on a cluster needs dask.distributed: pip install "
                           "'mitsuba_lab[distributed]'") from err
        self.client = cluster if isinstance(cluster, Client) else self._connect(Client, cluster)
        self.retries = retries

    @staticmethod
    def _connect(client_class, address: str):
        try:
            return client_class(address, timeout="20s")
        except (OSError, TimeoutError) as err:
            raise LabError(f"cannot reach the Dask scheduler at {address}: {err}") from err

    def map(self, tasks: list[PointTask]):
        from distributed import as_completed

        futures = [self.client.submit(execute, task, pure=False, retries=self.retries,
                                      key=f"mitsuba_lab-{task.point.id}-{i}") for i, task in enumerate(tasks)]
        for future in as_completed(futures):
            result: PointResult = future.result()
            future.release()
            yield result
