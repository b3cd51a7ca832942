"""`wsp`: the WorldSimProbe command line.

The scoring commands are defined here. Other commands come from the `worldsimprobe.commands` entry-point group
as `Command`s (this distribution adds the build side's `build`, `sources` and `teleop` from
`wsp_data.commands`), and a plug-in command is loaded only when it is asked for: `wsp score` never runs
build-side code, and in the scoring-only install a build-side command stops with one line naming the extra.

    wsp build --platform maniskill --suite t1 --count N --out DIR   build (or resume) a config of a release
    wsp info DIR                                                     what a release holds
    wsp sources [--seeds N]                                          scripted expert success per task
    wsp validate SUBMISSION --release DIR                            check a submission, score nothing
    wsp verify DIR                                                   check every release file against release.json
    wsp baseline NAME --release DIR --out SUBMISSION                 write a calibration-baseline submission
    wsp generate --model MODULE:CALLABLE --release DIR --out SUB     run a model over a release → submission
    wsp generate --model ws://HOST:PORT --release DIR --out SUB      the same through a model server (`wsp-serve`)
    wsp score SUBMISSION --release DIR --out REPORT_DIR              score a submission: JSON, Markdown, HTML
    wsp calibrate --release DIR --out DIR                            every baseline, scored, in one table
    wsp teleop --task T --seed S --operator NAME                     browser teleoperation → source trajectory
    wsp study corruption --release DIR --out DIR                     RMFA under blur / texture removal (validity)
    wsp study t5-negatives --release DIR --out DIR                   T5 and the label judge on generated-video negatives
    wsp study t4-negatives --release DIR --out DIR                   T4 on objects moving without contact, and drawn blurred
    wsp rate SUB [SUB ...] --release DIR --annotator NAME --out DIR  human rating page on 127.0.0.1 (resumable)
    wsp study agreement --ratings DIR --reports REPORT [REPORT ...]  metrics against the human ratings
    wsp study coverage --release DIR --out DIR                       PCA of expert, counterfactual, source-diverse arm motion
    wsp study t1-response --release DIR --reports R [R ...] --out DIR  T1 response per magnitude, compression slope
    wsp study t2-mismatch --release DIR --reports R [R ...] --out DIR  T2 score against mismatch: Spearman ρ, deciles
    wsp study t3-sources --release DIR --reports R [R ...] --out DIR   T3 per source: late − early gap, operators' spread
    wsp study ordering --release DIR --reports R [R ...] --out DIR     Kendall τ of the suites against a known order
    wsp study idm-train --release DIR --platform P --out FILE        ridge inverse-dynamics model on train_<platform>
    wsp study idm --release DIR [--submission SUB] --out DIR         IDM action error per stream kind (a baseline)
    wsp leaderboard REPORT [REPORT ...] --out DIR                    models × suites with CIs and ties
    wsp export-inputs --release DIR --out DIR                        inputs-only release (private test sets)
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

from wsp_eval import console
from wsp_eval.command import CliError, Command, positive
from wsp_eval.registry import PluginError, Registry
from wsp_eval.release_format import DEFAULT_RELEASE_NAME, ReleaseError, load_release


COMMANDS: Registry[Command] = Registry("command", "worldsimprobe.commands")


# Modules that only an extra installs (`build`: simulators, LeRobot, `datasets`; `cluster`: Ray); the scoring-only
# install (`pip install worldsimprobe`) has none of them, and a command that needs one says so in one line.
BUILD_MODULES = frozenset({"sapien", "mani_skill", "mujoco", "robosuite", "libero", "lerobot", "datasets", "torch",
                           "huggingface_hub", "gymnasium", "OpenGL", "numba", "easydict", "filelock"})
EXTRA_OF_MODULE = {**dict.fromkeys(BUILD_MODULES, "build"), "ray": "cluster"}


ANALYSES = {  # `wsp study NAME` of the paper's analyses that read score reports (docs/analyses.md)
    "t1-response": "T1's relative response per perturbation magnitude, model against simulator, and the compression "
                   "slope",
    "t2-mismatch": "Spearman ρ between T2 instance score and receiver–donor mismatch, and the decile curve",
    "t3-sources": "T3 per source group: the late − early policy gap and the operators' spread",
    "ordering": "Kendall τ per suite between the reports' known order (worst first: e.g. checkpoints by training "
                "step) and their scores",
}


def parser(argv: list[str] | None = None) -> argparse.ArgumentParser:
    """`wsp`'s parser for the command line `argv`: the scoring commands, and the plug-in command `argv` names
    (the others are listed by name, loaded when used)."""
    p = argparse.ArgumentParser(prog="wsp", description="WorldSimProbe: build and inspect benchmark releases.")
    sub = p.add_subparsers(dest="command", required=True)
    asked = next((a for a in argv or [] if not a.startswith("-")), None)
    for name in COMMANDS:
        if name == asked:
            command = COMMANDS[name]
            c = sub.add_parser(name, help=command.help)
            command.add_arguments(c)
            c.set_defaults(run=command.run)
            continue
        try:  # no command named (`wsp --help`): every command's own help line
            text = COMMANDS[name].help if asked is None else f"see `wsp {name} --help`"
        except PluginError:
            text = f"see `wsp {name} --help`"
        sub.add_parser(name, help=text)
    i = sub.add_parser("info", help="summarise a release folder")
    i.add_argument("release", type=Path)
    v = sub.add_parser("validate", help="check a submission against a release without scoring it")
    v.add_argument("submission", type=Path)
    v.add_argument("--release", type=Path, default=Path(DEFAULT_RELEASE_NAME))
    ve = sub.add_parser("verify", help="check every file of a release against its sha256 in release.json")
    ve.add_argument("release", type=Path)
    ve.add_argument("--configs", nargs="+", help="only these configs (default: every config release.json lists)")
    ve.add_argument("--quiet", action="store_true", help="no progress bar")
    bl = sub.add_parser("baseline", help="write a calibration-baseline submission (oracle, static, action_blind, …)")
    bl.add_argument("name")
    bl.add_argument("--release", type=Path, default=Path(DEFAULT_RELEASE_NAME))
    bl.add_argument("--out", type=Path, required=True)
    bl.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2])
    g = sub.add_parser("generate", help="run a model (a callable, or a model server) over a release and write a "
                                        "submission")
    g.add_argument("--model", required=True, help="MODULE:CALLABLE taking (first_frame, actions, fps, seed), or a "
                                                   "batched one (README), or a registered name: reference, or "
                                                   "ws://HOST:PORT, a model server (`wsp-serve`)")
    g.add_argument("--name", help="model name for submission.json (default: the MODULE:CALLABLE, or the model "
                                  "server's model name)")
    g.add_argument("--release", type=Path, default=Path(DEFAULT_RELEASE_NAME))
    g.add_argument("--out", type=Path, required=True)
    g.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2])
    g.add_argument("--configs", nargs="+", help="only these configs (default: every scored config)")
    g.add_argument("--action-key", choices=("action", "action.ee", "action.joint"),
                   help="the native stream (default; a model server states its own) or the one stored beside it: "
                        "action.ee on ManiSkill and ALOHA, action.joint on LIBERO")
    g.add_argument("--timeout", type=float, default=1800.0,
                   help="with ws://: seconds to wait for one batch's reply (default 1800)")
    g.add_argument("--reconnect", type=float, default=120.0,
                   help="with ws://: seconds to keep retrying a lost or refused connection (default 120)")
    g.add_argument("--quiet", action="store_true")
    sc = sub.add_parser("score", help="score a submission against a release; write JSON, Markdown and HTML reports")
    sc.add_argument("submission", type=Path)
    sc.add_argument("--release", type=Path, default=Path(DEFAULT_RELEASE_NAME))
    sc.add_argument("--out", type=Path, required=True, help="report folder (also holds the resumable cache)")
    _score_options(sc)
    ca = sub.add_parser("calibrate", help="write every calibration baseline, score each, print one table")
    ca.add_argument("--release", type=Path, default=Path(DEFAULT_RELEASE_NAME))
    ca.add_argument("--out", type=Path, required=True, help="folder for the baseline submissions and reports")
    ca.add_argument("--baselines", nargs="+", help="default: all registered baselines")
    ca.add_argument("--seeds", type=int, nargs="+", default=[0])
    _score_options(ca)
    st = sub.add_parser("study", help="validity studies of the evaluators (docs/validity.md) and the paper's "
                                      "analyses (docs/analyses.md)")
    study = st.add_subparsers(dest="study", required=True)
    co = study.add_parser("corruption", help="RMFA drop under blur and texture removal, robot region vs background")
    co.add_argument("--release", type=Path, default=Path(DEFAULT_RELEASE_NAME))
    co.add_argument("--out", type=Path, required=True, help="folder for corruption.{json,md}, example.png (resumable)")
    co.add_argument("--config", help="T2 config (default: the release's first, e.g. t2_libero)")
    co.add_argument("--count", type=positive, default=50, help="references (default 50, as the paper)")
    co.add_argument("--seed", type=int, default=0, help="seed of the background regions and the bootstrap")
    co.add_argument("--quiet", action="store_true", help="no progress bar")
    for name, text, files in (
            ("t5-negatives", "T5 and the label judge on generated-video negatives made from the references (object "
                             "frozen, erased, early, late, reversed, scaled, teleported, another object moved)",
             "t5_negatives.{json,md,png}"),
            ("t4-negatives", "T4 on generated-video stand-ins: the object shifted, faded, carried or smeared without "
                             "contact (must score 0), or drawn blurred or noisy", "t4_negatives.{json,md}")):
        neg = study.add_parser(name, help=text)
        neg.add_argument("--release", type=Path, default=Path(DEFAULT_RELEASE_NAME))
        neg.add_argument("--out", type=Path, required=True, help=f"folder for {files}")
        neg.add_argument("--configs", nargs="+", help="configs of the suite (default: every one of the release)")
        neg.add_argument("--limit", type=positive, help="instances per config (default: all)")
        neg.add_argument("--quiet", action="store_true", help="no progress bar")
    ag = study.add_parser("agreement", help="Spearman ρ and binary agreement of scores with `wsp rate` ratings")
    ag.add_argument("--ratings", type=Path, required=True, help="the folder `wsp rate --out` wrote")
    ag.add_argument("--reports", type=Path, nargs="+", required=True, help="report folders (or report.json) of `wsp score`")
    ag.add_argument("--threshold", type=float, default=50.0, help="a score at or above it counts as positive (default 50)")
    ag.add_argument("--out", type=Path, help="also write agreement.json and agreement.md here")
    cv = study.add_parser("coverage", help="PCA of the arm motion of expert, counterfactual (T2) and source-diverse "
                                           "(T3) rollouts of one task per platform, with each set's spread")
    cv.add_argument("--release", type=Path, default=Path(DEFAULT_RELEASE_NAME))
    cv.add_argument("--out", type=Path, required=True, help="folder for coverage.{json,png}")
    cv.add_argument("--task", nargs="+", help="the task to plot on each platform that has it (default: the task of "
                                              "the platform's T3 config, else its first T2 task)")
    for name, text in ANALYSES.items():
        an = study.add_parser(name, help=text)
        an.add_argument("--release", type=Path, default=Path(DEFAULT_RELEASE_NAME))
        an.add_argument("--reports", type=Path, nargs="+", required=True,
                        help="report folders (or report.json) of `wsp score` against this release, one per model")
        an.add_argument("--out", type=Path, required=True, help=f"folder for {name.replace('-', '_')}.{{json,png}}")
    it = study.add_parser("idm-train", help="train the ridge inverse-dynamics model (flow features → action) on a "
                                            "platform's train split: a small JSON checkpoint")
    it.add_argument("--release", type=Path, default=Path(DEFAULT_RELEASE_NAME))
    it.add_argument("--platform", required=True)
    it.add_argument("--out", type=Path, required=True, help="the checkpoint file (JSON)")
    ie = study.add_parser("idm", help="the IDM's action error on simulator references of expert, early-policy and "
                                      "cross-task streams, and on a submission's videos (a baseline, not a score)")
    ie.add_argument("--release", type=Path, default=Path(DEFAULT_RELEASE_NAME))
    ie.add_argument("--checkpoint", type=Path, nargs="+", help="IDM checkpoints (default: the packaged ones)")
    ie.add_argument("--submission", type=Path, help="also evaluate this submission's generated videos (first seed)")
    ie.add_argument("--out", type=Path, required=True, help="folder for idm.json")
    ex = sub.add_parser("export-inputs", help="write an inputs-only release: first frames and actions, no reference")
    ex.add_argument("--release", type=Path, default=Path(DEFAULT_RELEASE_NAME))
    ex.add_argument("--out", type=Path, required=True, help="folder of the inputs-only release")
    ex.add_argument("--quiet", action="store_true", help="no progress bar")
    lb = sub.add_parser("leaderboard", help="models × (platform, suite, Overall) from score reports, ties marked")
    lb.add_argument("reports", type=Path, nargs="+", help="report folders (or report.json) of `wsp score`")
    lb.add_argument("--out", type=Path, required=True, help="folder for leaderboard.{md,html,json}")
    r = sub.add_parser("rate", help="serve the human rating page (generated beside reference, model hidden, 1–5)")
    r.add_argument("submissions", type=Path, nargs="+")
    r.add_argument("--release", type=Path, default=Path(DEFAULT_RELEASE_NAME))
    r.add_argument("--annotator", required=True, help="your name: ratings go to OUT/ratings_<name>.jsonl")
    r.add_argument("--out", type=Path, default=Path("ratings"), help="ratings folder (default ./ratings)")
    r.add_argument("--suites", nargs="+", default=["t2", "t3"], help="suites to rate (default t2 t3)")
    r.add_argument("--seeds", type=int, nargs="+", default=[0], help="generation seeds to rate (default 0)")
    r.add_argument("--per-config", type=positive, help="rate only the first N instances of each config")
    r.add_argument("--order-seed", type=int, default=0, help="seed of the presentation order (default 0)")
    r.add_argument("--port", type=int, default=8766, help="port on 127.0.0.1 (default 8766; 0 = any free port)")
    return p


def _score_options(p: argparse.ArgumentParser) -> None:
    from wsp_eval.backends import FLOW, JUDGE, TRACKER

    p.add_argument("--workers", type=positive, default=1, help="scoring processes (default 1)")
    p.add_argument("--executor", choices=("local", "ray"), default="local",
                   help="local processes (default) or ray (instances as Ray tasks; every node reads the release "
                        "and submission at the same paths)")
    p.add_argument("--address", help="with --executor ray: the cluster to join (`auto`, host:port); default: a "
                                     "local Ray instance with --workers CPUs")
    p.add_argument("--allow-missing", action="store_true", help="score missing or unusable videos as 0")
    p.add_argument("--accept-lossy", action="store_true",
                   help="score lossy or chroma-subsampled videos, and videos at another resolution than their "
                        "reference's, instead of refusing them (the report says so; such scores are not comparable: "
                        "codec noise lowers T1 most, resampling T1-T3)")
    p.add_argument("--flow", choices=FLOW, default="dis")
    p.add_argument("--no-reference-cache", action="store_true",
                   help="recompute the reference side (T2/T3 reference flows, T4/T5 results on the references) "
                        "instead of reusing the release's reference caches")
    p.add_argument("--flow-checkpoint", help="local checkpoint for --flow dpflow")
    p.add_argument("--tracker", choices=TRACKER, default="lk")
    p.add_argument("--tracker-checkpoint", help="local checkpoint for --tracker tapnext")
    p.add_argument("--judge", choices=JUDGE, default="net")
    p.add_argument("--judge-checkpoint", help="ONNX weights for --judge net (default: the packaged ones)")
    p.add_argument("--judge-url", help="OpenAI-compatible endpoint for --judge openai (e.g. http://127.0.0.1:8000/v1)")
    p.add_argument("--judge-model", help="model name served there (e.g. Qwen/Qwen3-VL-8B-Instruct)")
    p.add_argument("--quiet", action="store_true", help="no progress bar")


def cmd_info(args) -> int:
    from wsp_eval.release_info import describe

    try:
        print(describe(args.release))
    except ReleaseError as e:
        raise CliError(str(e)) from None
    return 0


def _release_or_error(path: Path) -> Path:
    """`path` when it holds a readable release, else CliError saying why."""
    try:
        load_release(path)
    except ReleaseError as e:
        raise CliError(str(e)) from None
    return path


def cmd_validate(args) -> int:
    from wsp_eval.submission import validate

    problems = validate(args.submission, _release_or_error(args.release))
    for p in problems:  # a release file's problem names it by its full path
        print(p if Path(p.path).is_absolute() else f"{args.submission}/{p}")
    print(f"{len(problems)} problem(s) in {args.submission}" if problems else f"{args.submission}: valid")
    return 1 if problems else 0


def cmd_verify(args) -> int:
    from wsp_eval.integrity import check, repair

    release = _release_or_error(args.release)
    prints, problems = check(release, args.configs, unlisted=True, progress=not args.quiet)
    for p in problems:
        print(f"{release / p.path}: {p.reason}")
    if problems:
        print(f"{len(problems)} file(s) of {release} differ from release.json, the release as built")
        for config in sorted({p.path.split("/", 1)[0] for p in problems}):
            print(f"  fix: {repair(release, config)}")
        return 1
    for config, fp in prints.items():
        print(f"{config}: fingerprint {fp[:16]}")
    print(f"{release}: every file of {len(prints)} config(s) matches release.json")
    return 0


def cmd_baseline(args) -> int:
    from wsp_eval.baselines import BaselineError, write_baseline

    try:
        n = write_baseline(args.name, _release_or_error(args.release), args.out, seeds=tuple(args.seeds), progress=True)
    except KeyError as e:
        raise CliError(e.args[0]) from None
    except BaselineError as e:
        raise CliError(str(e)) from None
    print(f"wrote {n} videos of baseline {args.name!r} to {args.out}")
    return 0


def cmd_generate(args) -> int:
    from wsp_eval.generate import GenerateError, generate, load_model
    from wsp_eval.model_client import generate_remote, is_server_url

    served = ""
    try:
        if is_server_url(args.model):
            result, hello = generate_remote(args.model, _release_or_error(args.release), args.out,
                                            seeds=tuple(args.seeds), configs=args.configs, name=args.name,
                                            action_key=args.action_key, progress=not args.quiet,
                                            timeout=args.timeout, reconnect=args.reconnect)
            served = f" by {hello.model} (version {hello.version}) at {args.model}"
        else:
            model = load_model(args.model)
            result = generate(model, _release_or_error(args.release), args.out, seeds=tuple(args.seeds),
                              configs=args.configs, name=args.name or args.model,
                              action_key=args.action_key or "action", progress=not args.quiet)
    except GenerateError as e:
        raise CliError(str(e)) from None
    print(f"{args.out}: {result.written} video(s) written{served}, {result.skipped} already there, "
          f"{result.seconds:.1f} s; check it with `wsp validate {args.out} --release {args.release}`")
    return 0


def _spec(args):
    from wsp_eval.backends import BackendSpec

    return BackendSpec(args.flow, args.tracker, args.judge, args.flow_checkpoint, args.tracker_checkpoint,
                       args.judge_url, args.judge_model, args.judge_checkpoint)


def _score(submission: Path, release: Path, out: Path, args) -> dict:
    from wsp_eval.backends.errors import BackendUnavailable
    from wsp_eval.score import ScoreError, score_submission

    try:
        return score_submission(submission, release, out, spec=_spec(args), workers=args.workers,
                                allow_missing=args.allow_missing, accept_lossy=args.accept_lossy,
                                progress=not args.quiet, reference_cache=not args.no_reference_cache,
                                executor=args.executor, address=args.address)
    except (ScoreError, BackendUnavailable) as e:
        raise CliError(str(e)) from None


def cmd_score(args) -> int:
    from wsp_eval.report import baseline_table

    with console.library_output_to(args.out / console.LOG_NAME):
        report = _score(args.submission, _release_or_error(args.release), args.out, args)
    print(baseline_table({report["submission"]["model"]: report}))
    print(f"\nreports: {args.out / 'report.md'}, {args.out / 'report.html'}, {args.out / 'report.json'}")
    return 0


def cmd_calibrate(args) -> int:
    from wsp_eval.baselines import BASELINES, BaselineError, write_baseline
    from wsp_eval.report import baseline_table

    release = _release_or_error(args.release)
    names = args.baselines or list(BASELINES)
    unknown = [n for n in names if n not in BASELINES]
    if unknown:
        raise CliError(f"unknown baseline(s) {', '.join(unknown)}; known: {', '.join(BASELINES)}")
    reports = {}
    with console.library_output_to(args.out / console.LOG_NAME):
        for name in names:
            sub = args.out / "submissions" / name
            try:
                write_baseline(name, release, sub, seeds=tuple(args.seeds), progress=not args.quiet)
            except BaselineError as e:
                raise CliError(str(e)) from None
            reports[name] = _score(sub, release, args.out / "reports" / name, args)
    from wsp_eval import leaderboard

    (args.out / "baselines.md").write_text(baseline_table(reports) + "\n")
    board = leaderboard.build([args.out / "reports" / name for name in names])
    leaderboard.write(board, args.out / "leaderboard")
    print(leaderboard.markdown(board))
    print(f"per-baseline reports (HTML with plots): {args.out / 'reports'}/<baseline>/report.html; table: "
          f"{args.out / 'baselines.md'}; leaderboard: {args.out / 'leaderboard' / 'leaderboard.html'}")
    return 0


def cmd_study(args) -> int:
    from wsp_eval.studies import agreement, corruption

    if args.study == "coverage" or args.study in ANALYSES:
        return run_analysis(args)
    if args.study in ("idm", "idm-train"):
        return run_idm(args)

    if args.study == "agreement":
        try:
            result = agreement.agreement(agreement.load_ratings(args.ratings), agreement.load_scores(args.reports),
                                         args.threshold)
        except agreement.AgreementError as e:
            raise CliError(str(e)) from None
        text = agreement.markdown(result)
        print(text)
        if args.out:
            args.out.mkdir(parents=True, exist_ok=True)
            (args.out / "agreement.json").write_text(json.dumps(result, indent=1))
            (args.out / "agreement.md").write_text(text)
        return 0

    if args.study in ("t4-negatives", "t5-negatives"):
        from wsp_eval.studies import StudyError, t4_negatives, t5_negatives

        study = t4_negatives if args.study == "t4-negatives" else t5_negatives
        try:
            summary = study.run(_release_or_error(args.release), args.out, configs=args.configs, limit=args.limit,
                                progress=not args.quiet)
        except StudyError as e:
            raise CliError(str(e)) from None
        print(study.markdown(summary))
        print("written: " + ", ".join(str(args.out / name) for name in study.OUTPUTS))
        return 0

    try:
        summary = corruption.run(_release_or_error(args.release), args.out, config=args.config, count=args.count,
                                 seed=args.seed, progress=not args.quiet)
    except corruption.StudyError as e:
        raise CliError(str(e)) from None
    print(corruption.markdown(summary, summary["config"]))
    print(f"written: {args.out / 'corruption.md'}, {args.out / 'corruption.json'}, {args.out / 'example.png'}")
    return 0


def run_analysis(args) -> int:
    """`wsp study coverage` and the ANALYSES: the study's table, and the files it wrote."""
    import importlib

    from wsp_eval.studies import StudyError

    study = importlib.import_module(f"wsp_eval.studies.{args.study.replace('-', '_')}")
    release = _release_or_error(args.release)
    try:
        result = (study.run(release, args.out, args.task) if args.study == "coverage"
                  else study.run(release, args.reports, args.out))
    except StudyError as e:
        raise CliError(str(e)) from None
    print(study.markdown(result))
    print("written: " + ", ".join(str(args.out / name) for name in study.OUTPUTS))
    return 0


