"""Run a build: decide this shard's slots (resumably, optionally in worker processes), then — once every
slot of the config is decided — assemble the config, its build report and the release-level files.

Layout while building: `<release>/.wsp-staging/<config>/` holds `build_config.json` and one folder per
decided slot (see `staging`). It is removed when the config is assembled.
"""

from __future__ import annotations

import json
import multiprocessing as mp
import os
import shutil
import sys
import tempfile
import time
from collections import Counter, defaultdict
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

from tqdm import tqdm

from wsp_data import pair_survey
from wsp_data.builders import BUILDERS, BuildConfig, Kept, SlotPlan, builder_class
from wsp_data.machine import cpu_model, mixed_cpus_warning, peak_rss_mb
from wsp_data.platforms import kit
from wsp_data.release import ReleaseError, load_release, record_build, write_release
from wsp_data.schema import BUILD_REPORT, INSTANCE_ID, LOG_DIR, RELEASE_JSON, STAGING_DIR
from wsp_data.staging import CONFIG_JSON, RolloutArrays, SlotRecord, Staging
from wsp_data.writer import write_config
from wsp_eval import folder_lock
from wsp_eval.console import library_output_to, terminal
from wsp_eval.release_format import BENCHMARK_VERSION


class BuildError(RuntimeError):
    """A build that cannot start or continue; the message names the path and the problem."""


@dataclass
class BuildResult:
    config: BuildConfig
    release: Path
    decided_now: int
    kept_now: int
    remaining: int  # slots of the config not decided yet (other shards)
    assembled: bool
    seconds: float
    rendered_steps: int
    report: dict | None = None
    up_to_date: bool = False  # the config was already assembled from this very build config
    peak_worker_rss_mb: float = 0.0  # the largest peak resident memory of a process that decided a slot now
    log: Path | None = None  # library, simulator and encoder output of this build
    assembly_seconds: float = 0.0  # of `seconds`: writing the config from its staged slots


# -- output folder checks ------------------------------------------------------------------------------
def prepare_output(out: Path) -> Path:
    """Create / check the release folder: writable, and either empty or a WorldSimProbe release."""
    out = Path(out).expanduser().resolve()
    if out.exists() and not out.is_dir():
        raise BuildError(f"{out}: exists and is not a folder")
    ours = {RELEASE_JSON, STAGING_DIR, LOG_DIR}
    if out.exists() and any(out.iterdir()) and not any((out / name).exists() for name in ours):
        raise BuildError(f"{out}: folder is not empty and is not a WorldSimProbe release; choose an empty or new folder")
    try:
        out.mkdir(parents=True, exist_ok=True)
        with tempfile.NamedTemporaryFile(dir=out, prefix=".wsp-write-test"):
            pass
    except OSError as e:
        raise BuildError(f"{out}: cannot write here ({e.strerror or e})") from e
    if (out / RELEASE_JSON).exists():
        try:
            version = load_release(out).get("version")
        except ReleaseError as e:
            raise BuildError(str(e)) from e
        if version != BENCHMARK_VERSION:
            raise BuildError(f"{out}: a release of format {version!r}; this version of worldsimprobe writes "
                             f"{BENCHMARK_VERSION!r} and cannot add to it: build into a new folder")
    return out


def open_staging(out: Path, config: BuildConfig, restart: bool) -> Staging:
    """The staging folder of `config` under `out`, created, or resumed when the same configuration is staged
    (`restart`: discarded first); a different staged configuration is refused."""
    staging = Staging(out / STAGING_DIR / config.name)
    cfg_path = staging.root / CONFIG_JSON
    if restart:
        shutil.rmtree(staging.root, ignore_errors=True)
    if cfg_path.exists():
        previous = json.loads(cfg_path.read_text())
        if previous != config.to_json():
            raise BuildError(
                f"{staging.root}: an unfinished build of {config.name} with a different configuration is staged "
                f"({json.dumps(previous, sort_keys=True)}). Re-run with those arguments to resume it, or pass "
                f"--restart to discard it.")
        if not staging.has_current_format():
            decided = sum(staging.is_decided(k) for k in range(config.count))
            raise BuildError(f"{staging.root}: an unfinished build of {config.name} staged by an earlier wsp, whose "
                             f"staged slots this one cannot assemble; pass --restart to discard its {decided} decided "
                             "slot(s) and build again.")
    else:
        staging.root.mkdir(parents=True, exist_ok=True)
        staging.mark_format()  # before the config: a folder with a config is one this wsp can resume
        cfg_path.write_text(json.dumps(config.to_json(), indent=1, sort_keys=True))
    staging.clean_partial()
    return staging


