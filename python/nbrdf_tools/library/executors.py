"""Where the materials' tasks run: a local process pool, or a Dask distributed cluster.

Both take the same task (:func:`nbrdf_tools.library.task.convert`) and give back its rows as
they finish, with the workers' progress events (the current material's epoch) in between:

* ``LocalExecutor(jobs)``: a ``concurrent.futures`` pool of ``jobs`` spawned processes; each
  imports the plugin in its initializer and sends its events through a queue.
* ``DaskExecutor(address, jobs)``: a ``distributed.Client`` of the scheduler at ``address``, or
  of a ``LocalCluster`` of ``jobs`` single-threaded worker processes started here and stopped at
  the end. A worker plugin imports ``nbrdf_mitsuba`` on every worker as it joins (and the task
  imports it again, which costs nothing once done); events travel as Dask structured events
  (``Worker.log_event``, ``Client.subscribe_topic``).

A task that dies with its worker (a killed process, a lost machine) comes back as a failed row
saying so; the next run redoes it.
"""

from __future__ import annotations

import multiprocessing
import queue as queue_module
import time
from concurrent.futures import ProcessPoolExecutor

from nbrdf_tools.library import task

try:
    from distributed import WorkerPlugin as _WorkerPlugin
except ImportError:  # the local executor needs no Dask
    _WorkerPlugin = object

EXECUTORS = ("local", "dask")
POLL_SECONDS = 0.2


def _lost(source, settings, key, error) -> dict:
    return {"name": source.name, "kind": source.kind, "source": source.path, "key": key, "status": "failed",
            "error": f"worker: {type(error).__name__}: {error}", "wall_seconds": None}


class _Executor:
    def __init__(self):
        self.events: queue_module.Queue = queue_module.Queue()

    def _submit(self, source, settings, key):
        raise NotImplementedError

    def run(self, jobs, on_event):
        """Runs ``convert(source, settings, key)`` for each ``(source, settings, key)`` of
        ``jobs``; yields the rows as they finish and calls ``on_event(event)`` with each
        progress event in between (in this thread)."""
        pending = {self._submit(*job): job for job in jobs}
        try:
            while pending:
                finished = [f for f in pending if f.done()]
                self._drain(on_event)
                if not finished:
                    time.sleep(POLL_SECONDS)
                    continue
                for future in finished:
                    job = pending.pop(future)
                    try:
                        row = future.result()
                    except Exception as error:  # noqa: BLE001 - the worker died, not the task
                        row = _lost(*job, error)
                    yield row
            self._drain(on_event)
        finally:
            for future in pending:
                future.cancel()

    def _drain(self, on_event):
        while True:
            try:
                event = self.events.get_nowait()
            except queue_module.Empty:
                return
            on_event(event)

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()
        return False

    def close(self):
        pass


class LocalExecutor(_Executor):
    def __init__(self, jobs: int):
        super().__init__()
        context = multiprocessing.get_context("spawn")
        self.events = context.Queue()
        self.pool = ProcessPoolExecutor(max_workers=jobs, mp_context=context, initializer=task.init_local_worker,
                                        initargs=(self.events,))

    def _submit(self, source, settings, key):
        return self.pool.submit(task.convert, source, settings, key)

    def close(self):
        self.pool.shutdown(wait=True, cancel_futures=True)
        self.events.close()


class ImportPlugin(_WorkerPlugin):
    """A Dask worker plugin: registers the nbrdf plugins in every worker as it starts."""

    name = "nbrdf-import-plugin"

    def setup(self, worker):
        task.import_plugin()

    def teardown(self, worker):
        pass


class DaskExecutor(_Executor):
    def __init__(self, address: str | None, jobs: int):
        super().__init__()
        from distributed import Client, LocalCluster

        self.cluster = None
        if address:
            self.client = Client(address)
        else:
            # One thread per worker: each task runs its own multi-threaded trainer.
            self.cluster = LocalCluster(n_workers=jobs, threads_per_worker=1, processes=True,
                                        dashboard_address=None)
            self.client = Client(self.cluster)
        self.client.register_plugin(ImportPlugin(), name=ImportPlugin.name)
        self.client.subscribe_topic(task.PROGRESS_TOPIC, lambda event: self.events.put(event[1]))

    def workers(self) -> int:
        return len(self.client.scheduler_info()["workers"])

    def _submit(self, source, settings, key):
        # pure=False: a task is its side effects' run, never shared with another submission.
        return self.client.submit(task.convert, source, settings, key, pure=False, key=f"convert-{source.name}-{key[:12]}")

    def close(self):
        try:
            self.client.unsubscribe_topic(task.PROGRESS_TOPIC)
        finally:
            self.client.close()
            if self.cluster is not None:
                self.cluster.close()


def make(kind: str, jobs: int, address: str | None = None) -> _Executor:
    if kind == "local":
        if address:
            raise ValueError("--address is for --executor dask")
        return LocalExecutor(jobs)
    if kind == "dask":
        return DaskExecutor(address, jobs)
    raise ValueError(f"unknown executor {kind!r} ({', '.join(EXECUTORS)})")
