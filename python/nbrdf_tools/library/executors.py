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


def lost_row(job, error) -> dict:
    """The row of a conversion whose worker died (its job: source, settings, key)."""
    source, _, key = job
    return {"name": source.name, "kind": source.kind, "source": source.path, "key": key, "status": "failed",
            "error": f"worker: {type(error).__name__}: {error}", "wall_seconds": None}


class _Executor:
    def __init__(self):
        self.events: queue_module.Queue = queue_module.Queue()

    def _submit(self, function, args):
        raise NotImplementedError

    def run(self, jobs, on_event=None, function=task.convert, on_lost=lost_row):
        """Runs ``function(*job)`` for each tuple of ``jobs`` (by default the conversion of a
        ``(source, settings, key)``); yields the results as they finish, ``on_lost(job, error)``
        for a job whose worker died, and calls ``on_event(event)`` with each progress event in
        between (in this thread)."""
        on_event = on_event or (lambda event: None)
        pending = {self._submit(function, job): job for job in jobs}
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
                        row = on_lost(job, error)
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

    def __exit__(self, kind, *_):
        self.close(abort=kind is not None and issubclass(kind, KeyboardInterrupt))
        return False

    def close(self, abort: bool = False):
        """Stops the workers; ``abort`` (Ctrl-C) ends the running tasks instead of waiting."""


class LocalExecutor(_Executor):
    def __init__(self, jobs: int):
        super().__init__()
        context = multiprocessing.get_context("spawn")
        self.events = context.Queue()
        self.pool = ProcessPoolExecutor(max_workers=jobs, mp_context=context, initializer=task.init_local_worker,
                                        initargs=(self.events,))

    def _submit(self, function, args):
        return self.pool.submit(function, *args)

    def close(self, abort: bool = False):
        if abort:
            # concurrent.futures has no way to end running tasks before Python 3.14
            # (terminate_workers); their commands die with them (task._die_with_parent).
            for process in list((getattr(self.pool, "_processes", None) or {}).values()):
                process.terminate()
        self.pool.shutdown(wait=not abort, cancel_futures=True)
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
                                        dashboard_address=":0")
            self.client = Client(self.cluster)
        self.client.register_plugin(ImportPlugin(), name=ImportPlugin.name)
        self.client.subscribe_topic(task.PROGRESS_TOPIC, lambda event: self.events.put(event[1]))

    def workers(self) -> int:
        return len(self.client.scheduler_info()["workers"])

    def _submit(self, function, args):
        # pure=False: every submission runs (no result shared between equal-looking calls).
        return self.client.submit(function, *args, pure=False)

    def close(self, abort: bool = False):
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
