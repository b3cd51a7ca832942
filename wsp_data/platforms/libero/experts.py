"""Scripted expert sources for LIBERO: one closed-loop pick-and-place script in LIBERO's own OSC action space,
driven by simulator state (object geometry and poses), for every task whose BDDL goal is a single
`(On obj target)` or `(In obj region)`.

`TASKS` is the registry of the benchmark's 40 LIBERO tasks (chosen by measured scripted success: see
docs/guides/experts.md). `LiberoExpertSource(task).trajectory(seed)` scripts the task on an unrendered env and returns
the OSC stream only if it succeeds; a replay of that stream from the same scene is bit-identical (tested), so
every returned stream is a verified success.
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from functools import lru_cache

import mujoco
import numpy as np

from wsp_data.platforms.libero.env import GRIPPER_CLOSED, GRIPPER_OPEN, LiberoPlatform, libero_task

ROT_SCALE = 0.5  # rad per unit of OSC rotation action
GAIN = 12.0  # proportional gain: action = GAIN · error (m), clipped to ±MAX_ACTION
MAX_ACTION = 0.9  # arm action bound: leaves T1's largest perturbation (0.02) inside the controller's [−1, 1]
MAX_STEPS = 360  # 18 s at 20 Hz
HOLD_AFTER_SUCCESS = 6  # steps recorded after the goal first holds
FINGER_DEPTH = 0.02  # m the fingertips reach below the top of a grasped rim or box
RIM_INSET = 0.012  # m from a bowl or mug's outer radius to the rim-grasp point
_GOAL = re.compile(r"\(:goal\s*\(And\s*\((In|On)\s+([A-Za-z0-9_]+)\s+([A-Za-z0-9_]+)\)\s*\)\s*\)", re.I)


@dataclass(frozen=True)
class LiberoTaskSpec:
    """A LIBERO task of the benchmark: the held object, the goal relation and where it must end up."""

    name: str
    instruction: str
    relation: str  # "in" | "on"
    target: str  # the object picked up
    destination: str  # an object (on) or a region site (in / on a table region)
    objects: tuple[str, ...]  # pose/contact columns: target, then the destination's object


@lru_cache(maxsize=None)
def task_spec(name: str) -> LiberoTaskSpec:
    t = libero_task(name)
    text = open(t.bddl_file).read()
    m = _GOAL.search(" ".join(text.split()))
    if m is None:
        raise ValueError(f"{name}: goal is not a single (On …) / (In …); no scripted expert for it")
    relation, target, destination = m.group(1).lower(), m.group(2), m.group(3)
    owner = _region_owner(text, destination)
    objects = (target,) + ((owner,) if owner else ())
    return LiberoTaskSpec(name, t.instruction, relation, target, destination, objects)


def _region_owner(bddl: str, destination: str) -> str | None:
    """The object a destination belongs to: itself when it is an object, a region's target object, or None
    for a region of the table / floor."""
    objects = {name for names in re.findall(r"^\s*([a-z0-9_ ]+?)\s+-\s+[a-z0-9_]+\s*$", bddl, re.M)
               for name in names.split()}  # a line may declare several objects of one type
    if destination in objects:
        return destination
    for obj in sorted(objects, key=len, reverse=True):
        if destination.startswith(obj + "_") and not obj.startswith(("main_table", "floor", "kitchen_table",
                                                                       "living_room_table", "study_table")):
            return obj
    return None


class Scene:
    """Geometry queries on a LIBERO platform's current MuJoCo state."""

    def __init__(self, p: LiberoPlatform):
        self.p, self.m, self.d = p, p.model, p.data
        m = self.m
        self._left = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_BODY, "gripper0_leftfinger")
        self._right = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_BODY, "gripper0_rightfinger")

    def body(self, name: str) -> int:
        return self.p.body(name)

    def points(self, name: str, frame: str = "world") -> np.ndarray:
        return self.p.collision_points(name, frame)

    def box(self, name: str) -> tuple[np.ndarray, np.ndarray]:
        pts = self.points(name)
        return pts.min(axis=0), pts.max(axis=0)

    def site(self, name: str) -> np.ndarray:
        sid = mujoco.mj_name2id(self.m, mujoco.mjtObj.mjOBJ_SITE, name)
        if sid < 0:
            raise ValueError(f"{self.p.task}: no site {name!r}")
        return np.array(self.d.site_xpos[sid])

    def ee(self) -> np.ndarray:
        return np.array(self.d.site_xpos[self.p.eef_site])

    def closing_axis(self) -> np.ndarray:
        """Horizontal unit vector along which the fingers close (right finger → left finger)."""
        v = self.d.xpos[self._left] - self.d.xpos[self._right]
        v[2] = 0
        return v / np.linalg.norm(v)


