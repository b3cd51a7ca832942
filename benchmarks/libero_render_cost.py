"""Where a LIBERO rendered step goes, against the bare simulator, in one run.

Side by side in this one process, over the same action stream from the same scene (rounds interleaved, so load
on the machine hits every column alike):

- bare: LIBERO's own env (`OffScreenRenderEnv`) stepped with robosuite's camera observation switched on (the
  128² `agentview` RGB) plus one segmentation image through robosuite's render context (its segmentation
  observable and `sim.render(segmentation=True)` overflow under numpy 2: the raw ids are read):
  what any user of the simulator pays for the same two images;
- ours: `LiberoPlatform.step` with rendering (physics, both passes, the label images and every state field);
- and ours split into its parts: the unrendered step (robosuite's physics and OSC controller), the RGB pass, the
  segmentation pass;
- the RGB pass without 4× multisampling (`offsamples` 0), with how far its pixels move: an option that changes
  every LIBERO frame, measured, not used.

Prints wall milliseconds per step (and CPU ms: OSMesa's llvmpipe renders on threads), ratios to the bare
simulator, and the scene's visible triangle count; asserts nothing.

    .venv/bin/python benchmarks/libero_render_cost.py [--task libero_object/...] [--steps 30] [--rounds 3]
"""

from __future__ import annotations

import argparse
import contextlib
import io
import time

import numpy as np

from wsp_data.platforms.libero.env import CAMERA, LiberoPlatform
from wsp_data.schema import IMAGE_SIZE

import mujoco  # noqa: E402  (after the platform: it selects the GL backend)
from libero.libero.envs import OffScreenRenderEnv  # noqa: E402

TASK = "libero_object/pick_up_the_alphabet_soup_and_place_it_in_the_basket"


def visible_triangles(model: mujoco.MjModel, groups: np.ndarray) -> int:
    """Faces of the mesh geoms the camera draws (geom groups enabled in the render options, not transparent)."""
    g = np.nonzero((model.geom_type == mujoco.mjtGeom.mjGEOM_MESH) & (groups[model.geom_group] > 0)
                   & (model.geom_rgba[:, 3] > 0))[0]
    return int(model.mesh_facenum[model.geom_dataid[g]].sum())


def timed(fn, n: int) -> tuple[float, float]:
    """Wall and CPU milliseconds per call of `fn(i)`, i < n."""
    w, c = time.perf_counter(), time.process_time()
    for i in range(n):
        fn(i)
    return (time.perf_counter() - w) * 1000 / n, (time.process_time() - c) * 1000 / n


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--task", default=TASK)
    ap.add_argument("--steps", type=int, default=30, help="steps per round and column")
    ap.add_argument("--rounds", type=int, default=3)
    args = ap.parse_args()
    rng = np.random.default_rng(0)
    actions = np.clip(rng.normal(0, 0.3, (args.steps, 7)), -1, 1)
    actions[:, 6] = -1.0

    ours = LiberoPlatform(args.task, render=True)
    physics = LiberoPlatform(args.task, render=False)
    with contextlib.redirect_stdout(io.StringIO()):
        bare = OffScreenRenderEnv(bddl_file_name=ours.spec.bddl_file, camera_names=[CAMERA],
                                  camera_heights=IMAGE_SIZE, camera_widths=IMAGE_SIZE, ignore_done=True,
                                  horizon=100_000)
        bare.seed(0)
        bare.reset()
    ctx = ours.sim._render_context_offscreen
    model = ours.model
    size, cam = IMAGE_SIZE, ours.camera_id
    rgb = np.empty((size, size, 3), np.uint8)

    def render_pass(segmentation: bool):
        def one(_: int) -> None:  # one pass of `LiberoPlatform.render_frame`, read back into `rgb`
            ctx.gl_ctx.make_current()
            ctx.render(width=size, height=size, camera_id=cam, segmentation=segmentation)
            mujoco.mjr_readPixels(rgb=rgb, depth=None, viewport=mujoco.MjrRect(0, 0, size, size), con=ctx.con)
        return one

    rgb_pass = render_pass(False)

    def bare_step(i: int) -> None:
        ctx_b = bare.env.sim._render_context_offscreen
        ctx_b.gl_ctx.make_current()
        bare.step(actions[i])
        ctx_b.render(width=size, height=size, camera_id=cam, segmentation=True)
        ctx_b.read_pixels(size, size)  # the raw ids: robosuite's own unpacking overflows under numpy 2

    columns = {"bare simulator (robosuite step, RGB obs, seg render)": bare_step,
               "ours: LiberoPlatform.step, rendered": lambda i: ours.step(actions[i]),
               "  unrendered step (physics + OSC)": lambda i: physics.step(actions[i]),
               "  RGB pass (4x MSAA)": rgb_pass, "  segmentation pass": render_pass(True)}
    totals = {k: np.zeros(2) for k in columns}
    for _ in range(args.rounds):
        ours.reset(0), physics.reset(0)
        for name, fn in columns.items():
            totals[name] += timed(fn, args.steps)
    # the RGB pass without multisampling: a new render context for the same model, pixels compared to the default
    ctx.gl_ctx.make_current()
    rgb_pass(0)
    default = rgb.copy()
    samples = model.vis.quality.offsamples
    model.vis.quality.offsamples = 0
    ctx.con.free()
    ctx.con = mujoco.MjrContext(model, mujoco.mjtFontScale.mjFONTSCALE_150)
    mujoco.mjr_setBuffer(mujoco.mjtFramebuffer.mjFB_OFFSCREEN, ctx.con)
    no_msaa = np.zeros(2)
    for _ in range(args.rounds):
        no_msaa += timed(rgb_pass, args.steps)
    rgb_pass(0)
    moved = np.abs(rgb.astype(int) - default).mean()
    changed = float((rgb != default).any(axis=2).mean())

    bare_ms = totals[next(iter(columns))][0] / args.rounds
    print(f"LIBERO {args.task}, {size}x{size}, {args.rounds} rounds x {args.steps} steps; "
          f"{visible_triangles(model, np.asarray(ctx.vopt.geomgroup)):,} visible mesh triangles, "
          f"offsamples {samples}")
    print(f"{'':<52} {'wall ms':>8} {'cpu ms':>8} {'/ bare':>7}")
    for name, (wall, cpu) in totals.items():
        print(f"{name:<52} {wall / args.rounds:8.1f} {cpu / args.rounds:8.1f} {wall / args.rounds / bare_ms:7.2f}")
    wall, cpu = no_msaa / args.rounds
    print(f"{'  RGB pass, offsamples 0 (changes pixels)':<52} {wall:8.1f} {cpu:8.1f} {wall / bare_ms:7.2f}")
    print(f"offsamples 0 against the default RGB: {changed:.0%} of pixels change, mean |Δ| {moved:.2f} levels")
    for p in (ours, physics):
        p.close()
    bare.close()


if __name__ == "__main__":
    main()
