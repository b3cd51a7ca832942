"""The pair survey (`wsp_data.pair_survey`): before any slot, every (task, primitive) pair of a T5 config is screened
unrendered on scenes of its own; a pair none of whose proposals passes is left out of the plan, with its reasons in
the build report, instead of costing every slot drawn to it `max_attempts` attempts."""

from __future__ import annotations

import json

from wsp_data.build import build_report, decide, format_report
from wsp_data.builders import BuildConfig, SlotPlan
from wsp_data.builders.t5 import T5Builder
from wsp_data.pair_survey import SURVEY_SLOT, excluded_pairs, survey_report, survey_units


def test_the_shared_t5_release_reports_its_survey(suites_release):
    """The tiny ManiSkill T5 config (8 slots, PickCube, one per primitive): every pair is screened on the survey's
    own scenes, each until its first pass, none excluded, every slot planned."""
    report = json.loads((suites_release / "t5_maniskill" / "build_report.json").read_text())
    cfg = BuildConfig.from_json(report["build_config"])
    survey = report["survey"]
    assert sorted(survey["pairs"]) == sorted(f"PickCube · {p}" for p in T5Builder(cfg).primitives)
    for pair in survey["pairs"].values():  # a slot per pair: screened unrendered
        assert pair["passed"] and not pair["rendered"] and pair["screened"] == 1 + sum(pair["dropped"].values())
    assert survey["excluded"] == [] and report["unplanned_slots"] == [] and survey["simulator_steps"] > 0
    slot_seeds = {cfg.scene_seed(k, a) for k in range(cfg.count) for a in range(cfg.max_attempts)}
    survey_seeds = {cfg.scene_seed(SURVEY_SLOT - i, 0) for i in range(len(survey["pairs"]))}
    assert not slot_seeds & survey_seeds  # the survey's scenes are never a slot's


def test_an_excluded_pair_is_left_out_of_the_plan():
    """Exclusions move a primitive's slots to its other tasks; a primitive with none left gets slots with no plan,
    decided at once with no attempt (no simulator is made), and reported as such."""
    cfg = BuildConfig("t5", "maniskill", 16, ("PickCube", "PushCube"))
    builder = T5Builder(cfg)
    pairs = builder.survey_pairs()
    assert {(p.task, p.group) for p in pairs} == {(t, g) for g in builder.primitives for t in builder.compatible(g)}
    assert survey_units(builder) == [(i, p.task, p.group, False) for i, p in enumerate(pairs)]
    # two slots per pair or more: the survey also renders what passes unrendered (about an instance per pair)
    assert {u[3] for u in survey_units(T5Builder(BuildConfig("t5", "maniskill", 32, cfg.tasks)))} == {True}

    failing = {SlotPlan("PushCube", "push"), SlotPlan("PickCube", "drop")}
    passed = [{"seed": 1, "outcome": "passed", "simulated_steps": 10}]
    dropped = [{"seed": 2, "outcome": "primitive_not_observed", "simulated_steps": 5}] * cfg.max_attempts
    entries = [{"task": p.task, "group": p.group, "attempts": dropped if p in failing else passed} for p in pairs]
    excluded = excluded_pairs(entries)
    assert excluded == failing
    builder.exclude(excluded)
    plans = [builder.plan(k) for k in range(cfg.count)]
    n = len(builder.primitives)
    assert {p.task for k, p in enumerate(plans) if builder.primitives[k % n] == "push"} == {"PickCube"}
    assert {p.task for k, p in enumerate(plans) if builder.primitives[k % n] == "drop"} == {"PushCube"}

    builder.exclude(excluded | {SlotPlan("PushCube", "drop")})
    drop_slot = builder.primitives.index("drop")
    assert builder.plan(drop_slot) is None
    record, rollouts = decide(builder, drop_slot)
    assert record.attempts == [] and not record.kept and rollouts == {}
    report = build_report(cfg, [record], entries)
    assert report["unplanned_slots"] == [drop_slot] and report["exhausted_slots"] == [drop_slot]
    assert survey_report(entries)["excluded"] == ["PushCube · push", "PickCube · drop"]
    assert report["survey"]["pairs"]["PickCube · drop"] == {"screened": 8, "passed": False, "rendered": False,
                                                            "dropped": {"primitive_not_observed": 8}}
    text = format_report(report)
    assert "pair survey: 2 of 16 pairs yield no proposal that passes the checks before rendering" in text
    assert survey_report(entries)["screens"] == "pairs"
    assert "PushCube · push" in text and "left empty" in text
    assert "found no valid instance" not in text  # the empty slot is not reported as 8 failed attempts


COOKIE = "libero_spatial/pick_up_the_black_bowl_next_to_the_cookie_box_and_place_it_on_the_plate"
SOUP = "libero_object/pick_up_the_alphabet_soup_and_place_it_in_the_basket"


