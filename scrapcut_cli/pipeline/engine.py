"""The batch engine: many independent tasks on Dask distributed, results as they finish.

``batch`` and ``reproduce`` hand their tasks (one pipeline job, or one simulated scan and its
jobs) to an :class:`Engine`:

- by default a ``LocalCluster`` on this machine: one worker process per core (``workers``), one
  thread each (the nanny sets ``OMP_NUM_THREADS=1`` and friends, which ``_open3d`` passes on to
  open3d's TBB pool, so workers do not fight over the cores);
- ``scheduler="tcp://host:8786"``: a running cluster (``dask scheduler`` and ``dask worker``
  processes, or one made by dask-jobqueue on SLURM). Workers read the recordings and write the
  outputs by the paths they are given, so they must see the same file system (absolute paths);
- ``scheduler="inline"``: every task in this process, one after the other, without Dask — for
  debugging and for tests that need no cluster.

A task function must be importable (module level) and take one picklable argument. The engine
wraps it so that an exception becomes a :class:`TaskLost` result instead of stopping the run; a
worker that dies is Dask's to handle (its tasks go to the other workers, up to
``distributed.scheduler.allowed-failures`` times), after which the task is reported lost too.
Nothing here prints; ``on_done(index, result)`` is called in this process, in completion order.
"""

from __future__ import annotations

import ctypes
import functools
import logging
import os
import sys
import traceback
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from types import TracebackType
from typing import Any, Generic, TypeVar

from scrapcut_cli.errors import PipelineError

T = TypeVar("T")
R = TypeVar("R")

#: ``--scheduler inline``: no Dask, tasks run in this process.
INLINE = "inline"
#: How long to wait for a scheduler address to answer, seconds.
CONNECT_TIMEOUT_S = 10.0


@dataclass(frozen=True)
class TaskLost:
    """A task that returned no result: it raised (``error`` names the exception and where), or
    its worker died more often than Dask allows (``KilledWorker``)."""

    error: str

    def __str__(self) -> str:
        return self.error


@dataclass(frozen=True)
class _Guarded(Generic[T, R]):
    """``fn`` with every exception turned into a :class:`TaskLost` (picklable: ``fn`` is a
    module-level function, pickled by reference)."""

    fn: Callable[[T], R]
    on_worker: bool = False

    def __call__(self, task: T) -> R | TaskLost:
        if self.on_worker:
            worker_malloc()
        try:
            return self.fn(task)
        except Exception as exc:  # a bug in one task must not abort a thousand others
            where = traceback.extract_tb(exc.__traceback__)[-1]
            return TaskLost(
                f"internal error: {type(exc).__name__}: {exc} "
                f"({os.path.basename(where.filename)}:{where.lineno})"
            )


#: glibc's ``mallopt`` parameter numbers, and the values set on workers: where glibc's own
#: dynamic thresholds end up after a process has freed a large block.
_M_TRIM_THRESHOLD, _M_MMAP_THRESHOLD = -1, -3
WORKER_MMAP_THRESHOLD_BYTES = 32 * 1024 * 1024
WORKER_TRIM_THRESHOLD_BYTES = 2 * WORKER_MMAP_THRESHOLD_BYTES


@functools.cache
def worker_malloc() -> bool:
    """Undo, in a Dask worker process, what Dask's nanny does to glibc's allocator; once per
    process. True when it was done (glibc), False elsewhere.

    The nanny starts workers with ``MALLOC_TRIM_THRESHOLD_=65536`` (``distributed.nanny.
    pre-spawn-environ``), and setting any malloc threshold also freezes glibc's mmap threshold
    at 128 KiB: every image or depth map is then mapped afresh and unmapped (or trimmed) after
    use, and the page faults made a simulated scan 1.6x slower in a worker than in a plain
    process (``make demo``: 2.5x the CPU). The thresholds glibc would have reached by itself
    restore the plain process's speed while freed memory beyond 64 MiB still goes back to the
    system. Set here rather than in the cluster's settings so that workers of a running
    cluster (``--scheduler``, ``dask worker``) get it too.
    """
    if not sys.platform.startswith("linux"):
        return False
    try:
        mallopt = ctypes.CDLL(None).mallopt
    except (OSError, AttributeError):  # not glibc
        return False
    mallopt.argtypes = [ctypes.c_int, ctypes.c_int]
    mallopt.restype = ctypes.c_int
    return bool(
        mallopt(_M_MMAP_THRESHOLD, WORKER_MMAP_THRESHOLD_BYTES)
        and mallopt(_M_TRIM_THRESHOLD, WORKER_TRIM_THRESHOLD_BYTES)
    )