def run_idm(args) -> int:
    """`wsp study idm-train` (a checkpoint) and `wsp study idm` (its action error)."""
    from wsp_eval.studies import StudyError, idm

    release = _release_or_error(args.release)
    try:
        if args.study == "idm-train":
            checkpoint = idm.train(release, args.platform)
            idm.save(checkpoint, args.out)
            print(f"IDM of {args.platform}: {checkpoint['samples']} frame pairs of {checkpoint['episodes']} episodes, "
                  f"train Micro-MSE {checkpoint['train_mse']:.4g}; written: {args.out}")
            return 0
        result = idm.run(release, args.checkpoint, args.out, args.submission)
    except StudyError as e:
        raise CliError(str(e)) from None
    print(idm.markdown(result))
    print("written: " + ", ".join(str(args.out / name) for name in idm.OUTPUTS))
    return 0


def cmd_export_inputs(args) -> int:
    from wsp_eval.inputs import ExportError, export_inputs

    try:
        manifest = export_inputs(_release_or_error(args.release), args.out, progress=not args.quiet)
    except ExportError as e:
        raise CliError(str(e)) from None
    n = sum(c["episodes"] for c in manifest["configs"].values())
    print(f"wrote the inputs of {n} episodes ({', '.join(manifest['configs'])}) to {args.out}: first frames and "
          f"actions only; scored against the release with release.json sha256 "
          f"{manifest['source_release_json_sha256'][:12]}")
    return 0


