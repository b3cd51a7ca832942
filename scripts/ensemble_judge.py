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
from onnx import helper

from wsp_eval.backends.judge_net import CHANNELS, SIDE


def merged(paths: list[Path]) -> onnx.ModelProto:
    """One graph: every member's nodes and weights (names prefixed m0_, m1_, …) on the shared input `clip`,
    their `logits` summed and scaled by 1/n into the output `logits`."""
    models = [onnx.load(str(p)) for p in paths]
    first = models[0].graph
    nodes, inits, outs = [], [], []
    for i, m in enumerate(models):
        g = m.graph
        if [x.name for x in g.input] != ["clip"] or [x.name for x in g.output] != ["logits"]:
            raise SystemExit(f"{paths[i]}: not a judge network (input 'clip', output 'logits')")
        rename = {t.name: f"m{i}_{t.name}" for t in g.initializer}
        for n in g.node:
            rename.update({o: f"m{i}_{o}" for o in n.output})
        for t in g.initializer:
            t = onnx.TensorProto.FromString(t.SerializeToString())
            t.name = rename[t.name]
            inits.append(t)
        for n in g.node:
            n = onnx.NodeProto.FromString(n.SerializeToString())
            n.name = f"m{i}_{n.name}"
            n.input[:] = [rename.get(x, x) for x in n.input]
            n.output[:] = [rename[x] for x in n.output]
            nodes.append(n)
        outs.append(rename["logits"])
    total = outs[0]
    for k, o in enumerate(outs[1:]):
        nodes.append(helper.make_node("Add", [total, o], [f"sum{k}"], name=f"sum{k}"))
        total = f"sum{k}"
    inits.append(helper.make_tensor("inv_n", onnx.TensorProto.FLOAT, [], [1.0 / len(models)]))
    nodes.append(helper.make_node("Mul", [total, "inv_n"], ["logits"], name="mean"))
    graph = helper.make_graph(nodes, "judge_ensemble", list(first.input), list(first.output), inits)
    model = helper.make_model(graph, opset_imports=list(models[0].opset_import), producer_name="ensemble_judge")
    onnx.checker.check_model(model)
    return model


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("members", type=Path, nargs="+", help="trained judge networks (.onnx), each with its .json")
    ap.add_argument("--out", type=Path, required=True)
    args = ap.parse_args()
    if len(args.members) < 2:
        ap.error("an ensemble needs at least two members")
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
