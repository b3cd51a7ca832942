"""The learned T5 judge (`net`) on the shared tiny releases: test-range seeds, which no training clip comes from
(the judge trains on `--seed-range train` builds only; its record says which).

Tolerances: the judge's measured agreement on fresh references is in docs/validity.md, Primitive recognition (≥ 95 % per
platform on ≥ 16 references per primitive); on the 12 tiny-release references here (8 ManiSkill, 4 LIBERO) we
allow one miss, so the test fails when the judge is clearly worse than measured, not on a single borderline clip.
The rejections (static, still objects, no robot) are required on every clip, as docs/validity.md reports them; so is
the frozen clip's (the robot performs the primitive, the object held still) on the platforms whose weights
trained on frozen clips (`FROZEN_TRAINED`; measured 3–11 of 55–166 fresh ones still accepted on ManiSkill, none of
55 on ALOHA), where it visibly differs from its reference.
ALOHA's weights are checked on the ALOHA tiny release in tests/test_aloha.py (its oracle's T5 score).
"""

from __future__ import annotations

import hashlib
import json
import sys
from pathlib import Path

import cv2
import numpy as np
import pytest

from wsp_eval.backends.judge import score_verdict
from wsp_eval.backends.errors import BackendUnavailable
from wsp_eval.backends.judge_net import (CHANNELS, OBJECT_WEIGHTS, PERSIST_FRAMES, PLATFORM_WEIGHTS, RELEASED,
                                         SIDE, NetJudge, at_frame_size, judge_input, persists)
from wsp_eval.judge_data import t4_clips, t5_clips

MOVING = ("push", "pull", "drag", "tap", "knock-over", "drop")
FROZEN_TRAINED = ("maniskill", "libero", "aloha")  # every platform's weights are trained with frozen-object negatives
ENSEMBLE = str(Path(__file__).resolve().parents[1] / "scripts" / "ensemble_judge.py")
# tasks whose every T5 pair the pair survey leaves out (every primitive on the bowl beside the cookie box drives the
# arm past a joint limit: 0 of 64 proposals in two builds; tests/test_pair_survey.py checks that the survey finds it)
SURVEY_EXCLUDED = {
    "libero": ("libero_spatial/pick_up_the_black_bowl_next_to_the_cookie_box_and_place_it_on_the_plate",)}


@pytest.fixture(scope="module")
def judge() -> NetJudge:
    return NetJudge()


@pytest.fixture(scope="module")
def clips(suites_release, libero_release) -> list:
    return (t5_clips(suites_release, "t5_maniskill") + t5_clips(libero_release, "t5_libero")
            + t4_clips(suites_release, "t4_maniskill") + t4_clips(libero_release, "t4_libero"))


WHOLE_WEIGHTS = {**{(p, "network"): w for p, w in PLATFORM_WEIGHTS.items()},  # networks that judge every label
                 **{(p, "verifier"): w for (p, label), w in OBJECT_WEIGHTS.items() if label is None}}


@pytest.mark.parametrize("platform, role", sorted(WHOLE_WEIGHTS))
def test_the_packaged_weights_and_their_training_record(platform, role):
    weights = WHOLE_WEIGHTS[platform, role]
    record = json.loads(weights.with_suffix(".json").read_text())
    assert weights.stat().st_size < 20e6
    assert record["sha256"] == hashlib.sha256(weights.read_bytes()).hexdigest()
    assert record["onnx_vs_torch_max_abs_diff"] < 1e-3
    assert all("train" in d["seed_range"] for d in record["data"])  # training-range seeds only
    trained_on = {c.split("_", 1)[1] for d in record["data"] for c in d["configs"]}
    assert platform in trained_on  # each platform's weights saw that platform's clips


