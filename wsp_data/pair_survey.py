"""The pair survey: before any slot is decided, every (task, group) pair the config's slots draw from
(`SuiteBuilder.survey_pairs`: T5's task and primitive; the task alone for T1, T2, T4 and the training split,
`wsp_data.builders.source_survey`) is screened on scenes of its own (`SuiteBuilder.screen`: the checks a
proposal passes before it is rendered, and, in a config of at least `RENDERED_FROM` slots per pair, those on its
rendered replay too), until one proposal passes or `max_attempts` are dropped. A pair
none passes is excluded from the plan (`SuiteBuilder.exclude`): its slots go to the group's other pairs, and a slot
whose group keeps no pair is decided with no attempt. The build report lists every screened pair with its drop
reasons and the excluded ones (`survey_report`).

The survey's scenes are those of the config's own seed range at the top of its slot space: pair i's attempt a
draws `config.scene_seed(SURVEY_SLOT - i, a)`, a slot no build below `SURVEY_SLOT - #pairs` instances reaches, so
its outcome depends only on the build config; every shard, worker and resumed run excludes the same pairs. Pairs
are screened in parallel on the build's workers (or Ray tasks), each staged as one file under `<staging>/survey/`,
so a resumed build does not screen them again and a crash loses at most the pairs in flight.
"""

from __future__ import annotations

import json
import os
from collections import Counter
from collections.abc import Callable, Iterable
from pathlib import Path

from tqdm import tqdm

from wsp_data.builders import BuildConfig, SlotPlan, SuiteBuilder
from wsp_data.schema import MAX_ATTEMPTS, SEED_SPAN
from wsp_eval.console import terminal

SURVEY_SLOT = SEED_SPAN // MAX_ATTEMPTS - 1  # the survey's first pair screens on this slot's scenes, the next below
SURVEY_DIR = "survey"

RENDERED_FROM = 2  # slots per pair from which the survey also renders: a pair then has slots enough to pay for it

Unit = tuple[int, str, str, bool]  # (pair index, task, group, rendered)


def survey_units(builder: SuiteBuilder) -> list[Unit]:
    """The builder's survey pairs, each with its index and whether it is screened rendered: when the builder's
    survey renders (`survey_renders`) and the config has at least `RENDERED_FROM` slots per pair, a screened
    proposal must also pass the checks made on its rendered replay (`SuiteBuilder.screen(..., rendered=True)`),
    which costs about one instance per pair that yields."""
    pairs = builder.survey_pairs()
    rendered = builder.survey_renders and builder.config.count >= RENDERED_FROM * len(pairs)
    return [(i, pair.task, pair.group, rendered) for i, pair in enumerate(pairs)]


def screen_unit(builder: SuiteBuilder, unit: Unit) -> dict:
    """Screen one pair: its attempts (scene seed, outcome, simulator steps) up to the first that passes (`outcome`
    "passed") or `max_attempts` dropped."""
    cfg: BuildConfig = builder.config
    i, task, group, rendered = unit
    attempts = []
    for a in range(cfg.max_attempts):
        seed = cfg.scene_seed(SURVEY_SLOT - i, a)
        try:
            why, steps = builder.screen(SlotPlan(task, group), seed, cfg.rng(SURVEY_SLOT - i, a), rendered)
            outcome = "passed" if why is None else why
        except Exception as e:  # noqa: BLE001 - a simulator crash drops the proposal, as in a slot
            outcome, steps = f"simulator_error: {type(e).__name__}", 0
        attempts.append({"seed": seed, "outcome": outcome, "simulated_steps": steps})
        if outcome == "passed":
            break
    return {"task": task, "group": group, "rendered": rendered, "attempts": attempts}


def _unit_path(staging_root: Path, unit: int) -> Path:
    return Path(staging_root) / SURVEY_DIR / f"pair_{unit:04d}.json"


def run_survey(builder: SuiteBuilder, staging_root: Path,
               screen: Callable[[list[Unit]], Iterable[tuple[Unit, dict]]], progress: bool = False) -> list[dict]:
    """Every pair's survey entry, in pair order: staged ones read back, the others screened by `screen` (units →
    (unit, entry), in any order: this process, a worker pool or Ray tasks) and staged as they end (a bar of pairs
    when `progress`)."""
    units = survey_units(builder)
    done: dict[int, dict] = {}
    todo = []
    for unit in units:
        try:
            done[unit[0]] = json.loads(_unit_path(staging_root, unit[0]).read_text())
        except (OSError, ValueError):
            todo.append(unit)
    if todo:
        bar = tqdm(screen(todo), total=len(todo), desc=f"survey {builder.config.name}", unit="pair",
                   disable=not progress, file=terminal(), leave=False)
        for unit, entry in bar:
            path = _unit_path(staging_root, unit[0])
            path.parent.mkdir(parents=True, exist_ok=True)
            tmp = path.with_suffix(f".tmp{os.getpid()}")
            tmp.write_text(json.dumps(entry, indent=1))
            os.replace(tmp, path)
            done[unit[0]] = entry
    return [done[u] for u in sorted(done)]


def excluded_pairs(entries: list[dict]) -> frozenset[SlotPlan]:
    """The pairs none of whose screened proposals passed."""
    return frozenset(SlotPlan(e["task"], e["group"]) for e in entries if not _passed(e))


def _passed(entry: dict) -> bool:
    return any(a["outcome"] == "passed" for a in entry["attempts"])


def survey_report(entries: list[dict]) -> dict:
    """The build report's `survey`: what it screens (`screens`: "pairs", or "tasks" for a source survey), per pair
    (`task · group`, or the task) the proposals screened, whether one passed and the drop reasons; the excluded
    pairs; the simulator steps (rendered or not) the survey cost."""
    pairs = {}
    for e in entries:
        dropped = Counter(a["outcome"] for a in e["attempts"] if a["outcome"] != "passed")
        pairs[e["task"] if e["group"] is None else f"{e['task']} · {e['group']}"] = {"screened": len(e["attempts"]), "passed": _passed(e),
                                               "rendered": bool(e.get("rendered")),
                                               "dropped": dict(sorted(dropped.items()))}
    return {"screens": "tasks" if all(e["group"] is None for e in entries) else "pairs",
            "pairs": pairs, "excluded": [k for k, v in pairs.items() if not v["passed"]],
            "simulator_steps": sum(a["simulated_steps"] for e in entries for a in e["attempts"])}


def read_survey(staging_root: Path) -> list[dict]:
    """The staged survey entries in pair order (none when the config has no survey)."""
    return [json.loads(path.read_text()) for path in sorted((Path(staging_root) / SURVEY_DIR).glob("pair_*.json"))]

