"""Functions run as Ray tasks, for `wsp build` and `wsp score` with `--executor ray [--address ADDR]`.

`ray_imap(fn, items)` runs `fn(item)` for every item as a Ray task of one CPU and yields the results as they
complete (completion order), keeping a bounded number of tasks in flight. A task whose worker or node dies is
retried (`MAX_RETRIES`), so a lost node costs only the tasks it was running. Without an address a new local Ray
instance with `workers` CPUs is started (and stopped at the end) — never one already running on the machine, which
Ray's default would join (and then refuse the CPU count); with one (`auto`, or `host:port`), the
cluster's CPUs decide how many tasks run at once. Every node needs this project installed (the same version).
Ray's own output goes to its session log folder (`/tmp/ray/session_latest/logs`), never to the terminal. Ray
comes with the `cluster` extra; the scoring-only install has none.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable, Iterator
from typing import Any

MAX_RETRIES = 3  # per task, on worker or node failure
IN_FLIGHT_PER_CPU = 2  # tasks submitted ahead per cluster CPU (bounded driver memory, no idle CPU)


def ray_imap(fn: Callable[[Any], Any], items: Iterable, workers: int, address: str | None) -> Iterator[Any]:
    """`fn(item)` for every item as Ray tasks; yields each result as its task completes."""
    import ray

    started = not ray.is_initialized()
    if started:
        common = dict(log_to_driver=False, include_dashboard=False, logging_level="WARNING")
        if address:
            ray.init(address=address, **common)
        else:
            ray.init(address="local", num_cpus=workers, **common)
    try:
        remote = ray.remote(num_cpus=1, max_retries=MAX_RETRIES)(fn)
        limit = max(1, int(ray.cluster_resources().get("CPU", workers))) * IN_FLIGHT_PER_CPU
        todo, running = list(items), []
        while todo or running:
            while todo and len(running) < limit:
                running.append(remote.remote(todo.pop(0)))
            ready, running = ray.wait(running, num_returns=1)
            yield ray.get(ready[0])
    finally:
        if started:
            ray.shutdown()
