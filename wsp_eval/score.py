"""`wsp score`: a submission against a release → per-instance results → suite, group and overall scores with
95% bootstrap CIs (spec §6) → JSON, Markdown and HTML reports (`wsp_eval.report`).

- The release as published: every file of the scored configs is checked against its SHA-256 in `release.json`
  before anything is scored (`wsp_eval.integrity`; hashed once, remembered by size, mtime and inode); a mismatch
  stops scoring with the file. Each config's fingerprint (its verified content) is in the report and keys the
  reference caches. One `wsp score` at a time writes into an `--out` (`wsp_eval.folder_lock`).
- Seeds are averaged per instance before anything else; a suite score is the mean over instances (T5: over
  primitives of the mean within each), Overall = unweighted mean of a platform's T1–T5, and the macro average
  is the mean over platforms.
- CIs: `BOOTSTRAP` resamples of the instances (within groups for a balanced suite), percentile interval,
  fixed RNG seed; Overall and macro CIs combine the suites' resamples index by index.
- A missing or unusable video (missing, unreadable, not a video, over the size cap, wrong frame count, absurd
  fps, a resolution other than the reference's, or unlike its instance's other videos) is a *problem*, found per file in bounded memory. Without
  `allow_missing` a missing file stops scoring before it starts and a broken one stops it at the end (the
  finished instances are cached); with it, the seed of every affected instance scores 0 and the report
  counts and lists the problems.
- Encoding: a lossy or chroma-subsampled video, or one at another resolution than its reference's, is a problem
  (`wsp_eval.video.encoding_problem`, `submission.RESAMPLED`, docs/submission.md, Encodings); `accept_lossy` scores it
  anyway, and the report says the encoding check was off (such scores are not comparable with others: codec
  noise lowers T1 most, resampling T1–T3).
- Resumable: every finished instance is appended to `<out>/cache/instances.jsonl`; a re-run with the same
  submission, release, backends (names and versions) and `SCORING_VERSION` skips them (another key clears the cache).
- Parallel: instances are scored in `workers` spawned processes, each building its own backends (OpenCV
  single-threaded); or, with `executor="ray"`, as Ray tasks on a cluster (`wsp_eval.ray_tasks`; identical scores).
  Tasks carry paths, not videos: every node reads the release, the submission and the reference-flow cache at
  the same paths (a shared file system, or the same copy on each node), which is cheaper than shipping
  gigabytes of video through Ray's object store.
- The reference side is computed once per release and evaluator and reused by later scorings of any submission:
  RMFA's reference flows (T2, T3; `wsp_eval.flow_cache`) and T4's and T5's results on the reference
  (`wsp_eval.reference_cache`); `reference_cache=False` recomputes them. The copy check decodes a reference only
  until the video is known to differ from it.
"""

from __future__ import annotations

import hashlib
import json
import time
from concurrent.futures import ProcessPoolExecutor
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pyarrow.parquet as pq

from wsp_eval import backends as backend_registry
from wsp_eval import folder_lock
from wsp_eval.backends import BackendSpec, Backends
from wsp_eval.console import terminal
from wsp_eval.flow_cache import cache_dir
from wsp_eval.reference import reference_size
from wsp_eval.integrity import IntegrityError, release_json_sha256, verify
from wsp_eval.reference_cache import results_folder
from wsp_eval.release_format import INSTANCES, format_problem, load_release, split_config
from wsp_eval.submission import (SUBMISSION_JSON, Expected, check_sizes, load_video, named_configs, test_configs,
                                 validate)
from wsp_eval.suites import SCORERS
from wsp_eval.suites.reference import InstanceReference

