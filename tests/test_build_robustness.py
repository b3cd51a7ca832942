"""Sharding, crash + resume, determinism, and clear errors for bad arguments — on real builds."""

from __future__ import annotations

import json
import os
import re
import signal
import subprocess
import sys
import time

import pytest

from conftest import TINY, release_files as _files, tiny_build_command as _build_args
from wsp_data.build import BuildError, open_staging, prepare_output
from wsp_data.builders import BuildConfig
from wsp_data.machine import cpu_model
from wsp_data.schema import RELEASE_JSON, STAGING_DIR
from wsp_data.staging import FORMAT_FILE, SLOT_JSON

WSP = [sys.executable, "-m", "wsp_eval.cli"]


def test_sharded_killed_and_resumed_build_is_byte_identical(tmp_path, t1_release):
    out = tmp_path / "worldsimprobe"
    # Shard 0/2 decides slots 0 and 2 and must not assemble (slots 1 and 3 are another shard's).
    done = subprocess.run(_build_args(out, "--shard", "0/2"), capture_output=True, text=True, timeout=600)
    assert done.returncode == 0, done.stderr
    assert "not decided yet" in done.stdout and not (out / "t1_maniskill").exists()
    staging = out / STAGING_DIR / "t1_maniskill"
    assert sorted(p.name for p in staging.glob("slot_*")) == ["slot_000000", "slot_000002"]

    # A full build is killed as soon as slot 1 is staged: at most the slot in flight is lost.
    proc = subprocess.Popen(_build_args(out), stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
                            start_new_session=True)
    deadline = time.time() + 600
    while not (staging / "slot_000001" / "slot.json").exists():
        assert proc.poll() is None and time.time() < deadline, "build ended before it could be killed"
        time.sleep(0.2)
    os.killpg(proc.pid, signal.SIGKILL)
    proc.wait()
    if not (out / "t1_maniskill").exists():  # killed before it finished: the staged slots survive
        assert (staging / "slot_000000").exists() and (staging / "slot_000001").exists()
        resumed = subprocess.run(_build_args(out), capture_output=True, text=True, timeout=600)
        assert resumed.returncode == 0, resumed.stderr
    # Same config and seed → the same instances and the same checksums as the straight build.
    assert _files(out) == _files(t1_release)
    assert not (out / STAGING_DIR).exists()

    again = subprocess.run(_build_args(out), capture_output=True, text=True, timeout=600)
    assert again.returncode == 0 and "up to date" in again.stdout


def test_slots_record_their_cpu_and_a_build_from_two_cpu_types_says_so(tmp_path, t1_release):
    """Every slot records the CPU type that decided it (`built_on` in the build report) and its process's peak
    memory (printed by the build); a config assembled from slots of two CPU types (here: shard 0's slot staged as if
    another machine had decided it) warns."""
    report = json.loads((t1_release / "t1_maniskill" / "build_report.json").read_text())
    assert report["built_on"] == {cpu_model(): list(range(TINY["count"]))}

    out = tmp_path / "worldsimprobe"
    one = ["--count", "2", "--tasks", "PickCube"]  # after TINY's: argparse keeps the last
    first = subprocess.run([*_build_args(out), *one, "--shard", "0/2"], capture_output=True, text=True, timeout=600)
    assert first.returncode == 0, first.stderr
    slot = out / STAGING_DIR / "t1_maniskill" / "slot_000000" / "slot.json"
    record = json.loads(slot.read_text())
    assert record["cpu"] == cpu_model()
    assert record["peak_rss_mb"] > 100  # the deciding process's peak memory: a ManiSkill simulator holds more
    slot.write_text(json.dumps({**record, "cpu": "Other CPU (x86_64)"}))
    second = subprocess.run([*_build_args(out), *one, "--shard", "1/2"], capture_output=True, text=True, timeout=600)
    assert second.returncode == 0, second.stderr
    assert "slots were decided on 2 CPU types" in second.stdout
    assert re.search(r"peak memory of a build worker \d+\.\d GB", second.stdout)
    assert "the config written" not in first.stdout  # shard 0 left the config to the last shard
    written = re.search(r"the config written in (\d+\.\d) s \((\d+)% of this run\)", second.stdout)
    assert written and float(written[1]) > 0 and 0 <= int(written[2]) <= 100
    built_on = json.loads((out / "t1_maniskill" / "build_report.json").read_text())["built_on"]
    assert built_on == {"Other CPU (x86_64)": [0], cpu_model(): [1]}


def _wsp(*args: str, timeout: int = 300) -> subprocess.CompletedProcess:
    return subprocess.run([*WSP, *args], capture_output=True, text=True, timeout=timeout)


def test_unknown_task_is_a_clear_error(tmp_path):
    r = _wsp("build", "--suite", "t1", "--count", "2", "--tasks", "FlyToMoon", "--out", str(tmp_path / "r"))
    assert r.returncode == 2 and "unknown task(s) FlyToMoon" in r.stderr and "Traceback" not in r.stderr
    assert not (tmp_path / "r").exists()


