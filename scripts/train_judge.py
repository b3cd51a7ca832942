"""Train the learned T5 judge (`wsp_eval.backends.judge_net`) from simulator clips of training-range scene seeds,
export it to ONNX and check that OpenCV's dnn gives the same outputs as torch.

    # LIBERO's weights (three networks averaged), from a fresh clone; $TASKS, $LIVING and $K10 are the task lists
    # of train-u, train-lr and train-k10x in the weights' training record (judge_net_v14_libero.json):
    wsp build --platform libero --suite t5 --seed-range train --primitives tap pull --count 64 --workers 2 --out train-tp
    wsp build --platform libero --suite t5 --seed-range train --primitives push drop --count 56 --workers 2 --out train-pd
    wsp build --platform libero --suite t4 --seed-range train --count 48 --workers 2 --out train-t4
    wsp build --platform libero --suite t5 --seed-range train --tasks $TASKS --primitives pull drop --count 40 \
        --workers 2 --out train-u
    wsp build --platform libero --suite t5 --seed-range train --tasks $LIVING --primitives push tap --count 32 \
        --workers 2 --out train-lr
    wsp build --platform libero --suite t5 --seed-range train --tasks $K10 --primitives push tap --count 48 \
        --workers 2 --out train-k10x
    for s in 0 1 2; do .venv/bin/python scripts/train_judge.py train-tp train-pd train-t4 train-u train-lr \
        train-k10x --seed $s --out r14_s$s.onnx; done
    .venv/bin/python scripts/ensemble_judge.py r14_s0.onnx r14_s1.onnx r14_s2.onnx \
        --out wsp_eval/backends/weights/judge_net_v14_libero.onnx
    # its object verifier: the same builds and seeds, erased objects as negatives
    for s in 0 1 2; do .venv/bin/python scripts/train_judge.py train-tp train-pd train-t4 train-u train-lr \
        train-k10x --erased clear --seed $s --out e15_s$s.onnx; done
    .venv/bin/python scripts/ensemble_judge.py e15_s0.onnx e15_s1.onnx e15_s2.onnx \
        --out wsp_eval/backends/weights/judge_net_v15_libero_object.onnx

The other shipped weights (ManiSkill's two networks, its drop verifier, ALOHA's network) are made the same way:
each `.json` training record beside the weights in `wsp_eval/backends/weights/` names every build it was trained on
(release, config, count, build seed, tasks, primitives where restricted, checksums; all on `--seed-range train`)
and every training argument (epochs, batch, learning rate, seed, `--expert`, `--erased`, `--object-of`).

Clips (`wsp_eval.judge_data`): every T5 reference (label, agent and object true), frame 0 repeated (both false),
the approach before first contact (object false), the robot held still while the object moves (agent false), the
robot acting over a still scene (`frozen`: object false where visibly unlike the reference), with `--erased` the
robot acting while the object fades out where it stood (`erased`: likewise), and every T4 reference (the robot near or touching an object that never moves: object false). Augmented toward what generated video looks like: JPEG noise, blur, down- and up-sampling, colour
gain/offset, left–right mirroring, jittered frame sampling with repeated frames, a shifted object position.
Deterministic on the CPU (fixed seeds, one thread): the same data and torch version give the same weights.
The training record (data checksums, counts, epochs, losses, train accuracy) is written beside the weights.
`--init FILE --init-member I` fine-tunes member I of a shipped file instead of training from random weights
(none of the shipped weights is a fine-tune).
"""

from __future__ import annotations

import argparse
import hashlib
import json
import sys
import time
from pathlib import Path

import cv2
import numpy as np
import torch
from torch import nn

from wsp_eval.backends.judge import JUDGE_FRAMES, PRIMITIVES
from wsp_eval.backends.judge_net import CHANNELS, FRAME, at_frame_size, judge_input
from wsp_eval.judge_data import DENSE, T5_KINDS, Clip, t4_clips, t5_clips
from wsp_eval.release_format import BUILD_REPORT, CARD, CROISSANT, RELEASE_JSON, split_config