def test_libero_survey_leaves_out_a_task_that_cannot_yield(tmp_path):
    """LIBERO's bowl beside the cookie box: every pull on it drives the arm past a joint limit, so the survey drops
    all its screened proposals and leaves the pair out; the can's pull passes at once. Real simulators, unrendered;
    the same survey run again reads its staged result and screens nothing. One attempt per pair (≈ 20 s of
    unrendered simulation on the bowl; a build's default is 8)."""
    from wsp_data.pair_survey import run_survey, screen_unit

    cfg = BuildConfig("t5", "libero", 2, (COOKIE, SOUP), primitives=("pull",), max_attempts=1)
    builder = T5Builder(cfg)
    screened = []

    def screen(units):
        for u in units:
            screened.append(u[1:])
            yield u, screen_unit(builder, u)
    try:
        entries = run_survey(builder, tmp_path, screen)
    finally:
        builder.close()
    cookie, soup = entries
    assert screened == [(COOKIE, "pull", False), (SOUP, "pull", False)]  # a slot per pair: unrendered
    assert (cookie["task"], soup["task"]) == (COOKIE, SOUP)
    assert len(cookie["attempts"]) == cfg.max_attempts
    assert {a["outcome"] for a in cookie["attempts"]} == {"joint_limit"}
    assert soup["attempts"][-1]["outcome"] == "passed"
    assert [a["seed"] for a in soup["attempts"]] == [cfg.scene_seed(SURVEY_SLOT - 1, a)
                                                     for a in range(len(soup["attempts"]))]
    assert excluded_pairs(entries) == {SlotPlan(COOKIE, "pull")}
    assert run_survey(T5Builder(cfg), tmp_path, lambda units: (_ for _ in ()).throw(AssertionError(units))) == entries


def test_the_shared_expert_suites_report_their_source_survey(suites_release, t1_release):
    """T1, T2 and T4 screen each task their slots draw (the source survey): on the tiny ManiSkill configs every task
    passes at its first screened scene, nothing is left out and every slot is planned."""
    for release, config in ((t1_release, "t1_maniskill"), (suites_release, "t2_maniskill"),
                            (suites_release, "t4_maniskill")):
        report = json.loads((release / config / "build_report.json").read_text())
        cfg = BuildConfig.from_json(report["build_config"])
        survey = report["survey"]
        assert survey["screens"] == "tasks" and survey["excluded"] == [] and report["unplanned_slots"] == []
        assert sorted(survey["pairs"]) == sorted({report_task for report_task in report["per_task"]}), config
        assert all(p == {"screened": 1, "passed": True, "rendered": False, "dropped": {}}
                   for p in survey["pairs"].values()), config
        assert survey["simulator_steps"] > 0 and len(survey["pairs"]) <= len(set(cfg.tasks))


def test_a_task_left_out_by_the_source_survey_gets_no_slot():
    """A task none of whose sources passes is left out: T1's and the training split's slots go to the config's other
    tasks in turn, T4's to the kind's other tasks; only the tasks some slot draws are screened."""
    from wsp_data.builders.t1 import T1Builder
    from wsp_data.builders.t4 import T4Builder
    from wsp_data.builders.train import TrainBuilder
    from wsp_data.platforms.contract import KINDS

    tasks = ("PickCube", "PushCube", "StackCube")
    assert [p.task for p in T1Builder(BuildConfig("t1", "maniskill", 2, tasks)).survey_pairs()] == list(tasks[:2])
    for builder in (T1Builder(BuildConfig("t1", "maniskill", 6, tasks)),
                    TrainBuilder(BuildConfig("train", "maniskill", 6, tasks))):
        assert survey_units(builder) == [(i, t, None, False) for i, t in enumerate(tasks)]  # never rendered
        builder.exclude(frozenset({SlotPlan("PushCube")}))
        assert [builder.plan(k).task for k in range(6)] == ["PickCube", "StackCube"] * 3
        builder.exclude(frozenset(SlotPlan(t) for t in tasks))
        assert builder.plan(0) is None
    t4 = T4Builder(BuildConfig("t4", "maniskill", 12, tasks))
    before = [t4.plan(k) for k in range(12)]
    assert [p.task for p in t4.survey_pairs()] == list(dict.fromkeys(p.task for p in before))
    assert "PickCube" in {p.task for p in before}
    t4.exclude(frozenset({SlotPlan("PickCube")}))
    for k in range(12):  # each kind's slots go to its other tasks in turn; a kind left with none is unplanned
        kind = KINDS[k % len(KINDS)]
        others = [t for t in t4.kind_tasks[kind] if t != "PickCube"]
        assert t4.plan(k) == (SlotPlan(others[(k // len(KINDS)) % len(others)], kind) if others else None)


def test_libero_source_survey_leaves_out_a_task_whose_expert_breaks_a_joint_limit(tmp_path):
    """LIBERO's bowl beside the cookie box: its expert drives the arm past a joint limit on every scene, so a
    training split's survey leaves the task out and every slot goes to the can, which passes at once; the build
    summary names the task and why. Real simulators, unrendered, one attempt per task (≈ 20 s)."""
    from wsp_data.builders.train import TrainBuilder
    from wsp_data.pair_survey import run_survey, screen_unit

    cfg = BuildConfig("train", "libero", 4, (COOKIE, SOUP), max_attempts=1)
    builder = TrainBuilder(cfg)
    try:
        entries = run_survey(builder, tmp_path, lambda units: ((u, screen_unit(builder, u)) for u in units))
    finally:
        builder.close()
    assert [(e["task"], [a["outcome"] for a in e["attempts"]]) for e in entries] == [
        (COOKIE, ["source_joint_limit"]), (SOUP, ["passed"])]
    builder.exclude(excluded_pairs(entries))
    assert [builder.plan(k).task for k in range(cfg.count)] == [SOUP] * 4
    text = format_report(build_report(cfg, [], entries))
    assert f"source survey: 1 of 2 tasks yield no valid expert source, left out: {COOKIE}" in text