def test_unknown_or_misplaced_primitive_is_a_clear_error(tmp_path):
    """`--primitives` names what the platform scripts (LIBERO: push, pull, tap, drop), on T5 only; nothing is built."""
    r = _wsp("build", "--platform", "libero", "--suite", "t5", "--count", "2", "--primitives", "drag",
             "--out", str(tmp_path / "r"))
    assert r.returncode == 2 and "unknown primitive(s) drag" in r.stderr and "push, pull, tap, drop" in r.stderr
    r = _wsp("build", "--suite", "t4", "--count", "2", "--primitives", "drop", "--out", str(tmp_path / "r"))
    assert r.returncode == 2 and "the t4 suite has none" in r.stderr and "Traceback" not in r.stderr
    assert not (tmp_path / "r").exists()


@pytest.mark.parametrize("count", ["0", "-3", "many"])
def test_bad_count_is_a_clear_error(tmp_path, count):
    r = _wsp("build", "--suite", "t1", "--count", count, "--out", str(tmp_path / "r"))
    assert r.returncode == 2 and "--count" in r.stderr and "Traceback" not in r.stderr


def test_unwritable_output_is_a_clear_error(tmp_path):
    blocker = tmp_path / "a_file"
    blocker.write_text("keep me")
    r = _wsp("build", "--suite", "t1", "--count", "1", "--tasks", "PickCube", "--out", str(blocker / "release"))
    assert r.returncode == 2 and "cannot write here" in r.stderr and str(blocker) in r.stderr
    assert blocker.read_text() == "keep me"


def test_foreign_folder_is_refused_and_left_alone(tmp_path):
    (tmp_path / "notes.txt").write_text("mine")
    r = _wsp("build", "--suite", "t1", "--count", "1", "--tasks", "PickCube", "--out", str(tmp_path))
    assert r.returncode == 2 and "not a WorldSimProbe release" in r.stderr
    assert sorted(p.name for p in tmp_path.iterdir()) == ["notes.txt"]


def test_half_written_release_with_other_config_is_not_overwritten(tmp_path):
    out = tmp_path / "worldsimprobe"
    staged = out / STAGING_DIR / "t1_maniskill"
    staged.mkdir(parents=True)
    cfg = {**TINY, "tasks": list(TINY["tasks"]), "count": 9}
    (staged / "build_config.json").write_text(json.dumps(cfg))
    (staged / "slot_000000").mkdir()
    (staged / "slot_000000" / "slot.json").write_text(json.dumps({"slot": 0, "attempts": [], "row": None, "roles": []}))
    r = _wsp(*_build_args(out)[3:])
    assert r.returncode == 2 and "different configuration" in r.stderr and "--restart" in r.stderr
    assert (staged / "slot_000000" / "slot.json").exists()  # nothing lost


def test_a_staging_left_by_an_earlier_wsp_is_refused_before_any_slot(tmp_path):
    """An earlier wsp staged raw frames, which this one cannot assemble: resuming such a build stops at once with
    the count of decided slots and `--restart`, not after deciding the rest."""
    config = BuildConfig("t1", "maniskill", 2, ("PickCube",))
    out = prepare_output(tmp_path / "worldsimprobe")
    staging = open_staging(out, config, restart=False)
    assert staging.has_current_format()
    (staging.root / FORMAT_FILE).unlink()  # the folder as an earlier wsp left it
    staging.slot_dir(0).mkdir()
    (staging.slot_dir(0) / SLOT_JSON).write_text(json.dumps({"slot": 0, "attempts": [], "row": None, "roles": []}))
    with pytest.raises(BuildError, match=r"earlier wsp.*--restart to discard its 1 decided slot"):
        open_staging(out, config, restart=False)
    assert open_staging(out, config, restart=True).has_current_format()
    assert not staging.is_decided(0)


def test_corrupt_release_json_names_the_file(tmp_path):
    (tmp_path / RELEASE_JSON).write_text("{not json")
    r = _wsp("info", str(tmp_path))
    assert r.returncode == 2 and str(tmp_path / RELEASE_JSON) in r.stderr and "unreadable" in r.stderr
    r = _wsp("build", "--suite", "t1", "--count", "1", "--tasks", "PickCube", "--out", str(tmp_path))
    assert r.returncode == 2 and "unreadable" in r.stderr


def test_info_on_non_release_is_a_clear_error(tmp_path):
    r = _wsp("info", str(tmp_path))
    assert r.returncode == 2 and "not a WorldSimProbe release" in r.stderr