def _wrap_half_pi(a: float) -> float:
    """An angle modulo π, in [−π/2, π/2): a parallel-jaw grasp is symmetric under a half turn."""
    return (a + np.pi / 2) % np.pi - np.pi / 2


class PickPlaceScript:
    """Closed-loop pick-and-place on a state-only platform; records the OSC stream it sends."""

    def __init__(self, p: LiberoPlatform, spec: LiberoTaskSpec, seed: int):
        self.p, self.spec = p, spec
        self.g = Scene(p)
        self.actions: list[np.ndarray] = []
        self.observation = p.reset(seed)  # the latest observation
        self.succeeded_at: int | None = None
        self.grip = GRIPPER_OPEN
        self.gain = GAIN
        self.max_steps = MAX_STEPS
        self.success_wait: int | None = None  # steps to wait for the goal after placing (None: to the budget)

    # -- primitives ----------------------------------------------------------------------------------
    def act(self, a: np.ndarray) -> None:
        if len(self.actions) >= self.max_steps:
            raise OutOfTime
        a = np.asarray(a, dtype=np.float64).copy()
        a[:6] = np.clip(a[:6], -MAX_ACTION, MAX_ACTION)
        a = a.astype(np.float32)
        self.actions.append(a)
        ob = self.observation = self.p.step(a)
        if ob.success and self.succeeded_at is None:
            self.succeeded_at = len(self.actions)

    def move(self, target, yaw: float | None = None, tol: float = 0.006, max_steps: int = 60) -> bool:
        """Servo the grip site to `target` (world xyz), turning the closing axis to `yaw` (rad) if given."""
        target = np.asarray(target, dtype=np.float64)
        for _ in range(max_steps):
            err = target - self.g.ee()
            turn = 0.0 if yaw is None else _wrap_half_pi(yaw - self._closing_yaw())
            if np.linalg.norm(err) < tol and abs(turn) < 0.05:
                return True
            a = np.zeros(7)
            a[:3] = np.clip(self.gain * err, -1, 1)
            a[5] = np.clip(2.0 * turn / ROT_SCALE, -1, 1)
            a[6] = self.grip
            self.act(a)
        return False

    def _closing_yaw(self) -> float:
        v = self.g.closing_axis()
        return float(np.arctan2(v[1], v[0]))

    def gripper(self, command: float, steps: int = 10) -> None:
        self.grip = command
        for _ in range(steps):
            self.act(np.array([0, 0, 0, 0, 0, 0, command]))

    # -- plan ---------------------------------------------------------------------------------------
    def grasp_point(self) -> tuple[np.ndarray, float | None]:
        """Where the grip site closes and the closing-axis yaw: a rim point for bowls and mugs (the wall
        between the fingers), else the middle of a box's short side near its top."""
        name = self.spec.target
        lo, hi = self.g.box(name)
        centre = (lo + hi) / 2
        if any(k in name for k in ("bowl", "mug")):
            # the wall on the closing axis's line through the centre, on the side nearer the hand: the fingers
            # close across it without turning
            radius = 0.5 * min(hi[0] - lo[0], hi[1] - lo[1])
            axis = self.g.closing_axis()
            side = 1.0 if (self.g.ee() - centre)[:2] @ axis[:2] >= 0 else -1.0
            p = centre + side * axis * (radius - RIM_INSET)
            p[2] = hi[2] - FINGER_DEPTH
            return p, None
        body = self.g.points(name, frame="body")
        ext = body.max(axis=0) - body.min(axis=0)
        R = self.g.d.xmat[self.g.body(name)].reshape(3, 3)
        short = R[:, 0] if ext[0] <= ext[1] else R[:, 1]
        yaw = float(np.arctan2(short[1], short[0]))
        height = hi[2] - lo[2]
        p = centre.copy()
        p[2] = max(lo[2] + 0.5 * height, hi[2] - 0.03) if height > 0.06 else max(lo[2] + 0.012, hi[2] - FINGER_DEPTH)
        return p, yaw

    def place_point(self, held: np.ndarray) -> np.ndarray:
        """Grip-site position to release at: the held object's centre over the destination's centre, its
        bottom 2 cm above the destination's top (just below a container's rim). `held` = grip site − the
        held object's (x, y centre, bottom)."""
        spec = self.spec
        if spec.relation == "in" or spec.destination not in self.p.u.objects_dict | self.p.u.fixtures_dict:
            xy = self.g.site(spec.destination)[:2]
        else:
            lo, hi = self.g.box(spec.destination)
            xy = ((lo + hi) / 2)[:2]
        owner = spec.objects[1] if len(spec.objects) > 1 else None
        top = self.g.box(owner)[1][2] if owner else self.g.site(spec.destination)[2]
        if spec.relation == "in" and owner:
            top = top - 0.02
        return np.array([xy[0] + held[0], xy[1] + held[1], top + held[2] + 0.02])

    def grasp(self) -> None:
        """Approach the target's grasp point through `approach` (turning the hand), descend and close."""
        grasp, yaw = self.grasp_point()
        clear = max(0.10, self.g.box(self.spec.target)[1][2] - grasp[2] + 0.06)
        for point, tol, steps in self.approach(grasp, clear):
            self.move(point, yaw=yaw, tol=tol, max_steps=steps)
        self.move(grasp, yaw=yaw, tol=0.004, max_steps=50)
        self.gripper(GRIPPER_CLOSED, 12)

    def approach(self, grasp: np.ndarray, clear: float) -> list[tuple[np.ndarray, float, int]]:
        """Waypoints (point, tolerance, step budget) before the final descent: `clear` above the grasp point,
        reached, then settled."""
        above = grasp + [0, 0, clear]
        return [(above, 0.006, 80), (above, 0.004, 20)]

    def place(self) -> None:
        """Lift the held target, carry it over its destination, lower it, open the fingers and back off."""
        lo, hi = self.g.box(self.spec.target)
        release = self.place_point(self.g.ee() - [(lo[0] + hi[0]) / 2, (lo[1] + hi[1]) / 2, lo[2]])
        cruise = max(self.g.ee()[2] + 0.12, release[2] + 0.08)
        self.move([*self.g.ee()[:2], cruise], max_steps=40)
        self.move([*release[:2], cruise], max_steps=80)
        self.move(release, max_steps=50)
        self.gripper(GRIPPER_OPEN, 10)
        self.move(self.g.ee() + [0, 0, 0.08], max_steps=20)

    def run(self) -> bool:
        """The whole task; True when the goal holds at the end of the recorded stream."""
        try:
            self.grasp()
            self.place()
            placed = len(self.actions)
            while self.succeeded_at is None or len(self.actions) < self.succeeded_at + HOLD_AFTER_SUCCESS:
                self.act(np.array([0, 0, 0, 0, 0, 0, GRIPPER_OPEN]))
                late = self.success_wait is not None and len(self.actions) - placed > self.success_wait
                if self.succeeded_at is None and (late or len(self.actions) > self.max_steps - HOLD_AFTER_SUCCESS):
                    return False
        except OutOfTime:
            return False
        return bool(self.observation.success)