# -- slot decisions -------------------------------------------------------------------------------------
def decide(builder, slot: int) -> tuple[SlotRecord, dict[str, bytes]]:
    """Try attempts for one slot until one is kept: the decision and the kept instance's rollouts encoded as they
    are staged (`RolloutArrays.encode`, by role; the pictures encoded here, in the deciding process)."""
    cfg: BuildConfig = builder.config
    plan = builder.plan(slot)
    record = SlotRecord(slot, cpu=cpu_model())
    rollouts: list[RolloutArrays] = []
    for a in range(cfg.max_attempts if plan is not None else 0):  # None: the survey excluded every pair
        seed = cfg.scene_seed(slot, a)
        try:
            out = builder.attempt(plan, seed, cfg.rng(slot, a))
        except Exception as e:  # noqa: BLE001 - a simulator crash drops the proposal and is reported
            print(f"[wsp build] slot {slot} attempt {a} ({plan.task}, seed {seed}): {type(e).__name__}: {e}",
                  file=sys.stderr)
            out = None
        entry = {"attempt": a, "seed": seed, "task": plan.task, "group": plan.group,
                 "outcome": "kept" if isinstance(out, Kept) else ("simulator_error" if out is None else out.reason),
                 "rendered_steps": 0 if out is None else out.rendered_steps,
                 "simulated_steps": 0 if out is None else out.simulated_steps}
        record.attempts.append(entry)
        if isinstance(out, Kept):
            record.row = {**out.row, "suite": cfg.suite, "platform": cfg.platform, "slot": slot, "attempt": a,
                          "instance_id": INSTANCE_ID.format(config=cfg.name, slot=slot)}
            if plan.group is not None:
                record.row["group"] = plan.group
            record.roles = [r.role for r in out.rollouts]
            rollouts = out.rollouts
            break
    encoded = {r.role: r.encode(kit(cfg.platform).info.fps) for r in rollouts}
    record.peak_rss_mb = peak_rss_mb()
    return record, encoded


def decide_slot(builder, staging: Staging, slot: int) -> SlotRecord:
    """`decide` one slot and stage the decision atomically."""
    record, encoded = decide(builder, slot)
    staging.write_encoded(record, encoded)
    return record


_WORKER: dict = {}


def _worker_init(config_json: dict, staging_root: str) -> None:
    cfg = BuildConfig.from_json(config_json)
    _WORKER["builder"] = builder_class(cfg.suite)(cfg)
    _WORKER["staging"] = Staging(Path(staging_root))


def _worker_screen(unit: pair_survey.Unit) -> tuple[pair_survey.Unit, dict]:
    return unit, pair_survey.screen_unit(_WORKER["builder"], unit)


def _worker_decide(task: tuple[int, frozenset[SlotPlan]]) -> SlotRecord:
    slot, excluded = task
    builder = _WORKER["builder"]
    builder.exclude(excluded)
    return decide_slot(builder, _WORKER["staging"], slot)


def by_simulator(builder, slots: list[int]) -> list[int]:
    """`slots` ordered by their plan (task, then group; the builder's exclusions applied), so that a worker's
    consecutive slots mostly share its task simulators (`rigs_per_worker`); a slot's decision does not depend on
    the order."""
    def key(slot: int) -> tuple[str, str, int]:
        plan = builder.plan(slot)
        return ("", "", slot) if plan is None else (plan.task, plan.group or "", slot)
    return sorted(slots, key=key)


