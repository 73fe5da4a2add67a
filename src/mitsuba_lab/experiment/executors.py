"""Where a sweep's points run: in this process (default) or on a Dask distributed cluster.

Both yield ``worker.PointResult`` objects as points finish; the runner stores
them. On a cluster each worker should run one task at a time (``--nthreads 1``):
Dr.Jit already uses every core of its machine, and two renders sharing cores
would time each other. A worker that dies loses only the tasks it was running;
the scheduler gives them to another worker, and since workers return results
instead of writing them, a retried task cannot leave a duplicate row.
"""
from __future__ import annotations

from .worker import PointResult, PointTask, execute


class LocalExecutor:
    """Runs tasks one after another in this process."""

    def map(self, tasks: list[PointTask]):
        for task in tasks:
            yield execute(task)


class DaskExecutor:
    """Runs tasks on a Dask cluster: an address (``tcp://host:8786``) or a ``distributed.Client``."""

    def __init__(self, cluster, retries: int = 3):
        try:
            from distributed import Client
        except ImportError as err:
            from ..errors import LabError

            raise LabError("running on a cluster needs dask.distributed: pip install "
                           "'mitsuba_lab[distributed]'") from err
        self.client = cluster if isinstance(cluster, Client) else self._connect(Client, cluster)
        self.retries = retries

    @staticmethod
    def _connect(client_class, address: str):
        try:
            return client_class(address, timeout="20s")
        except (OSError, TimeoutError) as err:
            from ..errors import LabError

            raise LabError(f"cannot reach the Dask scheduler at {address}: {err}") from err

    def map(self, tasks: list[PointTask]):
        from distributed import as_completed

        futures = [self.client.submit(execute, task, pure=False, retries=self.retries,
                                      key=f"mitsuba_lab-{task.point.id}-{i}") for i, task in enumerate(tasks)]
        for future in as_completed(futures):
            result: PointResult = future.result()
            future.release()
            yield result