EPOCHS, BATCH, LR, WEIGHT_DECAY, SEED = 50, 32, 2e-3, 1e-4, 0
T4_REPEAT = 4  # T4 still-object clips are few (one per T4 reference) and the hardest negatives: each epoch sees
#   each of them this many times (differently augmented). Measured: once per epoch, 3 of 9 tiny-release T4
#   references were still accepted as a moving primitive.


class JudgeNet(nn.Module):
    """Five 3×3 convolutions (stride 2 but the second), batch norm, ReLU; global average pool; 10 outputs."""

    def __init__(self, width: tuple[int, ...] = (32, 48, 64, 96, 96)):
        super().__init__()
        layers, cin = [], CHANNELS
        for i, c in enumerate(width):
            layers += [nn.Conv2d(cin, c, 3, 1 if i == 1 else 2, 1, bias=False), nn.BatchNorm2d(c), nn.ReLU()]
            cin = c
        self.features = nn.Sequential(*layers)
        self.head = nn.Sequential(nn.AdaptiveAvgPool2d(1), nn.Flatten(), nn.Dropout(0.2),
                                  nn.Linear(cin, len(PRIMITIVES) + 2))

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return self.head(self.features(x))


def initialised(model: JudgeNet, path: Path, member: int) -> JudgeNet:
    """`model` holding a trained member's weights: each convolution its folded weight, each batch norm the identity
    plus the folded bias (statistics 0 and 1, scale √(1 + eps)); trained with those statistics frozen
    (`freeze_norms`), it computes what the member computes until the weights move, and exports folded again."""
    from ensemble_judge import member as member_of  # this script's directory is on sys.path when it runs

    layers, head_w, head_b = member_of(path, member)
    convs = [m for m in model.features if isinstance(m, nn.Conv2d)]
    norms = [m for m in model.features if isinstance(m, nn.BatchNorm2d)]
    if [tuple(c.weight.shape) for c in convs] != [w.shape for w, _ in layers]:
        sys.exit(f"{path}: member {member}'s convolutions do not have this script's shapes")
    with torch.no_grad():
        for conv, norm, (w, b) in zip(convs, norms, layers):
            conv.weight.copy_(torch.tensor(w))
            norm.running_mean.zero_()
            norm.running_var.fill_(1.0)
            norm.weight.fill_(float(np.sqrt(1.0 + norm.eps)))
            norm.bias.copy_(torch.tensor(b))
        model.head[-1].weight.copy_(torch.tensor(head_w))
        model.head[-1].bias.copy_(torch.tensor(head_b))
    return model


def init_record(path: Path, member: int) -> dict:
    """Where a fine-tuned network started: the file, its checksum, the member, and that member's own training
    record (which names the data it was trained on before; `test_judge_net` follows this chain)."""
    record = json.loads(path.with_suffix(".json").read_text())
    members = record.get("ensemble_of")
    return {"weights": path.name, "sha256": hashlib.sha256(path.read_bytes()).hexdigest(), "member": member,
            "record": members[member]["record"] if members else record}


def freeze_norms(model: nn.Module) -> None:
    """Batch norms use their stored statistics (a fine-tuned member's, folded at export), never a batch's."""
    for m in model.modules():
        if isinstance(m, nn.BatchNorm2d):
            m.eval()


