"""Slots as Ray tasks (`wsp build --executor ray [--address ADDR]`).

Each slot is one Ray task (one CPU): a worker process keeps one builder per build config (simulators are
created once per process, as in the local pool), decides the slot into a private temporary staging folder,
and returns that folder packed as bytes. The driver unpacks it into the release's own staging folder
atomically, so staged slots travel back through Ray's object store and no shared file system is needed;
resume works as for a local build (the driver's staging folder is the record). A task whose worker or node
dies is retried by Ray (`max_retries`), so a lost node costs only the slots it was running. A slot's decision
depends only on (build config, slot), so the release is byte-identical to a local build of the same config.

Without an address a local Ray instance with `workers` CPUs is started (and stopped at the end); with one
(`auto`, or `host:port`), the cluster's CPUs decide how many slots run at once. Every node needs this project
installed (the same version) with its build extra. Ray's own output goes to its session log folder
(`/tmp/ray/session_latest/logs`), never to the terminal.
"""

from __future__ import annotations

import io
import json
import os
import shutil
import tarfile
import tempfile
from collections.abc import Iterator
from pathlib import Path

from wsp_data.builders import BuildConfig, builder_class
from wsp_data.staging import SlotRecord, Staging

MAX_RETRIES = 3  # per task, on worker or node failure
IN_FLIGHT_PER_CPU = 2  # tasks submitted ahead per cluster CPU (bounded driver memory, no idle CPU)

_builders: dict[str, object] = {}


def _decide(config_json: dict, slot: int) -> bytes:
    """In a Ray worker: decide `slot` and return its staged folder as an uncompressed tar (npz inside is compressed)."""
    from wsp_data.build import decide_slot

    key = json.dumps(config_json, sort_keys=True)
    if key not in _builders:
        cfg = BuildConfig.from_json(config_json)
        _builders[key] = builder_class(cfg.suite)(cfg)
    with tempfile.TemporaryDirectory(prefix="wsp-ray-slot-") as d:
        staging = Staging(Path(d))
        decide_slot(_builders[key], staging, slot)
        buf = io.BytesIO()
        with tarfile.open(fileobj=buf, mode="w") as tar:
            tar.add(staging.slot_dir(slot), arcname=staging.slot_dir(slot).name)
        return buf.getvalue()


def _unpack(staging: Staging, slot: int, data: bytes) -> SlotRecord:
    final = staging.slot_dir(slot)
    tmp = final.with_name(final.name + f".tmp{os.getpid()}ray")
    shutil.rmtree(tmp, ignore_errors=True)
    tmp.mkdir(parents=True)
    with tarfile.open(fileobj=io.BytesIO(data), mode="r") as tar:
        tar.extractall(tmp, filter="data")
    shutil.rmtree(final, ignore_errors=True)
    os.replace(tmp / final.name, final)
    shutil.rmtree(tmp)
    return staging.read_slot(slot)


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
        decide = ray.remote(num_cpus=1, max_retries=MAX_RETRIES)(_decide)
        limit = max(1, int(ray.cluster_resources().get("CPU", workers))) * IN_FLIGHT_PER_CPU
        todo = list(slots)
        running: dict = {}
        while todo or running:
            while todo and len(running) < limit:
                slot = todo.pop(0)
                running[decide.remote(config.to_json(), slot)] = slot
            ready, _ = ray.wait(list(running), num_returns=1)
            slot = running.pop(ready[0])
            yield _unpack(staging, slot, ray.get(ready[0]))
    finally:
        if started:
            ray.shutdown()