def survey(builder, staging: Staging, screen, progress: bool = False) -> frozenset[SlotPlan]:
    """The pairs the pair survey excludes (`wsp_data.pair_survey`), screening what is not staged yet by
    `screen`."""
    return pair_survey.excluded_pairs(pair_survey.run_survey(builder, staging.root, screen, progress))


EXECUTORS = ("local", "ray")  # local: this process, or a process pool with --workers > 1; ray: see ray_executor


def decide_slots(config: BuildConfig, staging: Staging, slots: list[int], workers: int, executor: str = "local",
                 address: str | None = None, progress: bool = False) -> Iterator[SlotRecord]:
    """Run the pair survey (what is not staged yet), then decide `slots`, on `workers` processes (or Ray tasks),
    staging each kept instance; records as they end."""
    if executor == "ray":
        from wsp_data.ray_executor import run_slots

        yield from run_slots(config, staging, slots, workers, address, progress)
        return
    if workers <= 1 or len(slots) <= 1:
        builder = builder_class(config.suite)(config)
        try:
            builder.exclude(survey(builder, staging,
                                   lambda units: ((u, pair_survey.screen_unit(builder, u)) for u in units), progress))
            for slot in by_simulator(builder, slots):
                yield decide_slot(builder, staging, slot)
        finally:
            builder.close()
        return
    ctx = mp.get_context("spawn")
    with ctx.Pool(workers, initializer=_worker_init, initargs=(config.to_json(), str(staging.root))) as pool:
        planner = builder_class(config.suite)(config)
        excluded = survey(planner, staging, lambda units: pool.imap_unordered(_worker_screen, units), progress)
        planner.exclude(excluded)
        yield from pool.imap_unordered(_worker_decide, [(slot, excluded) for slot in by_simulator(planner, slots)])


# -- report ---------------------------------------------------------------------------------------------
def build_report(config: BuildConfig, records: list[SlotRecord], survey_entries: list[dict] | None = None) -> dict:
    """Proposed / kept / dropped per task, per group (kind / primitive) and per reason, acceptance rates, the
    rendering that unrendered validation saved (deterministic: step counts, no timings), and the pair survey's
    outcome where the config has one (`survey`; slots it left without a pair: `unplanned_slots`)."""
    def tally() -> dict:
        return {"proposed": 0, "kept": 0, "dropped": Counter()}

    per_task: dict[str, dict] = defaultdict(tally)
    per_group: dict[str, dict] = defaultdict(tally)
    dropped: Counter = Counter()
    steps = Counter()
    for r in records:
        for a in r.attempts:
            tallies = [per_task[a["task"]]] + ([per_group[a["group"]]] if a.get("group") else [])
            kept = a["outcome"] == "kept"
            for t in tallies:
                t["proposed"] += 1
                t["kept"] += kept
                if not kept:
                    t["dropped"][a["outcome"]] += 1
            if not kept:
                dropped[a["outcome"]] += 1
            steps["rendered"] += a["rendered_steps"]
            steps["simulated"] += a.get("simulated_steps", 0)
            if not kept and a["rendered_steps"] == 0:
                steps["render_avoided"] += a.get("simulated_steps", 0)

    def finish(t: dict) -> dict:
        return {**t, "dropped": dict(sorted(t["dropped"].items())),
                "acceptance_rate": round(t["kept"] / t["proposed"], 4) if t["proposed"] else None}

    proposed = sum(len(r.attempts) for r in records)
    kept = sum(r.kept for r in records)
    survey = {} if not survey_entries else {
        "survey": pair_survey.survey_report(survey_entries),
        "unplanned_slots": [r.slot for r in records if not r.attempts]}
    return {
        **survey,
        "built_on": slots_per_cpu(records),
        "config": config.name, "build_config": config.to_json(), "requested": config.count, "kept": kept,
        "exhausted_slots": [r.slot for r in records if not r.kept], "proposed": proposed,
        "acceptance_rate": round(kept / proposed, 4) if proposed else None, "dropped": dict(sorted(dropped.items())),
        "per_task": {k: finish(v) for k, v in sorted(per_task.items())},
        "per_group": {k: finish(v) for k, v in sorted(per_group.items())},
        "rendered_steps": steps["rendered"], "unrendered_steps": steps["simulated"],
        "rendered_steps_avoided": steps["render_avoided"],
    }