def augment(clip: Clip, rng: np.random.Generator) -> tuple[np.ndarray, tuple[float, float]]:
    """One augmented view of a clip: (12 frames, object position)."""
    base = np.round(np.linspace(0, DENSE - 1, JUDGE_FRAMES)).astype(int)
    idx = np.clip(base + rng.integers(-1, 2, JUDGE_FRAMES), 0, DENSE - 1)
    idx[0] = 0
    idx = np.maximum.accumulate(idx)
    if rng.random() < 0.2:  # a dropped frame: its neighbour repeated
        k = int(rng.integers(1, JUDGE_FRAMES))
        idx[k] = idx[k - 1]
    frames = clip.dense[idx].astype(np.float32)
    x, y = clip.object_px
    x, y = x + rng.normal(0, 2), y + rng.normal(0, 2)
    if rng.random() < 0.5:
        frames = frames[:, :, ::-1]
        x = 255.0 - x  # pixel centres at integers in the 256² frame
    gain = rng.uniform(0.85, 1.15) * rng.uniform(0.93, 1.07, 3)
    frames = np.clip(frames * gain + rng.uniform(-15, 15), 0, 255).astype(np.uint8)
    h, w = frames.shape[1:3]
    if rng.random() < 0.3:
        side = int(rng.choice([64, 96]))
        frames = np.stack([cv2.resize(cv2.resize(f, (side, side), interpolation=cv2.INTER_AREA), (w, h),
                                      interpolation=cv2.INTER_LINEAR) for f in frames])
    if rng.random() < 0.3:
        sigma = rng.uniform(0.5, 1.5)
        frames = np.stack([cv2.GaussianBlur(f, (0, 0), sigma) for f in frames])
    if rng.random() < 0.5:
        q = int(rng.integers(30, 90))
        frames = np.stack([cv2.imdecode(cv2.imencode(".jpg", np.ascontiguousarray(f),
                                                     [cv2.IMWRITE_JPEG_QUALITY, q])[1], cv2.IMREAD_UNCHANGED)
                           for f in frames])
    return np.ascontiguousarray(frames), (x, y)


def targets(clip: Clip) -> tuple[int, float, float]:
    """(label index or −1, agent 1/0/−1, object 1/0/−1); −1 = no target."""
    label = PRIMITIVES.index(clip.label) if clip.label else -1
    as_t = {None: -1.0, True: 1.0, False: 0.0}
    return label, as_t[clip.agent], as_t[clip.object]


def batch_of(clips: list[Clip], rng: np.random.Generator | None) -> tuple[torch.Tensor, torch.Tensor]:
    xs, ys = [], []
    for c in clips:
        frames, px = augment(c, rng) if rng is not None else (c.judge_frames(), c.object_px)
        xs.append(judge_input(frames, px)[0])
        ys.append(targets(c))
    return torch.from_numpy(np.stack(xs)), torch.tensor(ys, dtype=torch.float32)


def loss_of(out: torch.Tensor, y: torch.Tensor) -> torch.Tensor:
    label, agent, obj = y[:, 0].long(), y[:, 1], y[:, 2]
    n = len(PRIMITIVES)
    loss = torch.zeros(())
    if (label >= 0).any():
        loss = loss + nn.functional.cross_entropy(out[label >= 0, :n], label[label >= 0])
    for k, t in ((n, agent), (n + 1, obj)):
        m = t >= 0
        if m.any():
            loss = loss + nn.functional.binary_cross_entropy_with_logits(out[m, k], t[m])
    return loss


def data_digest(files: dict[str, str]) -> str:
    """SHA-256 over a release's data files and their checksums (release.json's `files`) without the card, the
    Croissant file and the build reports, which describe the build rather than its data (the card names the code
    commit; all three carry the build config, its seed among them): two builds of the same instances with the same
    toolchain give the same digest at any commit, so a rebuild can be checked against a record."""
    data = sorted((f, sha) for f, sha in files.items()
                  if f not in (CARD, CROISSANT) and Path(f).name != BUILD_REPORT)
    return hashlib.sha256(json.dumps(data).encode()).hexdigest()


