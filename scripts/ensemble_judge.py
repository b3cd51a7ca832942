"""Join trained judge networks into one ONNX file whose logits are their mean (an ensemble the `net` judge runs
like any other weights: one file, OpenCV's dnn, no torch).

    .venv/bin/python scripts/ensemble_judge.py A.onnx B.onnx --out wsp_eval/backends/weights/judge_net_vN_P.onnx

Each member keeps its own training record (`A.json`, `B.json`); the ensemble's record lists them, its checksum
and the largest |ensemble − mean of the members| on random inputs. Deterministic: the same members give the same
file.
"""

from __future__ import annotations

import argparse
import hashlib
import json
from pathlib import Path

import cv2
import numpy as np
import onnx
from onnx import helper, numpy_helper

from wsp_eval.backends.judge_net import CHANNELS, SIDE


def _judge_shaped(graph: onnx.GraphProto) -> bool:
    """Convolutions each followed by ReLU, then pool, flatten, linear: one network as `scripts/train_judge.py`
    exports it, or an ensemble as `merged` writes it."""
    ops = [n.op_type for n in graph.node]
    k = len(ops) - 3
    return k >= 2 and ops[:k] == ["Conv", "Relu"] * (k // 2) and ops[k:] == ["GlobalAveragePool", "Flatten", "Gemm"]


def _layers(path: Path, model: onnx.ModelProto) -> tuple[list[onnx.NodeProto], onnx.NodeProto, dict]:
    """A trained judge network's convolutions (each followed by ReLU, the first on `clip`) and its linear head,
    checked against the shape `scripts/train_judge.py` exports; and its weights by name."""
    g = model.graph
    if [x.name for x in g.input] != ["clip"] or [x.name for x in g.output] != ["logits"]:
        raise SystemExit(f"{path}: not a judge network (input 'clip', output 'logits')")
    ops = [n.op_type for n in g.node]
    grouped = any(_attributes(n).get("group", 1) != 1 for n in g.node if n.op_type == "Conv")  # an ensemble made here
    if grouped or not _judge_shaped(g):
        raise SystemExit(f"{path}: not one network as scripts/train_judge.py exports it (Conv, ReLU, …, pool, "
                         f"linear, ungrouped); got {', '.join(dict.fromkeys(ops))}. Give the single trained "
                         "networks, not an ensemble")
    return [n for n in g.node if n.op_type == "Conv"], g.node[-1], {t.name: numpy_helper.to_array(t)
                                                                    for t in g.initializer}


def _attributes(node: onnx.NodeProto) -> dict:
    return {a.name: helper.get_attribute_value(a) for a in node.attribute}


def merged(paths: list[Path]) -> onnx.ModelProto:
    """One network computing the mean of the members' logits, the members side by side: the first convolution's
    filters stacked (one convolution reads the clip once for all of them), the later ones grouped (member i's
    filters see only member i's channels), the linear heads joined into one that averages. The same arithmetic
    as running each member and averaging, up to float32 summation order; ≈ 13 % less network time than running
    them one after another, ≈ 10 % of a LIBERO clip's judging."""
    models = [onnx.load(str(p)) for p in paths]
    members = [_layers(p, m) for p, m in zip(paths, models)]
    depth = {len(convs) for convs, _, _ in members}
    if len(depth) != 1:
        raise SystemExit(f"{', '.join(map(str, paths))}: the members have different depths ({sorted(depth)})")
    n = len(members)
    nodes, inits, x = [], [], "clip"
    for k in range(depth.pop()):
        layer = [(convs[k], w) for convs, _, w in members]  # convolution k of every member, with its weights
        attributes = [_attributes(c) for c, _ in layer]
        if any(a != attributes[0] for a in attributes) or any(len(c.input) != 3 for c, _ in layer):
            raise SystemExit(f"convolution {k}: the members' shapes differ; they must come from one architecture")
        weight = np.concatenate([w[c.input[1]] for c, w in layer])
        bias = np.concatenate([w[c.input[2]] for c, w in layer])
        inits += [numpy_helper.from_array(weight, f"conv{k}.weight"), numpy_helper.from_array(bias, f"conv{k}.bias")]
        nodes += [helper.make_node("Conv", [x, f"conv{k}.weight", f"conv{k}.bias"], [f"conv{k}"], name=f"conv{k}",
                                   **{**attributes[0], "group": 1 if k == 0 else n}),
                  helper.make_node("Relu", [f"conv{k}"], [f"relu{k}"], name=f"relu{k}")]
        x = f"relu{k}"
    heads = [(head, w) for _, head, w in members]
    if any(_attributes(h) != {"alpha": 1.0, "beta": 1.0, "transB": 1} for h, _ in heads):
        raise SystemExit("the members' heads are not the linear layer scripts/train_judge.py exports")
    weight = np.concatenate([w[h.input[1]] for h, w in heads], axis=1) / np.float32(n)
    bias = np.mean([w[h.input[2]] for h, w in heads], axis=0, dtype=np.float32)
    inits += [numpy_helper.from_array(weight, "head.weight"), numpy_helper.from_array(bias, "head.bias")]
    nodes += [helper.make_node("GlobalAveragePool", [x], ["pool"], name="pool"),
              helper.make_node("Flatten", ["pool"], ["flat"], name="flat"),
              helper.make_node("Gemm", ["flat", "head.weight", "head.bias"], ["logits"], name="head", transB=1)]
    first = models[0].graph
    graph = helper.make_graph(nodes, "judge_ensemble", list(first.input), list(first.output), inits)
    model = helper.make_model(graph, opset_imports=list(models[0].opset_import), producer_name="ensemble_judge")
    model.ir_version = models[0].ir_version
    onnx.checker.check_model(model)
    return model


def member(path: Path, i: int) -> tuple[list[tuple[np.ndarray, np.ndarray]], np.ndarray, np.ndarray]:
    """Member `i` of a judge file, the inverse of `merged` (a single network is member 0): its convolutions'
    (weight, bias), batch norm folded in as exported, and its linear head's weight and bias. `merged` keeps only the
    mean of the members' head biases, so that mean is every member's bias here (10 numbers: what
    `scripts/train_judge.py --init` starts from, not a copy of the member)."""
    graph = onnx.load(str(path)).graph
    if not _judge_shaped(graph):
        raise SystemExit(f"{path}: not a judge network as scripts/train_judge.py or scripts/ensemble_judge.py writes "
                         f"it (Conv, ReLU, …, pool, linear); got {', '.join(dict.fromkeys(n.op_type for n in graph.node))}")
    weights = {t.name: numpy_helper.to_array(t) for t in graph.initializer}
    convs = [n for n in graph.node if n.op_type == "Conv"]
    groups = [_attributes(c).get("group", 1) for c in convs]
    n = groups[1]
    if groups[0] != 1 or any(g != n for g in groups[1:]):
        raise SystemExit(f"{path}: convolution groups {groups}: not one network or an ensemble written here")
    if not 0 <= i < n:
        raise SystemExit(f"{path}: holds {n} network(s); --init-member {i} is not one of them")
    layers = []
    for c in convs:
        w, b = weights[c.input[1]], weights[c.input[2]]
        rows = len(w) // n
        layers.append((w[i * rows:(i + 1) * rows], b[i * rows:(i + 1) * rows]))
    head = graph.node[-1]
    w, b = weights[head.input[1]], weights[head.input[2]]
    cols = w.shape[1] // n
    return layers, w[:, i * cols:(i + 1) * cols] * np.float32(n), b


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("members", type=Path, nargs="+", help="trained judge networks (.onnx), each with its .json")
    ap.add_argument("--out", type=Path, required=True)
    args = ap.parse_args()
    if len(args.members) < 2:
        ap.error("an ensemble needs at least two members")
    missing = [str(p.with_suffix(".json")) for p in args.members if not p.with_suffix(".json").is_file()]
    if missing:  # checked before anything is written: the ensemble's record is made of its members' records
        ap.error(f"no training record beside a member: {', '.join(missing)} (scripts/train_judge.py writes it; "
                 "copy a member's record along with its weights)")
    model = merged(args.members)
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_bytes(model.SerializeToString())
    x = np.random.default_rng(0).random((8, CHANNELS, SIDE, SIDE), dtype=np.float32)
    nets = [cv2.dnn.readNetFromONNX(str(p)) for p in [args.out, *args.members]]
    worst = 0.0
    for i in range(len(x)):
        outs = []
        for net in nets:
            net.setInput(x[i:i + 1])
            outs.append(net.forward().reshape(-1))
        worst = max(worst, float(np.abs(outs[0] - np.mean(outs[1:], axis=0)).max()))
    members = []
    for p in args.members:
        record = json.loads(p.with_suffix(".json").read_text())
        members.append({"weights": p.name, "sha256": hashlib.sha256(p.read_bytes()).hexdigest(), "record": record})
    record = {"weights": args.out.name, "sha256": hashlib.sha256(args.out.read_bytes()).hexdigest(),
              "ensemble_of": members, "ensemble_vs_member_mean_max_abs_diff": worst,
              "onnx_vs_torch_max_abs_diff": max(m["record"]["onnx_vs_torch_max_abs_diff"] for m in members),
              "data": [d for m in members for d in m["record"]["data"]], "opencv": cv2.__version__}
    args.out.with_suffix(".json").write_text(json.dumps(record, indent=1))
    print(json.dumps({k: record[k] for k in ("weights", "sha256", "ensemble_vs_member_mean_max_abs_diff")}))


if __name__ == "__main__":
    main()