def slots_per_cpu(records: list[SlotRecord]) -> dict[str, list[int]]:
    """CPU type → the slots it decided, in order."""
    cpus: dict[str, list[int]] = defaultdict(list)
    for r in sorted(records, key=lambda r: r.slot):
        cpus[r.cpu or "unknown CPU"].append(r.slot)
    return dict(sorted(cpus.items()))


def format_report(report: dict, max_rows: int = 6) -> str:
    """The build's terminal summary: one line, the drop reasons, and the tasks that dropped proposals (worst
    first, at most `max_rows`); the full per-task and per-group tables are in build_report.json."""
    rate = report["acceptance_rate"]
    lines = [f"{report['config']}: kept {report['kept']} / {report['requested']} requested, "
             f"{report['proposed']} proposals (acceptance {'-' if rate is None else f'{rate:.0%}'}); rendered "
             f"{report['rendered_steps']} steps, validation without rendering avoided {report['rendered_steps_avoided']}"]
    if report["dropped"]:
        lines.append("dropped: " + ", ".join(f"{k}={v}" for k, v in report["dropped"].items()) + "; by task:")
    lossy = sorted(((t["acceptance_rate"], name, t) for name, t in report["per_task"].items() if t["dropped"]),
                   key=lambda x: (x[0], x[1]))
    for rate, name, t in lossy[:max_rows]:
        reasons = ", ".join(f"{k}={v}" for k, v in t["dropped"].items())
        lines.append(f"  {name}: kept {t['kept']} of {t['proposed']} ({rate:.0%}); {reasons}")
    if len(lossy) > max_rows:
        lines.append(f"  … {len(lossy) - max_rows} more task(s) with drops")
    if survey := report.get("survey"):
        excluded, n = survey["excluded"], len(survey["pairs"])
        if survey.get("screens") == "tasks":
            name, units, what = "source survey", "tasks", "valid expert source"
        else:
            checks = ("every check, rendered" if all(p.get("rendered") for p in survey["pairs"].values())
                      else "the checks before rendering")
            name, units, what = "pair survey", "pairs", f"proposal that passes {checks}"
        lines.append(f"{name}: {len(excluded)} of {n} {units} yield no {what}, left out: {', '.join(excluded[:6])}"
                     + (f" … {len(excluded) - 6} more" if len(excluded) > 6 else "")
                     if excluded else f"{name}: each of {n} {units} yields a {what}")
    unplanned = set(report.get("unplanned_slots", []))
    if exhausted := [k for k in report["exhausted_slots"] if k not in unplanned]:
        lines.append(f"{len(exhausted)} slot(s) found no valid instance in "
                     f"{report['build_config']['max_attempts']} attempts: {exhausted[:10]}")
    if unplanned:
        lines.append(f"{len(unplanned)} slot(s) left empty: the survey excluded everything they could draw: "
                     f"{sorted(unplanned)[:10]}")
    if warning := mixed_cpus_warning(report["config"], report.get("built_on", {})):
        lines.append(warning)
    return "\n".join(lines)


# -- assembly -------------------------------------------------------------------------------------------
def assemble(config: BuildConfig, out: Path, staging: Staging, workers: int = 1, progress: bool = False) -> dict:
    """Write the config from its decided slots (read on `workers` threads; a bar of instances written when
    `progress`), its build report and the release-level files; then remove the staging."""
    records = [staging.read_slot(k) for k in range(config.count)]
    kept = sum(r.kept for r in records)
    if not kept:
        raise BuildError(f"{config.name}: no proposal passed validation; see the drop reasons in "
                         f"{staging.root} (nothing was assembled)")
    instances = tqdm(staging.read_kept(records, workers), total=kept, desc=f"write {config.name}", unit="instance",
                     disable=not progress, file=terminal())
    with instances:
        write_config(out / config.name, config.name, config.platform, instances)
    report = build_report(config, records, pair_survey.read_survey(staging.root))
    (out / config.name / BUILD_REPORT).write_text(json.dumps(report, indent=1, sort_keys=True) + "\n")
    record_build(out, config.name, config.to_json())
    write_release(out, BUILDERS)
    shutil.rmtree(staging.root)
    if not any((out / STAGING_DIR).iterdir()):
        (out / STAGING_DIR).rmdir()
    return report