def cmd_leaderboard(args) -> int:
    from wsp_eval import leaderboard

    try:
        board = leaderboard.build(args.reports)
    except leaderboard.LeaderboardError as e:
        raise CliError(str(e)) from None
    leaderboard.write(board, args.out)
    print(leaderboard.markdown(board))
    print(f"leaderboard: {args.out / 'leaderboard.html'} (sortable), {args.out / 'leaderboard.md'}, "
          f"{args.out / 'leaderboard.json'}")
    return 0


def cmd_rate(args) -> int:
    from wsp_eval.studies.rating import RatingError, RatingServer, RatingSession, collect_items

    try:
        items, skipped = collect_items(_release_or_error(args.release), args.submissions, tuple(args.suites),
                                       tuple(args.seeds), args.per_config)
        session = RatingSession(args.release, items, args.out, args.annotator, args.order_seed)
        server = RatingServer(session, args.port)
    except (RatingError, OSError) as e:
        raise CliError(str(e)) from None
    for line in skipped[:5]:
        print(f"not rated: {line}")
    if len(skipped) > 5:
        print(f"… and {len(skipped) - 5} more videos missing")
    st = session.state()
    print(f"{st['total']} rollouts of {len(args.submissions)} submission(s), {st['rated']} already rated by "
          f"{args.annotator}; ratings: {session.path}")
    print(f"open {server.url} in a browser (Ctrl-C stops; re-run to resume)")
    try:
        server.serve_forever()
    finally:
        server.server_close()
    return 0