@pytest.mark.parametrize("platform, role", sorted(WHOLE_WEIGHTS))
def test_the_weights_trained_on_every_task_and_primitive_t5_builds(platform, role):
    """Every (task, primitive) pair T5 can build on a platform from its default task list was planned in the
    training builds of every network in that platform's weights (each member of an ensemble on its own: their
    configs are in the weights' record; the builder's own slot plan replayed). A judge never shown a pair may fail
    there (on LIBERO a network whose builds missed pairs confused pulls with drops, 33 of 41 fresh references), and
    an ensemble member that never saw them undoes much of what the others learned; so every member must have seen
    every pair, and so must an object verifier that judges every label (LIBERO's). Planned, not kept: a slot may
    still have failed every attempt. The pairs the pair survey leaves out (`SURVEY_EXCLUDED`) are neither buildable
    nor planned, as in a build."""
    from wsp_data.builders.base import BuildConfig, SlotPlan
    from wsp_data.builders.t5 import T5Builder
    from wsp_data.platforms import kit

    platform_kit = kit(platform)
    excluded = frozenset(SlotPlan(t, p) for p in platform_kit.t5_primitives()
                         for t in SURVEY_EXCLUDED.get(platform, ()))
    buildable = {(task, primitive) for primitive, tasks in
                 platform_kit.t5_primitive_tasks(tuple(platform_kit.tasks())).items() for task in tasks
                 if SlotPlan(task, primitive) not in excluded}
    record = json.loads(WHOLE_WEIGHTS[platform, role].with_suffix(".json").read_text())
    for member in [m["record"] for m in record.get("ensemble_of", [])] or [record]:
        planned = set()
        for data in _lineage_data(member):
            config = data["configs"].get(f"t5_{platform}")
            if config:
                builder = T5Builder(BuildConfig("t5", platform, config["count"], tuple(config["tasks"]),
                                                primitives=tuple(config.get("primitives", ()))))
                builder.exclude(excluded)
                planned |= {(p.task, p.group) for p in map(builder.plan, range(config["count"]))}
        assert buildable - planned == set(), member["weights"]


def _lineage_data(record: dict) -> list[dict]:
    """The data a network was trained on, with the data of the network it was fine-tuned from (`--init`), and so on."""
    data = list(record["data"])
    while record.get("init"):
        record = record["init"]["record"]
        data += record["data"]
    return data


def test_fine_tuning_starts_from_the_members_of_an_ensemble_file(monkeypatch):
    """`train_judge.py --init FILE --init-member I` starts from member I of an ensemble written by
    `ensemble_judge.py` (LIBERO's weights: three networks side by side): the three members unpacked into the
    training script's network, batch norms frozen at identity plus the folded bias, average to the file's own logits
    as OpenCV runs it, to float32 summation order (1e-4 on logits up to ≈ 6; measured 1.4e-6). A member the file does
    not hold is refused by name."""
    torch = pytest.importorskip("torch")
    monkeypatch.syspath_prepend(str(Path(ENSEMBLE).parent))  # the scripts import each other, as when they run
    import ensemble_judge
    import train_judge as train

    weights = PLATFORM_WEIGHTS["libero"]
    x = np.random.default_rng(0).random((4, CHANNELS, SIDE, SIDE), dtype=np.float32)
    nets = [train.initialised(train.JudgeNet(), weights, i).eval() for i in range(3)]
    with torch.no_grad():
        logits = [net(torch.from_numpy(x)).numpy() for net in nets]
    file = cv2.dnn.readNetFromONNX(str(weights))
    file.setInput(x)
    assert np.abs(np.mean(logits, axis=0) - file.forward()).max() < 1e-4
    assert np.abs(logits[0] - logits[1]).max() > 0.1  # three different networks, not one copied
    with pytest.raises(SystemExit, match="holds 3 network.*--init-member 3"):
        ensemble_judge.member(weights, 3)