def build(config: BuildConfig, out: Path, *, shard: tuple[int, int] = (0, 1), workers: int = 1,
          restart: bool = False, progress: bool = True, executor: str = "local",
          address: str | None = None) -> BuildResult:
    index, total = shard
    if executor not in EXECUTORS:
        raise BuildError(f"executor {executor!r}: expected one of {', '.join(EXECUTORS)}")
    if address and executor != "ray":
        raise BuildError("--address names a Ray cluster: use it with --executor ray")
    if not (total >= 1 and 0 <= index < total):
        raise BuildError(f"--shard {index}/{total}: expected i/n with 0 <= i < n")
    out = prepare_output(out)
    if (out / RELEASE_JSON).exists() and not (out / STAGING_DIR / config.name).exists() and not restart:
        existing = load_release(out)["configs"].get(config.name)
        if existing and existing["build_config"] == config.to_json() and (out / config.name).exists():
            return BuildResult(config, out, 0, 0, 0, False, 0.0, 0, up_to_date=True)
    shard_tag = "" if total == 1 else f"_shard{index}of{total}"  # concurrent shards: one log and one lock each
    log = out / LOG_DIR / f"build_{config.name}{shard_tag}.log"
    try:
        with folder_lock.exclusive(out / LOG_DIR, f"wsp build {config.name}{shard_tag}",
                                   f"build_{config.name}{shard_tag}.lock"):
            return _build_locked(config, out, index, total, workers, restart, progress, executor, address, log)
    except folder_lock.FolderBusy as e:
        raise BuildError(f"{e} (this config{' shard' if total > 1 else ''} is being built by it)") from None


def _build_locked(config: BuildConfig, out: Path, index: int, total: int, workers: int, restart: bool,
                  progress: bool, executor: str, address: str | None, log: Path) -> BuildResult:
    with library_output_to(log):
        staging = open_staging(out, config, restart)
        t0 = time.perf_counter()
        todo = [k for k in range(config.count) if k % total == index and not staging.is_decided(k)]
        decided = kept = steps = proposed = 0
        peak = 0.0
        cpus: dict[str, list[int]] = {}  # CPU type → the slots it decided in this run
        bar = tqdm(total=len(todo), desc=f"build {config.name}", unit="slot", disable=not progress, file=terminal())
        for record in decide_slots(config, staging, todo, workers, executor, address, progress):
            new_cpu = record.cpu not in cpus
            cpus.setdefault(record.cpu, []).append(record.slot)
            if new_cpu and (warning := mixed_cpus_warning(config.name, cpus)):
                bar.write(warning, file=terminal())
            decided += 1
            peak = max(peak, record.peak_rss_mb)
            kept += record.kept
            proposed += len(record.attempts)
            steps += sum(a["rendered_steps"] for a in record.attempts)
            bar.update(1)
            bar.set_postfix(kept=kept, dropped=decided - kept, accept=f"{kept / max(1, proposed):.0%}")
        bar.close()
        remaining = sum(not staging.is_decided(k) for k in range(config.count))
        report = None
        t_assembly = time.perf_counter()
        if remaining == 0:  # one assembly at a time into a release: each rewrites release.json
            with folder_lock.exclusive(out / LOG_DIR, f"wsp build {config.name} (assembling)", "assemble.lock",
                                       wait=True):
                if staging.root.exists():  # else another shard of this config has just assembled it
                    report = assemble(config, out, staging, workers, progress)
        end = time.perf_counter()
    return BuildResult(config, out, decided, kept, remaining, report is not None, end - t0, steps, report, log=log,
                       peak_worker_rss_mb=peak, assembly_seconds=end - t_assembly if report is not None else 0.0)


def default_workers() -> int:
    return max(1, min(2, os.cpu_count() or 1))