REPORT_VERSION = 1
SCORING_VERSION = 30  # what the scores mean, in the report and the resume cache's key (a cache of another version is
#   discarded): bump it with every metric change and say in CHANGELOG.md what it does to scores
ENCODING_ON = "lossless at the reference resolution only"  # the report's `encoding_check`
ENCODING_OFF = "off (lossy or resampled videos scored)"
BOOTSTRAP = 1000  # resamples for the 95% CIs
COPY_MAD = 0.5  # grey levels: a video closer than this to its reference (mean absolute difference) equals it
COPY_SHARE = 0.9  # a submission whose videos equal their references this often is flagged as a probable copy
BOOTSTRAP_SEED = 0
CACHE = "cache/instances.jsonl"
CACHE_KEY = "cache/key.json"


class ScoreError(RuntimeError):
    """Scoring cannot go on; the message says why and what to do."""


@dataclass(frozen=True)
class Job:
    """One instance to score (what a worker process receives)."""

    release: str
    submission: str
    config: str
    row: dict
    seeds: tuple[int, ...]
    accept_lossy: bool = False
    flow_cache: str | None = None  # the release's reference-flow cache folder (`wsp_eval.flow_cache`), if used
    result_cache: str | None = None  # the suite's reference-result cache folder (`wsp_eval.reference_cache`), if used
    size: tuple[int, int] | None = None  # (H, W) of the config's reference video: the resolution required
    fingerprint: str = ""  # the config's verified content (`wsp_eval.integrity`): names its reference-cache entries


# -- one instance -----------------------------------------------------------------------------------------------
_BACKENDS: dict[tuple, Backends] = {}


def backends_for(spec: BackendSpec, needs: tuple[str, ...]) -> Backends:
    """The backends of `spec` for the roles `needs`, made once per process and shared by its instances."""
    key = (spec, needs)
    if key not in _BACKENDS:
        _BACKENDS[key] = backend_registry.make(spec, needs)
    return _BACKENDS[key]


def _load(path: Path, expected: Expected, rel: str, accept_lossy: bool) -> tuple[tuple[np.ndarray, float] | None, str | None]:
    if not path.is_file():
        return None, f"{rel}: missing"
    video, problems = load_video(path, expected, rel, accept_lossy=accept_lossy)
    return video, ("; ".join(map(str, problems)) or None)


def _load_seed(job: Job, seed: int) -> tuple[dict[str, tuple[np.ndarray, float]] | None, list[str]]:
    """One seed's videos by role, decoded one at a time (bounded: `load_video`), and their problems; None when
    one is missing or unusable or when they differ in resolution."""
    videos, rels, problems = {}, {}, []
    for role, episode_id, n in zip(job.row["roles"], job.row["episode_ids"], job.row["num_frames"]):
        exp = Expected(job.config, episode_id, seed, n, job.row["fps"], size=job.size)
        video, problem = _load(Path(job.submission) / exp.relpath, exp, exp.relpath, job.accept_lossy)
        if problem:
            problems.append(problem)
        else:
            videos[role], rels[role] = video, exp.relpath
    problems += map(str, check_sizes({rels[r]: v[0].shape[1:3] for r, v in videos.items()}))
    return (None if problems else videos), problems


def score_instance(job: Job, spec: BackendSpec) -> dict:
    """Score one instance over every seed: a JSON-ready record."""
    suite, platform = split_config(job.config)
    module = SCORERS[suite]
    backends = backends_for(spec, module.NEEDS)
    ref = InstanceReference(Path(job.release) / job.config, job.row,
                            flow_cache=Path(job.flow_cache) if job.flow_cache else None,
                            result_cache=Path(job.result_cache) if job.result_cache else None,
                            fingerprint=job.fingerprint)
    prepared = module.prepare(ref, backends)
    seeds, problems = [], []
    for seed in job.seeds:
        videos, found = _load_seed(job, seed)
        problems += found
        if videos is None:
            seeds.append({"seed": seed, "score": 0.0, "missing": True})
            continue
        score, detail = module.score_seed(prepared, videos, backends)
        seeds.append({"seed": seed, "score": float(score), **detail, "copy": _is_copy(ref, videos)})
    record = {"config": job.config, "suite": suite, "platform": platform, "instance_id": job.row["instance_id"],
              "task": job.row["task"], "score": float(np.mean([s["score"] for s in seeds])), "seeds": seeds,
              "problems": problems}
    if hasattr(module, "reference_check"):
        record["reference"] = module.reference_check(prepared)
    return record