def data_record(release: Path) -> dict:
    meta = json.loads((release / RELEASE_JSON).read_text())
    t5 = {c: i["build_config"] for c, i in sorted(meta["configs"].items()) if split_config(c)[0] in ("t4", "t5")}
    return {"release": release.name, "release_json_sha256": hashlib.sha256((release / RELEASE_JSON).read_bytes()).hexdigest(),
            "data_sha256": data_digest(meta["files"]),
            "configs": {c: {k: b[k] for k in ("count", "seed", "tasks", "primitives") if k in b} for c, b in t5.items()},
            "seed_range": sorted({b.get("seed_range", "") for b in t5.values()})}


def at_judge_size(clip: Clip) -> Clip:
    """The clip's frames at the judge's FRAME×FRAME, resized as `judge_input` resizes them (so an unaugmented clip
    gives the network the same input as at scoring time); augmentation then works at that size. A no-op on
    128×128 references (ManiSkill, LIBERO); ALOHA's 320×240 frames become 6.6× cheaper to augment."""
    if clip.dense.shape[1:3] != (FRAME, FRAME):
        clip.dense = at_frame_size(clip.dense)
    return clip


def load_clips(releases: list[Path], expert: bool = False, erased: bool = False) -> list[Clip]:
    """Every T4/T5 clip of the releases at the judge's frame size (with `expert`, the T5 source rollouts whose
    task's expert performs one primitive too: kind `expert`; with `erased`, the object-fades-away clips: kind
    `erased`); a clip found in more than one release (the same
    config, slot and scene seed: a bigger build of the same config contains a smaller one's instances) is used
    once. A clip is known by its kind, instance, task, scene seed and build seed: slot k's scene seed is the same in
    every build of a suite, so a build restricted to other tasks holds other clips. On the training range `--seed`
    does not key the scenes: a T5 build that differs only by it holds the same instances again (measured on
    LIBERO), which are then loaded twice; T4's seed draws other interventions on the same scenes."""
    kinds = T5_KINDS + (("expert",) if expert else ()) + (("erased",) if erased else ())
    clips, seen = [], set()
    for release in releases:
        meta = json.loads((release / RELEASE_JSON).read_text())
        for config, info in sorted(meta["configs"].items()):
            suite = split_config(config)[0]
            if suite not in ("t4", "t5"):
                continue
            seed_range = info["build_config"].get("seed_range")
            if seed_range != "train":
                sys.exit(f"{release}/{config}: built on the {seed_range or suite} seed range; the judge trains on "
                         "training-range seeds only (`wsp build --seed-range train`)")
            found = t5_clips(release, config, kinds) if suite == "t5" else t4_clips(release, config)
            build_seed = info["build_config"].get("seed", 0)
            new = [c for c in found if (c.kind, c.instance_id, c.task, c.seed, build_seed) not in seen]
            seen.update((c.kind, c.instance_id, c.task, c.seed, build_seed) for c in new)
            print(f"{release}/{config}: {len(new)} clips ({len(found) - len(new)} already loaded)", flush=True)
            clips += [at_judge_size(c) for c in new]
    return clips


def evaluate(model: nn.Module, clips: list[Clip]) -> dict:
    model.eval()
    right = {"label": [0, 0], "agent": [0, 0], "object": [0, 0]}
    with torch.no_grad():
        for i in range(0, len(clips), BATCH):
            x, y = batch_of(clips[i:i + BATCH], None)
            out = model(x)
            n = len(PRIMITIVES)
            for j in range(len(y)):
                if y[j, 0] >= 0:
                    right["label"][0] += int(out[j, :n].argmax() == y[j, 0])
                    right["label"][1] += 1
                for name, k, t in (("agent", n, y[j, 1]), ("object", n + 1, y[j, 2])):
                    if t >= 0:
                        right[name][0] += int((out[j, k] > 0) == (t > 0.5))
                        right[name][1] += 1
    return {k: f"{a}/{b}" for k, (a, b) in right.items()}