def test_a_training_record_names_its_data_by_content(monkeypatch, libero_release):
    """`train_judge.py`'s record keeps, per training release, a digest of its data files (`data_sha256`) that a
    rebuild of the same instances reproduces: release.json itself names the code commit and checksums the card, the
    Croissant file and the build reports, which carry the build config (a training-range build's seed changes them
    but not its instances), so its own checksum changes with every commit. The digest ignores exactly those and
    follows every data file."""
    pytest.importorskip("torch")
    monkeypatch.syspath_prepend(str(Path(ENSEMBLE).parent))
    import train_judge as train

    files = json.loads((libero_release / "release.json").read_text())["files"]
    digest = train.data_digest(files)
    assert train.data_record(libero_release)["data_sha256"] == digest
    provenance = [f for f in files if f in ("README.md", "croissant.json") or f.endswith("/build_report.json")]
    assert len(provenance) >= 3
    assert train.data_digest({**files, **{f: "0" * 64 for f in provenance}}) == digest
    for f in set(files) - set(provenance):  # every data file counts: the videos, the tables, the metadata
        assert train.data_digest({**files, f: "0" * 64}) != digest, f


def test_weights_are_chosen_by_platform_and_a_platform_without_weights_is_refused(tmp_path):
    judge, frames = NetJudge(), np.zeros((12, 128, 128, 3), np.uint8)
    assert len({judge.weights_for(p) for p in ("maniskill", "libero", "aloha")}) == 3
    assert judge.version.startswith("17 (maniskill ") and ", libero " in judge.version and ", aloha " in judge.version
    assert ", maniskill drop " in judge.version and ", libero object " in judge.version  # the object verifiers' too
    with pytest.raises(BackendUnavailable, match="no weights for platform 'robotwin'.*train_judge.py"):
        judge.judge(frames, (64.0, 64.0), "robotwin")
    custom = NetJudge(PLATFORM_WEIGHTS["aloha"])  # --judge-checkpoint: these weights judge every platform
    assert custom.judge(frames, (64.0, 64.0), "robotwin") == judge.judge(frames, (64.0, 64.0), "aloha")


def test_an_ensemble_file_judges_by_its_members_mean(tmp_path, judge, clips):
    """`scripts/ensemble_judge.py` (how the multi-network weight files are made): one ONNX file whose logits are the mean of
    its members' (here ALOHA's weights and ManiSkill's drop verifier, two single networks, run side by side as one
    network), with a record naming both; float32 sums in another order, so to 1e-5."""
    import subprocess

    members = [PLATFORM_WEIGHTS["aloha"], OBJECT_WEIGHTS[("maniskill", "drop")]]
    out = tmp_path / "ensemble.onnx"
    run = subprocess.run([sys.executable, ENSEMBLE, *map(str, members), "--out", str(out)],
                         capture_output=True, text=True, timeout=120)
    assert run.returncode == 0, run.stderr
    record = json.loads(out.with_suffix(".json").read_text())
    assert [m["weights"] for m in record["ensemble_of"]] == [m.name for m in members]
    assert record["sha256"] == hashlib.sha256(out.read_bytes()).hexdigest()
    ref = next(c for c in clips if c.kind == "reference")
    both = [NetJudge(m).logits(ref.judge_frames(), ref.object_px) for m in members]
    mean = NetJudge(out).logits(ref.judge_frames(), ref.object_px)
    assert not np.allclose(both[0], both[1], atol=1e-2)  # the members differ, so the mean is a real check
    assert np.allclose(mean, (both[0] + both[1]) / 2, atol=1e-5)
    assert subprocess.run([sys.executable, ENSEMBLE, str(members[0]), "--out", str(out)],
                          capture_output=True, text=True, timeout=120).returncode != 0  # one member: refused
    nested = subprocess.run([sys.executable, ENSEMBLE, str(members[0]), str(PLATFORM_WEIGHTS["maniskill"]), "--out",
                             str(tmp_path / "nested.onnx")], capture_output=True, text=True, timeout=120)
    assert nested.returncode != 0 and "not an ensemble" in nested.stderr  # members are single trained networks
    bare = tmp_path / "bare.onnx"  # weights without their training record (an .onnx copied without its .json)
    bare.write_bytes(members[1].read_bytes())
    unrecorded = subprocess.run([sys.executable, ENSEMBLE, str(members[0]), str(bare), "--out",
                                 str(tmp_path / "unrecorded.onnx")], capture_output=True, text=True, timeout=120)
    assert unrecorded.returncode != 0 and "bare.json" in unrecorded.stderr  # named, before anything is written
    assert not (tmp_path / "unrecorded.onnx").exists()