def test_seed_range_draws_scene_seeds_from_another_suites_range():
    """`--seed-range train` (judge-training data): slot k, attempt a gets the training range's seed; the field is
    left out of the config JSON when unset, so configs written before it existed compare equal."""
    from wsp_data.builders.base import BuildConfig
    from wsp_data.schema import SEED_BASE, scene_seed

    plain = BuildConfig("t5", "maniskill", 8, ("PickCube",))
    train = BuildConfig("t5", "maniskill", 8, ("PickCube",), seed_range="train")
    assert plain.scene_suite == "t5" and "seed_range" not in plain.to_json()
    assert train.scene_suite == "train" and train.to_json()["seed_range"] == "train"
    assert BuildConfig.from_json(train.to_json()) == train and BuildConfig.from_json(plain.to_json()) == plain
    assert scene_seed(train.scene_suite, 3, 1) == SEED_BASE["train"] + 301
    with pytest.raises(ValueError, match="unknown seed range 'test'"):
        BuildConfig("t5", "maniskill", 8, ("PickCube",), seed_range="test")


def test_private_seed_range_keys_the_scenes_by_the_build_seed():
    """`--seed-range private`: the build seed chooses the scenes; one build never repeats a scene; every seed lies
    above the named ranges; `slot_attempt` inverts it (T3 finds a slot's group seed that way). A build seed alone
    (any other range) leaves the scenes as they are, so the CLI says so."""
    from wsp_data.builders.base import BuildConfig
    from wsp_data.schema import MAX_ATTEMPTS, PRIVATE_BASE, PRIVATE_PRIME, SEED_BASE, SEED_SPAN

    a, b = (BuildConfig("t3", "maniskill", 8, ("PickCube",), seed=s, seed_range="private") for s in (7131, 7132))
    slots = [(k, t) for k in range(3000) for t in range(8)]  # a paper-size build's slots, 8 attempts each
    seeds_a = [a.scene_seed(k, t) for k, t in slots]
    assert len(set(seeds_a)) == len(slots)  # injective: no scene twice in one build
    assert all(PRIVATE_BASE <= s < PRIVATE_BASE + PRIVATE_PRIME for s in seeds_a)
    assert min(seeds_a) > max(SEED_BASE.values()) + SEED_SPAN and max(seeds_a) + SEED_SPAN // 2 < 2**31
    assert len(set(seeds_a) & {b.scene_seed(k, t) for k, t in slots}) < 3  # another key: other scenes
    assert all(a.slot_attempt(a.scene_seed(k, t)) == (k, t) for k, t in slots[::97])
    plain = BuildConfig("t3", "maniskill", 8, ("PickCube",), seed=7131)
    assert plain.scene_seed(5, 2) == SEED_BASE["t3"] + MAX_ATTEMPTS * 5 + 2 and plain.slot_attempt(3000502) == (5, 2)
    with pytest.raises(ValueError, match="needs a build seed other than 0"):
        BuildConfig("t5", "maniskill", 8, ("PickCube",), seed_range="private")


def test_build_seed_without_private_range_says_the_scenes_stay(tmp_path):
    r = _wsp("build", "--suite", "t1", "--count", "1", "--seed", "5", "--max-attempts", "101", "--out", str(tmp_path / "r"))
    assert r.returncode == 2 and "not the scenes" in r.stderr and "--seed-range private" in r.stderr
    assert "max_attempts must be in [1, 100]" in r.stderr and "Traceback" not in r.stderr
    r = _wsp("build", "--suite", "t1", "--count", "1", "--seed-range", "private", "--out", str(tmp_path / "r"))
    assert r.returncode == 2 and "needs a build seed other than 0" in r.stderr and not (tmp_path / "r").exists()


def test_private_build_holds_scenes_no_public_release_has(tmp_path, t1_release):
    """A real tiny build on the private range: its rows' scene seeds are the keyed ones of their slot and attempt,
    none of the public release's, and release.json documents the range."""
    from wsp_data.builders.base import BuildConfig

    out = tmp_path / "private"
    args = _build_args(out, "--count", "2", "--seed-range", "private", "--seed", "7131")
    done = subprocess.run(args, capture_output=True, text=True, timeout=600)
    assert done.returncode == 0, done.stderr
    config = BuildConfig.from_json(json.loads((out / "t1_maniskill" / "build_report.json").read_text())["build_config"])
    assert config.seed_range == "private" and config.seed == 7131
    import pyarrow.parquet as pq

    rows = pq.read_table(out / "t1_maniskill" / "instances.parquet", columns=["seed", "slot", "attempt"]).to_pylist()
    public = set(pq.read_table(t1_release / "t1_maniskill" / "instances.parquet", columns=["seed"])["seed"].to_pylist())
    assert rows and all(r["seed"] == config.scene_seed(r["slot"], r["attempt"]) for r in rows)
    assert not {r["seed"] for r in rows} & public
    ranges = json.loads((out / RELEASE_JSON).read_text())["seed_ranges"]
    assert ranges["private"][0] <= min(r["seed"] for r in rows) and max(r["seed"] for r in rows) <= ranges["private"][1]
