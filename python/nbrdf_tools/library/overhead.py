"""The executors' own cost, measured with no-op tasks: what the library pays per material on
top of the conversion itself (docs/scale.md's cost model).

    python -m nbrdf_tools library-overhead [--tasks 200] [--workers 1,2] [--executor local,dask]

For each executor and worker count: the start (pool or local cluster up, and the first no-op
task back: the workers' interpreter start and their import of the plugin included), then
``--tasks`` no-op tasks submitted at once (seconds per task, the scheduler's throughput), then
the close. Prints a markdown table; ``--json`` prints the numbers.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time

from nbrdf_tools.library import executors


def noop(i: int) -> int:
    return i


def measure(kind: str, workers: int, tasks: int) -> dict:
    # By its module's name: `python -m` runs this file as __main__, which workers cannot import.
    from nbrdf_tools.library.overhead import noop

    start = time.perf_counter()
    executor = executors.make(kind, workers)
    try:
        list(executor.run([(0,)], function=noop))
        started = time.perf_counter()
        results = list(executor.run([(i,) for i in range(tasks)], function=noop))
        ran = time.perf_counter()
    finally:
        executor.close()
    closed = time.perf_counter()
    if sorted(results) != list(range(tasks)):
        raise RuntimeError(f"{kind}: the no-op tasks came back wrong")
    return {"executor": kind, "workers": workers, "tasks": tasks, "start_seconds": started - start,
            "ms_per_task": 1000 * (ran - started) / tasks, "close_seconds": closed - ran}


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="python -m nbrdf_tools library-overhead",
                                description="The library executors' overhead with no-op tasks: start, "
                                            "milliseconds per task, close.")
    p.add_argument("--tasks", type=int, default=200, help="no-op tasks per measurement (default: %(default)s)")
    p.add_argument("--workers", default="1,2", help="worker counts (default: %(default)s)")
    p.add_argument("--executor", default=",".join(executors.EXECUTORS),
                   help="executors to measure (default: %(default)s)")
    p.add_argument("--json", action="store_true", help="print the numbers as JSON")
    args = p.parse_args(argv)
    rows = [measure(kind, int(w), args.tasks) for kind in args.executor.split(",") for w in args.workers.split(",")]
    if args.json:
        print(json.dumps({"cpus": os.cpu_count(), "rows": rows}, indent=1))
        return 0
    print(f"{os.cpu_count()} CPUs, {args.tasks} no-op tasks\n")
    print("| executor | workers | start s | ms per task | close s |\n|---|---|---|---|---|")
    for r in rows:
        print(f"| {r['executor']} | {r['workers']} | {r['start_seconds']:.2f} | {r['ms_per_task']:.2f} "
              f"| {r['close_seconds']:.2f} |")
    return 0


if __name__ == "__main__":
    sys.exit(main())