def main(argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else list(argv)
    try:
        args = parser(argv).parse_args(argv)
        commands = {"info": cmd_info, "validate": cmd_validate, "verify": cmd_verify, "baseline": cmd_baseline,
                    "generate": cmd_generate, "score": cmd_score, "calibrate": cmd_calibrate, "study": cmd_study,
                    "rate": cmd_rate, "leaderboard": cmd_leaderboard, "export-inputs": cmd_export_inputs}
        return args.run(args) if "run" in args else commands[args.command](args)
    except PluginError as e:
        missing = e.__cause__ if isinstance(e.__cause__, ModuleNotFoundError) else None
        if missing is None or _extra_needed(argv, missing) is None:
            print(f"wsp: error: {e}", file=sys.stderr)
        return 2
    except CliError as e:
        print(f"wsp: error: {e}", file=sys.stderr)
        _print_failure_hint()
        return 2
    except ModuleNotFoundError as e:
        if _extra_needed(argv, e) is None:
            raise
        return 2
    except KeyboardInterrupt:
        print("wsp: interrupted; finished work is kept (staged instances, written videos, cached scores): re-run "
              "the same command to resume", file=sys.stderr)
        return 130
    except Exception:
        _print_failure_hint()
        raise


def _extra_needed(argv: list[str], e: ModuleNotFoundError) -> str | None:
    """The extra that installs the module `e` misses, after saying so in one line; None for another module."""
    extra = EXTRA_OF_MODULE.get((e.name or "").split(".")[0])
    if extra is not None:
        command = next((a for a in argv if not a.startswith("-")), "")
        print(f"wsp: error: `wsp {command}` needs the {extra} extra (missing module {e.name!r}): "
              f"pip install 'worldsimprobe[{extra}]' — or `make setup`, which also installs LIBERO's stack",
              file=sys.stderr)
    return extra


def _print_failure_hint() -> None:
    hint = console.failure_hint()
    if hint:
        print(hint, file=sys.stderr)


if __name__ == "__main__":
    sys.exit(main())