def _is_copy(ref: InstanceReference, videos: dict[str, tuple[np.ndarray, float]]) -> bool:
    """Whether every video of a seed is its reference, frame for frame (mean absolute difference < COPY_MAD)."""
    return all(ref.equals(role, frames, COPY_MAD) for role, (frames, _) in videos.items())


def copy_check(records: list[dict]) -> dict:
    """How many scored videos equal their references; `probable_copy` when at least COPY_SHARE of them do."""
    seeds = [s for r in records for s in r["seeds"] if not s.get("missing")]
    copies = sum(bool(s.get("copy")) for s in seeds)
    return {"videos": len(seeds), "equal_to_reference": copies,
            "probable_copy": bool(seeds) and copies >= COPY_SHARE * len(seeds)}


def _worker(args: tuple[Job, BackendSpec]) -> dict:
    import cv2

    cv2.setNumThreads(1)
    return score_instance(*args)


# -- the run ----------------------------------------------------------------------------------------------------
def flow_cache_folder(release: Path, spec: BackendSpec, backends: Backends) -> str | None:
    """The release's reference-flow cache folder for this flow backend, or None (no flow backend, or nowhere to
    write)."""
    if backends.flow is None:
        return None
    folder = cache_dir(release, backends.flow.name, f"{backends.flow.version} {spec.flow_checkpoint or ''}")
    return str(folder) if folder else None


def result_cache_folder(release: Path, config: str, spec: BackendSpec, backends: Backends) -> str | None:
    """The reference-result cache folder of a config's suite (`backends`: built for at least its roles), or None:
    for a suite without reference-side results, or when a backend it uses may answer differently over time
    (`cacheable` False: a remote VLM)."""
    suite = split_config(config)[0]
    module = SCORERS[suite]
    if not module.REFERENCE_RESULTS:
        return None
    used = [getattr(backends, role) for role in module.NEEDS]
    if not all(getattr(b, "cacheable", True) for b in used):
        return None
    described = {role: d for role, d in backends.describe().items() if role in module.NEEDS}
    chosen = {k: v for k, v in spec.to_json().items() if k.split("_")[0] in module.NEEDS}  # role, checkpoint, …
    folder = results_folder(release, suite, described, chosen)
    return str(folder) if folder else None


def _rows(release: Path, config: str) -> list[dict]:
    return pq.read_table(release / config / INSTANCES).to_pylist()


def _cache_key(submission: Path, release: Path, spec: BackendSpec, backends: backend_registry.Backends,
               fingerprints: dict[str, str], accept_lossy: bool) -> dict:
    """What the resume cache's records depend on: the inputs (the configs by their verified content), the
    backends' names *and versions* (a retrained judge keeps its name) and the scoring version."""
    manifest = (submission / SUBMISSION_JSON).read_bytes()
    key = {"submission": hashlib.sha256(manifest).hexdigest(), "release": release_json_sha256(release),
           "backends": spec.to_json(), "versions": backends.describe(), "configs": list(fingerprints),
           "content": fingerprints, "scoring_version": SCORING_VERSION}
    return {**key, "accept_lossy": True} if accept_lossy else key


def _open_cache(out: Path, key: dict) -> dict[tuple[str, str], dict]:
    """Cached records of an earlier run with the same key; the cache is rewritten without a partial last line
    (a killed run's), so that the records appended next start on a line of their own."""
    key_path, cache = out / CACHE_KEY, out / CACHE
    cache.parent.mkdir(parents=True, exist_ok=True)
    if not key_path.is_file() or json.loads(key_path.read_text()) != key:
        cache.unlink(missing_ok=True)
        key_path.write_text(json.dumps(key, indent=1))
        return {}
    done = {}
    for line in cache.read_text().splitlines() if cache.is_file() else []:
        try:
            r = json.loads(line)
        except json.JSONDecodeError:
            continue
        done[(r["config"], r["instance_id"])] = r
    cache.write_text("".join(json.dumps(r) + "\n" for r in done.values()))
    return done