def test_input_and_determinism(judge, clips):
    ref = next(c for c in clips if c.kind == "reference")
    x = judge_input(ref.judge_frames(), ref.object_px)
    assert x.shape == (1, CHANNELS, SIDE, SIDE) and x.dtype == np.float32
    assert (judge.judge(ref.judge_frames(), ref.object_px, ref.platform)
            == judge.judge(ref.judge_frames(), ref.object_px, ref.platform))
    up = np.repeat(np.repeat(ref.judge_frames(), 2, axis=1), 2, axis=2)  # a 256² model output: same input size
    assert judge_input(up, ref.object_px).shape == x.shape
    # the layout the weights were trained on (module doc): the global view's frame 0, then frame i − frame 0 per
    # colour, then the mark, which peaks at the object's frame-0 position (scoring frame 256² → global view 64²)
    full = at_frame_size(ref.judge_frames())
    glob = np.stack([cv2.resize(f, (SIDE, SIDE), interpolation=cv2.INTER_AREA) for f in full])
    glob = glob.astype(np.float32).transpose(0, 3, 1, 2) / 255.0
    np.testing.assert_array_equal(x[0, :3], glob[0])
    np.testing.assert_array_equal(x[0, 3:3 * len(glob)], (glob[1:] - glob[:1]).reshape(-1, SIDE, SIDE))
    peak = np.unravel_index(np.argmax(x[0, -1]), (SIDE, SIDE))[::-1]
    assert np.allclose(peak, np.asarray(ref.object_px) / 4, atol=1)
    assert judge.judge(ref.judge_frames()[:5], ref.object_px, ref.platform).label is None  # unreadable: scores 0


def test_references_score_100_and_negatives_are_rejected(judge, clips):
    by_kind: dict[str, list] = {}
    for c in clips:
        by_kind.setdefault(c.kind, []).append((c, judge.judge(c.judge_frames(), c.object_px, c.platform)))
    refs = by_kind["reference"]
    full = [score_verdict(v, c.label) == 100.0 for c, v in refs]
    assert len(refs) == 12 and sum(full) >= len(refs) - 1, [(c.instance_id, c.label, v) for (c, v), ok in
                                                            zip(refs, full) if not ok]
    assert all(score_verdict(v, c.primitive) == 0.0 for c, v in by_kind["static"])
    for kind in ("approach", "t4"):
        assert by_kind[kind] and not any(v.label in MOVING and v.agent_ok and v.object_ok for _, v in by_kind[kind])
    assert not any(v.agent_ok for _, v in by_kind["no_robot"])
    frozen = [(c, v) for c, v in by_kind["frozen"] if c.object is False and c.platform in FROZEN_TRAINED]
    assert frozen and all(score_verdict(v, c.primitive) == 0.0 for c, v in frozen), \
        [(c.instance_id, c.primitive, v) for c, v in frozen if score_verdict(v, c.primitive)]