def export(model: nn.Module, path: Path, probe: list[Clip]) -> float:
    """ONNX export; the largest |torch − OpenCV dnn| output difference on `probe`."""
    model.eval()
    x, _ = batch_of(probe, None)
    path.parent.mkdir(parents=True, exist_ok=True)
    torch.onnx.export(model, (x[:1],), str(path), dynamo=False, opset_version=13, input_names=["clip"],
                      output_names=["logits"])
    net = cv2.dnn.readNetFromONNX(str(path))
    worst = 0.0
    with torch.no_grad():
        for i in range(len(x)):
            net.setInput(x[i:i + 1].numpy())
            worst = max(worst, float(np.abs(net.forward().reshape(-1) - model(x[i:i + 1]).numpy().reshape(-1)).max()))
    return worst


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("releases", type=Path, nargs="+", help="releases holding t5 configs built with --seed-range train")
    ap.add_argument("--out", type=Path, required=True, help="the .onnx file to write")
    ap.add_argument("--epochs", type=int, default=EPOCHS)
    ap.add_argument("--holdout", type=int, default=0, metavar="K",
                    help="development only: hold out every K-th run of 8 consecutive slots (all primitives; training-range "
                         "seeds still) and print its "
                         "accuracy every 5 epochs; the shipped judge trains on every clip (K = 0)")
    ap.add_argument("--exclude-tasks", nargs="+", default=[], metavar="TASK",
                    help="development only: train without these tasks' clips (a leave-task-out check of how the judge "
                         "does on tasks it never saw)")
    ap.add_argument("--expert", action="store_true",
                    help="also train on the task experts' own primitives (T5 source rollouts of the tasks in "
                         "wsp_eval.judge_data.EXPERT_PRIMITIVE, e.g. PullCube's pull); one of ManiSkill's two networks")
    ap.add_argument("--object-of", metavar="PRIMITIVE", nargs="+", choices=PRIMITIVES,
                    help="train an object verifier for these primitives (judge_net.OBJECT_WEIGHTS): only the object "
                         "output, on their T5 clips (references true; static, approach, frozen, erased false) and "
                         "every T4 reference (false); references repeated to weigh as much as the negatives "
                         "(ManiSkill's drop verifier)")
    ap.add_argument("--erased", nargs="?", const="all", choices=("all", "clear"),
                    help="also train on clips where the robot acts and the object fades out where it stood (kind "
                         "`erased`, object false): what world models often draw. `clear`: a negative only where its "
                         "reference shows the object visibly away from where it stood (`Clip.clear`), else no "
                         "object target (LIBERO's object verifier)")
    ap.add_argument("--init", type=Path, metavar="WEIGHTS.onnx",
                    help="fine-tune: start from a trained network (or member --init-member of an ensemble file) "
                         "instead of random weights, batch-norm statistics frozen as exported; use with a lower --lr "
                         "and fewer --epochs")
    ap.add_argument("--init-member", type=int, default=0, metavar="I", help="which member of the --init ensemble")
    ap.add_argument("--lr", type=float, default=LR, help="the one-cycle schedule's peak learning rate")
    ap.add_argument("--seed", type=int, default=SEED,
                    help="the initialisation, shuffling and augmentation seed; networks trained on the same data "
                         "with other seeds make an ensemble (LIBERO's versions 11 and 12: seeds 0, 1 and 2)")
    args = ap.parse_args()
    torch.manual_seed(args.seed)
    torch.set_num_threads(1)
    torch.use_deterministic_algorithms(True)
    cv2.setNumThreads(1)
    clips = [c for c in load_clips(args.releases, args.expert, bool(args.erased)) if c.task not in args.exclude_tasks]
    if args.erased == "clear":
        for c in clips:
            if c.kind == "erased" and not c.clear:
                c.object = None
    if not clips:
        sys.exit("no t5 configs found in " + ", ".join(map(str, args.releases)))
    repeat = 1
    if args.object_of:
        clips = [c for c in clips if (c.kind == "t4" or c.primitive in args.object_of) and c.object is not None]
        positives = sum(c.object is True for c in clips)
        negatives = sum((T4_REPEAT if c.kind == "t4" else 1) for c in clips if c.object is False)
        if not positives:
            sys.exit(f"no {' or '.join(args.object_of)} references in " + ", ".join(map(str, args.releases)))
        repeat = max(1, round(negatives / positives))
    held: list[Clip] = []
    if args.holdout:
        out_of = {c.instance_id for c in clips if int(c.instance_id.rsplit("/", 1)[1]) // 8 % args.holdout == 0}
        held = [c for c in clips if c.instance_id in out_of]
        clips = [c for c in clips if c.instance_id not in out_of]
    references = {p: sum(c.label == p for c in clips) for p in PRIMITIVES}
    if args.object_of:
        for c in clips + held:
            c.label, c.agent = None, None  # the object output alone is trained
    model = JudgeNet()
    if args.init:
        initialised(model, args.init, args.init_member)
    opt = torch.optim.AdamW(model.parameters(), lr=args.lr, weight_decay=WEIGHT_DECAY)
    pool = clips + [c for c in clips if c.kind == "t4"] * (T4_REPEAT - 1) + \
        [c for c in clips if c.kind == "reference"] * (repeat - 1)
    steps = args.epochs * ((len(pool) + BATCH - 1) // BATCH)
    sched = torch.optim.lr_scheduler.OneCycleLR(opt, max_lr=args.lr, total_steps=steps)
    rng = np.random.default_rng(args.seed)
    history, start = [], time.perf_counter()
    for epoch in range(args.epochs):
        model.train()
        if args.init:
            freeze_norms(model)
        order = rng.permutation(len(pool))
        total = 0.0
        for i in range(0, len(order), BATCH):
            x, y = batch_of([pool[k] for k in order[i:i + BATCH]], rng)
            loss = loss_of(model(x), y)
            opt.zero_grad()
            loss.backward()
            opt.step()
            sched.step()
            total += float(loss.detach()) * len(y)
        history.append(total / len(pool))
        print(f"epoch {epoch + 1}/{args.epochs}: loss {history[-1]:.4f} ({time.perf_counter() - start:.0f} s)",
              flush=True)
        if held and (epoch + 1) % 5 == 0:
            print(f"  held out: {evaluate(model, held)}", flush=True)
    train_acc = evaluate(model, clips)
    worst = export(model, args.out, clips[:16])
    record = {
        "weights": args.out.name, "sha256": hashlib.sha256(args.out.read_bytes()).hexdigest(),
        "data": [data_record(r) for r in args.releases],
        "clips": {k: sum(c.kind == k for c in clips) for k in sorted({c.kind for c in clips})},
        "references_per_primitive": references,
        "excluded_tasks": args.exclude_tasks, "expert": args.expert, "erased": args.erased, "object_of": args.object_of,
        "object_targets": {"true": sum(c.object is True for c in clips), "false": sum(c.object is False for c in clips)},
        "init": init_record(args.init, args.init_member) if args.init else None,
        "reference_repeat": repeat, "epochs": args.epochs, "t4_repeat": T4_REPEAT, "batch": BATCH, "lr": args.lr,
        "weight_decay": WEIGHT_DECAY, "seed": args.seed,
        "loss_per_epoch": [round(v, 5) for v in history], "train_accuracy_unaugmented": train_acc,
        "onnx_vs_torch_max_abs_diff": worst, "seconds": round(time.perf_counter() - start, 1),
        "torch": torch.__version__, "opencv": cv2.__version__,
    }
    args.out.with_suffix(".json").write_text(json.dumps(record, indent=1))
    print(json.dumps({k: record[k] for k in ("clips", "train_accuracy_unaugmented", "onnx_vs_torch_max_abs_diff",
                                             "seconds")}))


if __name__ == "__main__":
    main()