def _preflight(submission: Path, release: Path, allow_missing: bool) -> tuple[dict, list[str]]:
    """The manifest and the configs to score; missing files stop here unless allowed."""
    if not submission.is_dir():
        raise ScoreError(f"{submission}: submission folder not found")
    problems = validate(submission, release, check_videos=False, verify_release=False)  # verified already
    fatal = [p for p in problems if p.path == SUBMISSION_JSON or p.fatal]
    missing = [p for p in problems if p not in fatal and p.message == "missing"]
    if fatal:
        raise ScoreError("the submission is not scorable:\n  " + "\n  ".join(map(str, fatal)))
    if missing and not allow_missing:
        shown = "\n  ".join(map(str, missing[:20])) + (f"\n  … and {len(missing) - 20} more" if len(missing) > 20 else "")
        raise ScoreError(f"{len(missing)} video(s) missing:\n  {shown}\nrun `wsp validate` for every problem, or "
                         "score with --allow-missing (a missing rollout scores 0)")
    meta = json.loads((submission / SUBMISSION_JSON).read_text())
    return meta, meta.get("configs") or test_configs(release)


def score_submission(submission: Path, release: Path, out: Path, *, spec: BackendSpec = BackendSpec(),
                     workers: int = 1, allow_missing: bool = False, accept_lossy: bool = False,
                     progress: bool = True, reference_cache: bool = True, executor: str = "local",
                     address: str | None = None) -> dict:
    """Score `submission` against `release`; write the reports under `out`; return the report dict. Every
    release file of the scored configs is first checked against `release.json` (`wsp_eval.integrity`); `out` is
    held by this process alone (`wsp_eval.folder_lock`). With `reference_cache`, the reference side (RMFA's
    reference flows; T4's and T5's results on the reference) comes from (and goes to) the release's reference
    caches. `executor` "ray" scores on a Ray cluster (`address`, or a local instance with `workers` CPUs)."""
    submission, release, out = Path(submission), Path(release), Path(out)
    rel_meta = load_release(release)
    if (problem := format_problem(release, rel_meta)) is not None:
        raise ScoreError(problem)
    try:  # before anything reads a config's files (a config absent from the folder is the preflight's to name)
        fingerprints = verify(release, [c for c in named_configs(submission, release) if (release / c).is_dir()],
                              progress=progress)
    except IntegrityError as e:
        raise ScoreError(str(e)) from None
    meta, configs = _preflight(submission, release, allow_missing)
    needs = tuple(sorted({n for c in configs for n in SCORERS[split_config(c)[0]].NEEDS}))
    backends = backend_registry.make(spec, needs)  # fail fast on a missing checkpoint or endpoint
    try:
        with folder_lock.exclusive(out, "wsp score"):
            return _score_verified(submission, release, out, rel_meta, meta, configs, fingerprints, spec, backends,
                                   workers, allow_missing, accept_lossy, progress, reference_cache, executor, address)
    except folder_lock.FolderBusy as e:
        raise ScoreError(str(e)) from None


