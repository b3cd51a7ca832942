"""The ManiSkill platform on real rollouts: camera, mask, contacts, kinematics, determinism."""

from __future__ import annotations

import numpy as np
import pytest

from wsp_data.platforms.maniskill.env import MASK_DISTAL, ManiSkillPlatform, PlatformError
from wsp_data.platforms.maniskill.experts import ExpertSource, task_spec

SEED = 7


@pytest.fixture(scope="module")
def pick():
    es = ExpertSource("PickCube")
    actions = es.trajectory(SEED)
    es.close()
    assert actions is not None
    with ManiSkillPlatform("PickCube", objects=task_spec("PickCube").objects) as p:
        yield p, p.replay(SEED, actions), actions


def test_only_the_evaluated_camera_renders():
    with ManiSkillPlatform("StackCube", objects=task_spec("StackCube").objects) as p:  # mounts a hand camera
        p.reset(0)
        assert list(p.u._sensors) == ["base_camera"]


def test_camera_parameters_project_the_hand_onto_its_mask(pick):
    """Projecting the hand link with the stored intrinsics/extrinsics lands on the hand's mask label,
    within 4 px of the label-2 centroid at 128×128 (the link origin sits inside the visible hand)."""
    p, ro, _ = pick
    hand = next(l for l in p.robot.get_links() if l.name == "panda_hand")
    world = np.append(hand.pose.p[0].numpy(), 1.0)
    cam = ro.extrinsic @ world
    u, v = (ro.intrinsic @ cam)[:2] / cam[2]
    ys, xs = np.nonzero(ro.observations[-1].mask == MASK_DISTAL)
    assert np.hypot(xs.mean() - u, ys.mean() - v) < 4.0


def test_every_frame_labels_the_objects_the_camera_sees(pick):
    """Every frame carries the tracked objects' label image (the release stores it for T5): at frame 0 the cube's
    pixels (label 1) are where its centre projects (T4's `centre_hidden` finds it seen there); no label lies on the
    robot, in any frame."""
    from wsp_data.builders.t4 import centre_hidden
    from wsp_eval.tracking import frame_size, project

    p, ro, _ = pick
    ob = ro.observations[0]
    assert ob.objects.shape == (128, 128) and (ob.objects == 1).sum() > 4
    assert not ob.objects[ob.mask > 0].any()
    assert all(o.objects.shape == (128, 128) and not o.objects[o.mask > 0].any() for o in ro.observations)
    pixel = project(ob.object_poses[0, :3], ro.intrinsic, ro.extrinsic, frame_size(ob.rgb))
    assert centre_hidden(ob.objects, 0, pixel) is None
    assert centre_hidden(ob.objects, 0, pixel + 40) is not None  # 20 native px off the cube


def test_contacts_flag_the_grasp(pick):
    _, ro, actions = pick
    contacts = ro.stack("contacts")[:, 0]
    assert not contacts[0]  # the robot starts clear of the cube
    assert contacts[-10:].all()  # the cube is held at the goal
    closing = np.nonzero(np.diff(actions[:, 7]) < 0)[0][0]  # first step the gripper command closes
    assert not contacts[:closing].any()
    assert ro.success


def test_ee_action_is_forward_kinematics_of_the_joint_target(pick):
    """At rest after the final hold, the TCP sits at the FK of the commanded joints (tracking error < 5 mm)."""
    p, ro, actions = pick
    base = p.robot.pose.p[0].numpy()
    tcp_in_base = ro.observations[-1].tcp_pose[:3] - base  # the base is unrotated in PickCube
    assert np.linalg.norm(ro.alt_actions[-1][:3] - tcp_in_base) < 0.005


def test_replay_is_bit_identical_and_history_free(pick):
    p, ro, actions = pick
    other = ExpertSource("PickCube")
    p.replay(SEED + 1, other.trajectory(SEED + 1))  # another episode in between
    other.close()
    again = p.replay(SEED, actions)
    assert np.array_equal(again.stack("rgb"), ro.stack("rgb"))
    assert np.array_equal(again.stack("qpos"), ro.stack("qpos"))


def test_bad_streams_are_refused(pick):
    p, _, actions = pick
    with pytest.raises(PlatformError, match="shape"):
        p.replay(SEED, actions[:, :7])
    bad = actions.copy()
    bad[3, 2] = np.nan
    with pytest.raises(PlatformError, match="NaN"):
        p.replay(SEED, bad)
    with pytest.raises(PlatformError, match="unknown ManiSkill task"):
        ManiSkillPlatform("FlyToMoon")