def test_a_maniskill_drop_gets_its_object_verdict_from_the_drop_verifier(judge, suites_release):
    """Where the network says `drop` on a ManiSkill clip, `object_ok` is decided by the mean of its object logit and
    the drop verifier's (trained on training-range drops, `--object-of drop`; its record says so), then the
    persistence rule. On the tiny release's drop: the reference scores 100 and its frozen clip (the
    object held still) 0, with both probabilities in the evidence. A ManiSkill clip of another label is the
    network's alone."""
    weights = OBJECT_WEIGHTS[("maniskill", "drop")]
    record = json.loads(weights.with_suffix(".json").read_text())
    assert weights.stat().st_size < 20e6 and record["sha256"] == hashlib.sha256(weights.read_bytes()).hexdigest()
    object_of = record["object_of"]  # "drop" in the shipped record; a list since `--object-of` takes several
    assert ([object_of] if isinstance(object_of, str) else object_of) == ["drop"]
    assert all(d["seed_range"] == ["train"] for d in record["data"])
    drops = [c for c in t5_clips(suites_release, "t5_maniskill", ("reference", "frozen")) if c.primitive == "drop"]
    ref = next(c for c in drops if c.kind == "reference")
    v = judge.judge(ref.judge_frames(), ref.object_px, "maniskill")
    assert score_verdict(v, "drop") == 100.0, v
    z = [np.log(v.evidence[k] / (1 - v.evidence[k])) for k in ("p_object", "p_object_verifier")]
    assert v.evidence["p_object_mean"] == pytest.approx(1 / (1 + np.exp(-np.mean(z))), abs=1e-6)
    frozen = [c for c in drops if c.kind == "frozen" and c.object is False]
    assert frozen and all(score_verdict(judge.judge(c.judge_frames(), c.object_px, "maniskill"), "drop") == 0.0
                          for c in frozen)
    push = next(c for c in t5_clips(suites_release, "t5_maniskill", ("reference",)) if c.primitive == "push")
    assert "p_object_verifier" not in judge.judge(push.judge_frames(), push.object_px, "maniskill").evidence
    assert NetJudge(PLATFORM_WEIGHTS["maniskill"]).verifier_for("maniskill", "drop") is None  # given weights: alone


def test_a_libero_clip_gets_its_object_verdict_from_the_mean_with_an_erased_trained_verifier(judge, libero_release):
    """On LIBERO every label's `object_ok` is decided by the mean of the network's object logit and the verifier's:
    three networks trained with the LIBERO network's recipe and data plus erased objects as negatives
    (`--erased clear`; its record says so). Alone they doubt pushes and taps that slide under the gripper; the mean
    keeps the network's references and credits fewer erased objects. On the tiny release: the mean is in the evidence, and on every
    clip whose object is clearly erased the verifier doubts the object more than the network does, so the mean
    lowers its credit."""
    record = json.loads(OBJECT_WEIGHTS[("libero", None)].with_suffix(".json").read_text())
    assert len(record["ensemble_of"]) == 3 and all(m["record"]["erased"] == "clear" for m in record["ensemble_of"])
    clips = t5_clips(libero_release, "t5_libero", ("reference", "erased"))
    verdicts = [(c, judge.judge(c.judge_frames(), c.object_px, "libero")) for c in clips]
    for _, v in verdicts:
        z = [np.log(v.evidence[k] / (1 - v.evidence[k])) for k in ("p_object", "p_object_verifier")]
        assert v.evidence["p_object_mean"] == pytest.approx(1 / (1 + np.exp(-np.mean(z))), abs=1e-6)
    erased = [(c, v) for c, v in verdicts if c.kind == "erased" and c.object is False]
    assert erased and all(v.evidence["p_object_verifier"] < v.evidence["p_object"] for _, v in erased), \
        [(c.instance_id, c.primitive, v.evidence) for c, v in erased]


def test_persists_follows_the_object_to_the_end_of_the_clip():
    """The persistence rule on synthetic 12-frame clips (128², object position in the 256² scoring frame): a red
    square that slides away is still there; one that vanishes before the last `PERSIST_FRAMES` frames is not; an
    object whose colour is the whole scene's gives no evidence (None)."""
    rng = np.random.default_rng(0)
    scene = rng.integers(90, 110, size=(128, 128, 3)).astype(np.uint8)  # grey, a little texture
    frames = np.repeat(scene[None], 12, axis=0)
    for t in range(12):
        frames[t, 60:68, 40 + 3 * t:48 + 3 * t] = (200, 30, 30)  # slides 33 px (66 in the scoring frame)
    px = (2 * 43.5, 2 * 63.5)
    assert persists(frames, px) is True
    gone = frames.copy()
    gone[12 - PERSIST_FRAMES - 1:] = scene  # erased before the last frames
    assert persists(gone, px) is False
    assert persists(np.full_like(frames, (200, 30, 30)), px) is None  # not a distinct region: no evidence