class OutOfTime(Exception):
    """The script used up MAX_STEPS."""


# The benchmark's 40 LIBERO tasks: every single-goal pick-and-place task of libero_object, libero_spatial and
# libero_goal that the script solves in ≥ 7 of 10 scenes, then libero_90's in its order (docs/guides/experts.md lists
# all 97 candidates with their measured success).
BENCHMARK_TASKS: tuple[str, ...] = (
    "libero_object/pick_up_the_alphabet_soup_and_place_it_in_the_basket",
    "libero_object/pick_up_the_salad_dressing_and_place_it_in_the_basket",
    "libero_object/pick_up_the_bbq_sauce_and_place_it_in_the_basket",
    "libero_object/pick_up_the_ketchup_and_place_it_in_the_basket",
    "libero_object/pick_up_the_tomato_sauce_and_place_it_in_the_basket",
    "libero_object/pick_up_the_butter_and_place_it_in_the_basket",
    "libero_object/pick_up_the_milk_and_place_it_in_the_basket",
    "libero_object/pick_up_the_chocolate_pudding_and_place_it_in_the_basket",
    "libero_object/pick_up_the_orange_juice_and_place_it_in_the_basket",
    "libero_spatial/pick_up_the_black_bowl_between_the_plate_and_the_ramekin_and_place_it_on_the_plate",
    "libero_spatial/pick_up_the_black_bowl_next_to_the_ramekin_and_place_it_on_the_plate",
    "libero_spatial/pick_up_the_black_bowl_from_table_center_and_place_it_on_the_plate",
    "libero_spatial/pick_up_the_black_bowl_on_the_cookie_box_and_place_it_on_the_plate",
    "libero_spatial/pick_up_the_black_bowl_on_the_ramekin_and_place_it_on_the_plate",
    "libero_spatial/pick_up_the_black_bowl_next_to_the_cookie_box_and_place_it_on_the_plate",
    "libero_spatial/pick_up_the_black_bowl_next_to_the_plate_and_place_it_on_the_plate",
    "libero_goal/put_the_bowl_on_the_stove",
    "libero_goal/put_the_wine_bottle_on_top_of_the_cabinet",
    "libero_goal/put_the_bowl_on_top_of_the_cabinet",
    "libero_goal/put_the_cream_cheese_in_the_bowl",
    "libero_90/KITCHEN_SCENE10_put_the_black_bowl_in_the_top_drawer_of_the_cabinet",
    "libero_90/KITCHEN_SCENE1_put_the_black_bowl_on_the_plate",
    "libero_90/KITCHEN_SCENE1_put_the_black_bowl_on_top_of_the_cabinet",
    "libero_90/KITCHEN_SCENE2_put_the_black_bowl_at_the_back_on_the_plate",
    "libero_90/KITCHEN_SCENE2_put_the_black_bowl_at_the_front_on_the_plate",
    "libero_90/KITCHEN_SCENE2_put_the_middle_black_bowl_on_the_plate",
    "libero_90/KITCHEN_SCENE2_put_the_middle_black_bowl_on_top_of_the_cabinet",
    "libero_90/KITCHEN_SCENE3_put_the_moka_pot_on_the_stove",
    "libero_90/KITCHEN_SCENE4_put_the_wine_bottle_in_the_bottom_drawer_of_the_cabinet",
    "libero_90/KITCHEN_SCENE6_put_the_yellow_and_white_mug_to_the_front_of_the_white_mug",
    "libero_90/KITCHEN_SCENE9_put_the_white_bowl_on_top_of_the_cabinet",
    "libero_90/LIVING_ROOM_SCENE1_pick_up_the_alphabet_soup_and_put_it_in_the_basket",
    "libero_90/LIVING_ROOM_SCENE1_pick_up_the_cream_cheese_box_and_put_it_in_the_basket",
    "libero_90/LIVING_ROOM_SCENE1_pick_up_the_tomato_sauce_and_put_it_in_the_basket",
    "libero_90/LIVING_ROOM_SCENE2_pick_up_the_alphabet_soup_and_put_it_in_the_basket",
    "libero_90/LIVING_ROOM_SCENE2_pick_up_the_butter_and_put_it_in_the_basket",
    "libero_90/LIVING_ROOM_SCENE2_pick_up_the_tomato_sauce_and_put_it_in_the_basket",
    "libero_90/LIVING_ROOM_SCENE3_pick_up_the_alphabet_soup_and_put_it_in_the_tray",
    "libero_90/LIVING_ROOM_SCENE3_pick_up_the_butter_and_put_it_in_the_tray",
    "libero_90/LIVING_ROOM_SCENE3_pick_up_the_cream_cheese_and_put_it_in_the_tray",
)


TASKS: dict[str, LiberoTaskSpec] = {name: task_spec(name) for name in BENCHMARK_TASKS}


class LiberoExpertSource:
    """Scripted, verified expert streams for one LIBERO task."""

    def __init__(self, task: str, simulator: LiberoPlatform | None = None):
        """`simulator`: an unrendered platform of the task to run on (the caller's, left open at `close`); None:
        a state-only env of its own."""
        self.spec = task_spec(task)
        self._owns = simulator is None
        self.replayer = LiberoPlatform(task, render=False, objects=self.spec.objects) if self._owns else simulator
        self._cache: dict[int, np.ndarray | None] = {}

    def close(self) -> None:
        if self._owns:
            self.replayer.close()

    def trajectory(self, seed: int) -> np.ndarray | None:
        """The (T, 7) OSC stream that solves the task at scene `seed`, or None if the script fails."""
        if seed not in self._cache:
            script = PickPlaceScript(self.replayer, self.spec, seed)
            ok = script.run()
            self._cache[seed] = np.stack(script.actions) if ok and script.actions else None
        return self._cache[seed]