def _score_verified(submission: Path, release: Path, out: Path, rel_meta: dict, meta: dict, configs: list[str],
                    fingerprints: dict[str, str], spec: BackendSpec, backends: Backends, workers: int,
                    allow_missing: bool, accept_lossy: bool, progress: bool, reference_cache: bool, executor: str,
                    address: str | None) -> dict:
    from tqdm import tqdm

    from wsp_eval.report import write_reports
    from wsp_eval.strips import write_strips

    done = _open_cache(out, _cache_key(submission, release, spec, backends, fingerprints, accept_lossy))
    rows = {c: _rows(release, c) for c in configs}
    flows = flow_cache_folder(release, spec, backends) if reference_cache else None
    results = {c: result_cache_folder(release, c, spec, backends) if reference_cache else None for c in configs}
    sizes = {c: reference_size(release / c) for c in configs}
    todo = [Job(str(release), str(submission), c, r, tuple(meta["seeds"]), accept_lossy, flows, results[c], sizes[c],
                fingerprints[c]) for c in configs for r in rows[c] if (c, r["instance_id"]) not in done]
    start = time.perf_counter()
    bar = tqdm(total=len(todo) + len(done), initial=len(done), desc="scoring", unit="instance", disable=not progress,
               file=terminal())
    with open(out / CACHE, "a") as cache:
        def keep(record: dict) -> None:
            done[(record["config"], record["instance_id"])] = record
            cache.write(json.dumps(record) + "\n")
            cache.flush()
            bar.update()

        if executor == "ray":
            from wsp_eval.ray_tasks import ray_imap

            for record in ray_imap(_worker, [(j, spec) for j in todo], workers, address):
                keep(record)
        elif workers <= 1:
            for job in todo:
                keep(score_instance(job, spec))
        else:
            import multiprocessing as mp

            with ProcessPoolExecutor(workers, mp_context=mp.get_context("spawn")) as pool:
                for record in pool.map(_worker, [(j, spec) for j in todo], chunksize=1):
                    keep(record)
    bar.close()
    records = [done[(c, r["instance_id"])] for c in configs for r in rows[c]]
    problems = [p for r in records for p in r["problems"]]
    if problems and not allow_missing:
        raise ScoreError(f"{len(problems)} unusable video(s) (finished instances are cached):\n  "
                         + "\n  ".join(problems[:20]) + "\nfix them, or score with --allow-missing (they score 0)")
    report = aggregate(records, rows, configs)
    report.update(
        submission={"path": str(submission), "model": meta["model"], "seeds": meta["seeds"],
                    "hardware": meta.get("hardware"), "generation_seconds": meta.get("generation_seconds"),
                    **{k: meta[k] for k in ("model_server", "resampling") if isinstance(meta.get(k), dict)}},
        release={"path": str(release), "version": rel_meta["version"],
                 "code_version": str(rel_meta.get("code_version", "")),
                 "release_json_sha256": release_json_sha256(release),
                 "configs": {c: {"fingerprint": fingerprints[c]} for c in configs}},
        backends=backends.describe(), reference_flow_cache=flows,
        reference_result_cache={c: results[c] for c in configs if results[c]},
        allow_missing=allow_missing, encoding_check=ENCODING_OFF if accept_lossy else ENCODING_ON,
        problems=problems, copy_check=copy_check(records),
        timing={"seconds": time.perf_counter() - start, "workers": workers, "executor": executor,
                "instances": len(todo)},
        instances=records,
    )
    report["strips"] = write_strips(records, rows, release, submission, out)
    write_reports(report, out)
    return report


# -- aggregation ------------------------------------------------------------------------------------------------
def _ci(samples: np.ndarray) -> list[float] | None:
    return None if samples is None else [float(np.percentile(samples, 2.5)), float(np.percentile(samples, 97.5))]


def bootstrap_means(scores: np.ndarray, groups: list[str] | None, rng: np.random.Generator,
                    resamples: int = BOOTSTRAP) -> np.ndarray:
    """`resamples` resampled suite scores: plain means, or (balanced) means of per-group resampled means."""
    if groups is None:
        idx = rng.integers(0, len(scores), (resamples, len(scores)))
        return scores[idx].mean(axis=1)
    parts = []
    for g in dict.fromkeys(groups):
        s = scores[[i for i, x in enumerate(groups) if x == g]]
        parts.append(s[rng.integers(0, len(s), (resamples, len(s)))].mean(axis=1))
    return np.mean(parts, axis=0)


def _suite_score(scores: np.ndarray, groups: list[str], balanced: bool) -> float:
    if not balanced:
        return float(scores.mean())
    return float(np.mean([scores[[i for i, x in enumerate(groups) if x == g]].mean() for g in dict.fromkeys(groups)]))