def default_workers() -> int:
    """One local worker per core."""
    return max(1, os.cpu_count() or 1)


class Engine:
    """Run tasks on Dask (see the module docstring). Use as a context manager; the cluster is
    started on the first :meth:`run` that has work, so a batch with nothing to do starts none.

    Parameters
    ----------
    scheduler : str, optional
        ``tcp://host:port`` of a running scheduler, :data:`INLINE`, or None for a local cluster.
    workers : int, optional
        Local cluster size (default: one per core); ignored with a scheduler address.
    connect_timeout_s : float
        How long to wait for a scheduler address to answer.
    """

    def __init__(
        self,
        *,
        scheduler: str | None = None,
        workers: int | None = None,
        connect_timeout_s: float = CONNECT_TIMEOUT_S,
    ) -> None:
        if workers is not None and workers < 1:
            raise PipelineError(f"workers must be at least 1, got {workers}")
        if scheduler is not None and scheduler != INLINE and "://" not in scheduler:
            raise PipelineError(
                f"scheduler address {scheduler!r} is not an address like tcp://host:8786 "
                f"(or '{INLINE}')"
            )
        self.scheduler = scheduler
        self.workers = workers if workers is not None else default_workers()
        self.connect_timeout_s = connect_timeout_s
        self._cluster: Any = None
        self._client: Any = None

    def describe(self) -> str:
        """Where the tasks run, for reports (``local cluster, 2 workers``)."""
        if self.scheduler == INLINE:
            return "inline (this process, no Dask)"
        if self.scheduler is not None:
            return f"Dask scheduler {self.scheduler}"
        return f"Dask local cluster, {self.workers} worker(s) × 1 thread"

    def __enter__(self) -> Engine:
        return self

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        self.close()

    def start(self) -> Engine:
        """Start the local cluster (or connect to the scheduler) now rather than on the first
        :meth:`run` with work, e.g. to time the work alone."""
        if self.scheduler != INLINE:
            self._connect()
        return self

    def close(self) -> None:
        """Disconnect, and stop the local cluster if this engine started it."""
        client, cluster = self._client, self._cluster
        self._client = self._cluster = None
        if client is not None:
            client.close()
        if cluster is not None:
            cluster.close()

    def run(
        self,
        fn: Callable[[T], R],
        tasks: Sequence[T],
        *,
        keys: Sequence[str],
        on_done: Callable[[int, R | TaskLost], None],
    ) -> None:
        """Run ``fn(task)`` for every task; ``on_done(index, result)`` as each finishes.

        ``keys`` name the tasks on the cluster (unique; e.g. a content hash), so that the
        scheduler's dashboard and logs say which run is which.
        """
        if len(keys) != len(tasks):
            raise ValueError("one key per task")
        if not tasks:
            return
        if self.scheduler == INLINE:
            guarded = _Guarded(fn)
            for index, task in enumerate(tasks):
                on_done(index, guarded(task))
            return
        from distributed import as_completed

        client = self._connect()
        guarded = _Guarded(fn, on_worker=True)
        futures = [
            client.submit(guarded, task, key=key, pure=False)
            for task, key in zip(tasks, keys, strict=True)
        ]
        index_of = {future.key: i for i, future in enumerate(futures)}
        try:
            for future in as_completed(futures):
                index = index_of[future.key]
                if future.status == "finished":
                    on_done(index, future.result())
                else:
                    exc = future.exception()
                    on_done(index, TaskLost(f"lost on the cluster: {type(exc).__name__}: {exc}"))
                future.release()
        finally:
            for future in futures:
                future.cancel()

    def _connect(self) -> Any:
        if self._client is not None:
            return self._client
        from distributed import Client, LocalCluster

        if self.scheduler is None:
            try:
                self._cluster = LocalCluster(
                    n_workers=self.workers,
                    threads_per_worker=1,
                    processes=True,
                    # A random free port: a second cluster on the machine (another user's
                    # batch) must not collide on the default 8787 or warn about it.
                    dashboard_address=":0",
                    silence_logs=logging.ERROR,
                )
            except (OSError, RuntimeError) as exc:
                raise PipelineError(f"cannot start a local Dask cluster: {exc}") from None
            self._client = Client(self._cluster)
            return self._client
        try:
            self._client = Client(self.scheduler, timeout=self.connect_timeout_s)
        except (OSError, TimeoutError) as exc:
            raise PipelineError(
                f"cannot reach the Dask scheduler at {self.scheduler} ({type(exc).__name__}: {exc})"
            ) from None
        return self._client
