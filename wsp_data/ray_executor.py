"""Slots as Ray tasks (`wsp build --executor ray [--address ADDR]`; the task runner: `wsp_eval.ray_tasks`).

Each slot is one Ray task (one CPU): a worker process keeps the builder of the build config it last served
(simulators are created once per process, as in the local pool; a task of another config closes it first),
decides the slot and returns the decision with the kept rollouts encoded as the npz files they are staged as
(videos and label PNGs included); the driver writes them (`Staging.write_encoded`, atomic, as a local build does),
so decided slots travel back through Ray's object store and no shared file system is needed. Encoding in the
worker matters: encoding a slot's pictures costs ≈ 0.5 s per rollout, which a driver doing it for every slot would
turn into the build's bottleneck (measured when staging compressed raw frames: Ray stopped scaling at ≈ 2.5
slots/s on 16 cores while the process pool reached 6), and the encoded files are far smaller than the arrays to
send between nodes (≈ 0.5 MB for a 94-frame ALOHA rollout whose frames and masks hold 36 MB); resume works as for
a local build (the driver's staging folder is the record). A slot's decision depends only on (build config,
slot), so the release is byte-identical to a local build of the same config. Every node needs the build extra.
"""

from __future__ import annotations

import json
from collections.abc import Iterator

from wsp_data.builders import BuildConfig, SlotPlan, builder_class
from wsp_data.staging import SlotRecord, Staging

_builders: dict[str, object] = {}


def _builder(config_json: dict):
    """This process's builder of the config (one config's simulators per worker: a later build frees the
    earlier's)."""
    key = json.dumps(config_json, sort_keys=True)
    if key not in _builders:
        for old in _builders.values():
            old.close()
        _builders.clear()
        cfg = BuildConfig.from_json(config_json)
        _builders[key] = builder_class(cfg.suite)(cfg)
    return _builders[key]


def _screen(task: tuple[dict, tuple]) -> tuple[tuple, dict]:
    """In a Ray worker: screen one pair of the pair survey (`wsp_data.pair_survey`)."""
    from wsp_data.pair_survey import screen_unit

    config_json, unit = task
    return unit, screen_unit(_builder(config_json), unit)


def _decide(task: tuple[dict, frozenset[SlotPlan], int]) -> tuple[SlotRecord, dict[str, bytes]]:
    """In a Ray worker: decide slot `task[2]` with this process's builder for the config `task[0]`, the survey's
    excluded pairs `task[1]` left out; the kept rollouts come back encoded, by role."""
    from wsp_data.build import decide

    config_json, excluded, slot = task
    builder = _builder(config_json)
    builder.exclude(excluded)
    return decide(builder, slot)


def run_slots(config: BuildConfig, staging: Staging, slots: list[int], workers: int,
              address: str | None, progress: bool = False) -> Iterator[SlotRecord]:
    """Run the pair survey, then decide `slots`, as Ray tasks; yield each record once it is staged locally
    (completion order)."""
    from wsp_data.build import by_simulator, survey
    from wsp_eval.ray_tasks import ray_imap

    cfg = config.to_json()
    planner = builder_class(config.suite)(config)
    excluded = survey(planner, staging,
                      lambda units: ray_imap(_screen, [(cfg, unit) for unit in units], workers, address), progress)
    planner.exclude(excluded)
    ordered = by_simulator(planner, slots)
    for record, rollouts in ray_imap(_decide, [(cfg, excluded, slot) for slot in ordered], workers, address):
        staging.write_encoded(record, rollouts)
        yield record
