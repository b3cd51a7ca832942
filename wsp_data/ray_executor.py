"""Slots as Ray tasks (`wsp build --executor ray [--address ADDR]`).

Each slot is one Ray task (one CPU): a worker process keeps one builder per build config (simulators are
created once per process, as in the local pool), decides the slot and returns the decision with the kept
rollouts' arrays; the driver stages them (`Staging.write_slot`, atomic, as a local build does), so decided
slots travel back through Ray's object store and no shared file system is needed; resume works as for a local
build (the driver's staging folder is the record). A task whose worker or node
dies is retried by Ray (`max_retries`), so a lost node costs only the slots it was running. A slot's decision
depends only on (build config, slot), so the release is byte-identical to a local build of the same config.

Without an address a local Ray instance with `workers` CPUs is started (and stopped at the end); with one
(`auto`, or `host:port`), the cluster's CPUs decide how many slots run at once. Every node needs this project
installed (the same version) with its build extra. Ray's own output goes to its session log folder
(`/tmp/ray/session_latest/logs`), never to the terminal.
"""

from __future__ import annotations

import json
from collections.abc import Iterator

from wsp_data.builders import BuildConfig, builder_class
from wsp_data.staging import RolloutArrays, SlotRecord, Staging

MAX_RETRIES = 3  # per task, on worker or node failure
IN_FLIGHT_PER_CPU = 2  # tasks submitted ahead per cluster CPU (bounded driver memory, no idle CPU)

_builders: dict[str, object] = {}


def _decide(config_json: dict, slot: int) -> tuple[SlotRecord, list[RolloutArrays]]:
    """In a Ray worker: decide `slot` with this process's builder for the config."""
    from wsp_data.build import decide

    key = json.dumps(config_json, sort_keys=True)
    if key not in _builders:
        cfg = BuildConfig.from_json(config_json)
        _builders[key] = builder_class(cfg.suite)(cfg)
    return decide(_builders[key], slot)


def run_slots(config: BuildConfig, staging: Staging, slots: list[int], workers: int,
              address: str | None) -> Iterator[SlotRecord]:
    """Decide `slots` as Ray tasks; yield each record once it is staged locally (completion order)."""
    import ray

    started = not ray.is_initialized()
    if started:
        common = dict(log_to_driver=False, include_dashboard=False, logging_level="WARNING")
        if address:
            ray.init(address=address, **common)
        else:
            ray.init(num_cpus=workers, **common)
    try:
        remote_decide = ray.remote(num_cpus=1, max_retries=MAX_RETRIES)(_decide)
        limit = max(1, int(ray.cluster_resources().get("CPU", workers))) * IN_FLIGHT_PER_CPU
        todo, running = list(slots), []
        while todo or running:
            while todo and len(running) < limit:
                running.append(remote_decide.remote(config.to_json(), todo.pop(0)))
            ready, running = ray.wait(running, num_returns=1)
            record, rollouts = ray.get(ready[0])
            staging.write_slot(record, rollouts)
            yield record
    finally:
        if started:
            ray.shutdown()