def _group_rows(scores: np.ndarray, groups: list[str], rng: np.random.Generator) -> list[dict]:
    out = []
    for g in sorted(set(groups), key=lambda x: (not x.isdigit(), int(x) if x.isdigit() else 0, x)):
        s = scores[[i for i, x in enumerate(groups) if x == g]]
        out.append({"group": g, "score": float(s.mean()), "n": len(s),
                    "ci": _ci(bootstrap_means(s, None, rng)) if len(s) > 1 else None})
    return out


def _confusion(records: list[dict], rows: list[dict]) -> dict:
    from wsp_eval.backends.judge import PRIMITIVES

    labels = [p for p in PRIMITIVES if any(r["primitive"] == p for r in rows)]
    columns = list(PRIMITIVES) + ["unparsed"]
    matrix = [[0] * len(columns) for _ in labels]
    for rec, row in zip(records, rows):
        for s in rec["seeds"]:
            if not s.get("missing"):
                matrix[labels.index(row["primitive"])][columns.index(s["label"] or "unparsed")] += 1
    return {"labels": labels, "columns": columns, "matrix": matrix}


def aggregate(records: list[dict], rows: dict[str, list[dict]], configs: list[str]) -> dict:
    """The report's score part: platforms → suites (score, CI, n, groups) and Overall; the macro average."""
    rng = np.random.default_rng(BOOTSTRAP_SEED)
    by_config: dict[str, list[dict]] = {}
    for r in records:
        by_config.setdefault(r["config"], []).append(r)
    platforms: dict[str, dict] = {}
    samples: dict[str, dict[str, np.ndarray]] = {}
    for config in configs:
        suite, platform = split_config(config)
        module, recs = SCORERS[suite], by_config.get(config, [])
        if not recs:
            continue
        scores = np.array([r["score"] for r in recs])
        groups = module.groups(rows[config])
        boot = bootstrap_means(scores, groups if module.BALANCED else None, rng)
        entry = {"config": config, "title": module.TITLE, "score": _suite_score(scores, groups, module.BALANCED),
                 "ci": _ci(boot), "n": len(recs), "missing_rollouts": sum(s.get("missing", False) for r in recs
                                                                         for s in r["seeds"]),
                 "groups": {"by": module.GROUP_BY, "rows": _group_rows(scores, groups, rng)}}
        for rec, g in zip(recs, groups):
            rec["group"] = g
        if suite == "t5":
            entry["confusion"] = _confusion(recs, rows[config])
            checks = [r["reference"] for r in recs]
            entry["judge_agreement"] = 100.0 * float(np.mean([c["label"] == row["primitive"]
                                                              for c, row in zip(checks, rows[config])]))
            entry["judge_reference_score"] = float(np.mean([c["score"] for c in checks]))
            recognised = np.array([np.mean([s.get("recognised", 0.0) for s in r["seeds"]]) for r in recs])
            entry["primitive_recognised"] = _suite_score(recognised, groups, True)
        platforms.setdefault(platform, {"suites": {}})["suites"][suite] = entry
        samples.setdefault(platform, {})[suite] = boot
    for platform, p in platforms.items():
        suites = sorted(p["suites"])
        p["overall"] = {"score": float(np.mean([p["suites"][s]["score"] for s in suites])),
                        "ci": _ci(np.mean([samples[platform][s] for s in suites], axis=0)),
                        "suites": suites, "complete": set(suites) >= set(SCORERS)}
    names = sorted(platforms)
    macro = {"score": float(np.mean([platforms[p]["overall"]["score"] for p in names])) if names else None,
             "ci": _ci(np.mean([np.mean(list(samples[p].values()), axis=0) for p in names], axis=0)) if names else None,
             "platforms": names}
    return {"wsp_report_version": REPORT_VERSION, "scoring_version": SCORING_VERSION, "platforms": platforms,
            "macro_average": macro}