def test_an_object_erased_where_the_robot_acts_is_not_credited(judge, suites_release, aloha_release):
    """`erased` clips (the robot acts, the object fades out where it stood, as world models draw it) of the primitives
    that end with the object released (`RELEASED`) score 0 on the ManiSkill and ALOHA tiny releases (5 and 5 here; a
    network without the rule credits half to three quarters of such fresh clips), and every reference keeps
    its object to the end. Drag, rotate and shake end in the hand, so the rule leaves them to the network."""
    for release, config in ((suites_release, "t5_maniskill"), (aloha_release, "t5_aloha")):
        clips = t5_clips(release, config, ("reference", "erased"))
        assert all(persists(c.judge_frames(), c.object_px) is not False for c in clips if c.kind == "reference")
        erased = [c for c in clips if c.kind == "erased" and c.object is False and c.primitive in RELEASED]
        scored = [c.primitive for c in erased
                  if score_verdict(judge.judge(c.judge_frames(), c.object_px, c.platform), c.primitive)]
        assert len(erased) >= 4 and not scored, (config, scored)


def test_a_maniskill_pull_ends_with_its_cube_in_sight(judge, suites_release):
    """ManiSkill's pull script leaves the hand between the camera and the cube, so it then raises it `PULL_RISE` (a
    6 cm rise left the fingers over the cube in 18 of 96 fresh pulls, which the persistence rule then failed). The
    tiny release's pull reference: the rule finds the cube in the last frames and it scores 100; its erased clip,
    the cube faded out where the hand acted, is rejected by the rule."""
    from wsp_data.platforms.maniskill.primitives import CLEARANCE, PULL_RISE

    assert PULL_RISE >= 2 * CLEARANCE
    clips = t5_clips(suites_release, "t5_maniskill", ("reference", "erased"))
    ref = next(c for c in clips if c.kind == "reference" and c.primitive == "pull")
    v = judge.judge(ref.judge_frames(), ref.object_px, "maniskill")
    assert score_verdict(v, "pull") == 100.0 and v.evidence["object_persists"] == 1.0, v
    erased = next(c for c in clips if c.kind == "erased" and c.primitive == "pull")
    v = judge.judge(erased.judge_frames(), erased.object_px, "maniskill")
    assert score_verdict(v, "pull") == 0.0 and v.evidence.get("object_persists") == 0.0, v


def test_aloha_weights_reject_a_robot_acting_on_an_object_that_does_not_respond(judge, aloha_release):
    frozen = [c for c in t5_clips(aloha_release, "t5_aloha", ("frozen",)) if c.object is False]
    assert frozen and all(score_verdict(judge.judge(c.judge_frames(), c.object_px, c.platform), c.primitive) == 0.0
                          for c in frozen)


def test_a_frozen_object_clip_moves_the_robot_and_nothing_else(suites_release):
    """`frozen`: the robot pixels are the reference's, every other pixel is one still scene, and where frame 0
    shows the robot that scene comes from a frame before contact (nothing has moved yet), not from later."""
    from wsp_eval.backends.judge import frame_indices
    from wsp_eval.judge_data import DENSE, frozen_object, visibly_different
    from wsp_eval.suites.reference import InstanceReference
    import pyarrow.parquet as pq

    config = suites_release / "t5_maniskill"
    row = pq.read_table(config / "instances.parquet").to_pylist()[0]
    ref = InstanceReference(config, row)
    frames, masks = ref.frames("reference"), ref.masks("reference")
    idx = frame_indices(len(frames), DENSE)
    contact = int(row["first_contact_step"])
    out = frozen_object(frames, masks, contact, idx)
    robot = masks[idx] > 0
    assert out.shape == (DENSE, *frames.shape[1:]) and out.dtype == np.uint8
    assert np.array_equal(out[robot], frames[idx][robot])
    still = ~robot.any(axis=0)  # never the robot in these frames: the same scene pixel in every one
    assert np.array_equal(out[:, still], np.broadcast_to(out[0][still], out[:, still].shape))
    assert np.array_equal(out[0][~robot[0]], frames[0][~robot[0]])  # frame 0's scene where it shows it
    moved = np.abs(frames[-1].astype(int) - frames[0].astype(int)).sum(axis=-1) > 30
    assert (moved & still).any()  # the reference's object moved on pixels the frozen clip keeps still
    assert visibly_different(out, frames[idx]) and not visibly_different(frames[idx], frames[idx])


def test_an_erased_object_clip_fades_the_object_where_it_stood(suites_release):
    """`erased`: the frozen clip until first contact; then the object's frame-0 footprint fades into an inpainted
    scene while the robot pixels stay the reference's; nothing outside the footprint changes."""
    from wsp_eval.backends.judge import frame_indices
    from wsp_eval.judge_data import DENSE, erased_object, frozen_object, object_footprint, visibly_different
    from wsp_eval.suites.reference import InstanceReference
    from wsp_eval.tracking import frame_size, frame_xy
    import pyarrow.parquet as pq

    config = suites_release / "t5_maniskill"
    rows = [r for r in pq.read_table(config / "instances.parquet").to_pylist() if r["primitive"] == "drop"]
    ref = InstanceReference(config, rows[0])
    frames, masks = ref.frames("reference"), ref.masks("reference")
    x, y = frame_xy(tuple(rows[0]["object_pixel_256"]), *frame_size(frames[0]))
    footprint = object_footprint(frames, masks, (x, y))
    assert footprint is not None and footprint[round(y), round(x)]  # the object stood there
    assert footprint.sum() < 0.05 * footprint.size  # the object's pixels, not the scene's
    idx = frame_indices(len(frames), DENSE)
    contact = int(rows[0]["first_contact_step"])
    out, frozen = erased_object(frames, masks, contact, idx, footprint), frozen_object(frames, masks, contact, idx)
    robot = masks[idx] > 0
    assert np.array_equal(out[robot], frames[idx][robot])
    before = idx < contact
    assert before.any() and np.array_equal(out[before], frozen[before])  # nothing fades before contact
    assert np.array_equal(out[:, ~footprint], frozen[:, ~footprint])  # only the object's pixels change
    gone = ~robot[-1] & footprint
    assert np.abs(out[-1][gone].astype(int) - frozen[-1][gone].astype(int)).max() > 40  # it has faded by the end
    assert visibly_different(out, frames[idx])
    # `where` (what `Clip.clear` uses, with the footprint's complement) counts only the pixels it names
    assert visibly_different(out, frames[idx], footprint)
    assert not visibly_different(out, frames[idx], np.zeros_like(footprint))


def test_scoring_with_the_net_judge_needs_no_torch(tmp_path):
    """The judge runs in the scoring-only install: OpenCV's dnn, never torch."""
    import subprocess

    code = ("import sys, numpy as np; from wsp_eval.backends.judge_net import NetJudge; "
            "v = NetJudge().judge(np.zeros((12, 128, 128, 3), np.uint8), (128.0, 128.0), 'aloha'); "
            "assert 'torch' not in sys.modules and 'onnx' not in sys.modules, sorted(sys.modules); print(v.label)")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stderr


def test_training_refuses_clips_of_test_range_seeds(tmp_path, libero_release):
    """The judge and its verifiers train on `--seed-range train` builds only (what makes every measurement on
    test-range and private-range seeds fresh): `train_judge.py` on the tiny release (test-range seeds) stops before
    training, naming the config and the fix, and writes no weights."""
    import subprocess

    pytest.importorskip("torch")
    out = tmp_path / "verifier.onnx"
    run = subprocess.run([sys.executable, str(Path(ENSEMBLE).with_name("train_judge.py")), str(libero_release),
                          "--object-of", "tap", "pull", "--out", str(out)], capture_output=True, text=True, timeout=300)
    assert run.returncode != 0 and not out.exists()
    assert "t4_libero: built on the t4 seed range" in run.stderr and "--seed-range train" in run.stderr, run.stderr
