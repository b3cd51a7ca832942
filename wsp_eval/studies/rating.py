"""`wsp rate`: the paper's human rating study, served as a local page (127.0.0.1).

Items are (submission, config, instance, seed) of the chosen suites (default T2 and T3, the action-following
suites the paper rated). The page shows the generated rollout beside its simulator reference, played in step,
never the model's name, in an order randomised per annotator (seeded), and takes one rating per item on the
paper's 1–5 scale:

  1–2  the generated robot does not follow the reference action / motion;
  3    the robot action is followed, even if the environment responds differently;
  4–5  increasingly close agreement in both robot motion and environment response.

Ratings are appended, one JSON line per rating, to `<out>/ratings_<annotator>.jsonl` (the model name is kept
there, never sent to the page); restarting with the same arguments resumes at the first unrated item.
`wsp study agreement` (`wsp_eval.studies.agreement`) compares them with score reports.
"""

from __future__ import annotations

import hashlib
import json
import re
import threading
from dataclasses import asdict, dataclass
from datetime import datetime, timezone
from http.server import ThreadingHTTPServer
from pathlib import Path

import cv2
import numpy as np
import pyarrow.parquet as pq

from wsp_eval.local_http import JsonRequestHandler
from wsp_eval.reference import reference_frames
from wsp_eval.release_format import INSTANCES, load_release, split_config
from wsp_eval.submission import SUBMISSION_JSON, Expected
from wsp_eval.video import VideoError, read_video

PAGE = Path(__file__).with_name("rating_page.html")
DEFAULT_SUITES = ("t2", "t3")
RATINGS = "ratings_{annotator}.jsonl"
SPRITE_COLUMNS = 10
MAX_BODY = 4096


class RatingError(RuntimeError):
    """Bad arguments or a bad request (shown to the user or the page, never a traceback)."""


@dataclass(frozen=True)
class Item:
    """One rollout to rate; `item_id` is all the page sees of it."""

    item_id: str
    model: str
    submission: str
    config: str
    instance_id: str
    episode_id: str
    seed: int
    num_frames: int
    fps: float
    episode_index: int


def annotator_slug(name: str) -> str:
    slug = re.sub(r"[^A-Za-z0-9_-]+", "_", name.strip()).strip("_")
    if not slug:
        raise RatingError(f"annotator name {name!r} has no letters or digits")
    return slug


def _model(submission: Path) -> str:
    try:
        model = json.loads((submission / SUBMISSION_JSON).read_text())["model"]
    except (OSError, ValueError, KeyError, TypeError) as e:
        raise RatingError(f"{submission}: not a submission ({SUBMISSION_JSON} unreadable or without 'model': {e})"
                          ) from None
    return str(model)


def collect_items(release: Path, submissions: list[Path], suites: tuple[str, ...] = DEFAULT_SUITES,
                  seeds: tuple[int, ...] = (0,), per_config: int | None = None) -> tuple[list[Item], list[str]]:
    """Every (submission, instance, seed) of the suites' configs whose generated video exists (the first
    `per_config` instances of each config by id when given), and a line per video left out."""
    configs = sorted(c for c in load_release(release)["configs"] if split_config(c)[0] in suites)
    if not configs:
        raise RatingError(f"{release}: no config of suite(s) {', '.join(suites)}")
    items, skipped = [], []
    models = {}
    for sub in submissions:
        model = _model(sub)
        if model in models:
            raise RatingError(f"{sub} and {models[model]} both name their model {model!r}; ratings could not tell "
                              "them apart")
        models[model] = sub
    for config in configs:
        rows = sorted(pq.read_table(release / config / INSTANCES).to_pylist(), key=lambda r: r["instance_id"])
        for row in rows[:per_config]:
            k = row["roles"].index("reference")
            for model, sub in models.items():
                for seed in seeds:
                    exp = Expected(config, row["episode_ids"][k], seed, row["num_frames"][k], row["fps"])
                    if not (sub / exp.relpath).is_file():
                        skipped.append(f"{sub / exp.relpath}: missing")
                        continue
                    key = f"{model}|{config}|{exp.episode_id}|{seed}".encode()
                    items.append(Item(hashlib.sha256(key).hexdigest()[:16], model, str(sub), config,
                                      row["instance_id"], exp.episode_id, seed, exp.num_frames, float(row["fps"]),
                                      row["episode_indices"][k]))
    return items, skipped


def sprite(frames: np.ndarray) -> bytes:
    """All frames of a video tiled SPRITE_COLUMNS wide in one PNG (the page draws one tile per step)."""
    n, h, w = frames.shape[:3]
    rows = -(-n // SPRITE_COLUMNS)
    sheet = np.zeros((rows * h, SPRITE_COLUMNS * w, 3), np.uint8)
    for i, f in enumerate(frames):
        r, c = divmod(i, SPRITE_COLUMNS)
        sheet[r * h:(r + 1) * h, c * w:(c + 1) * w] = f
    ok, png = cv2.imencode(".png", cv2.cvtColor(sheet, cv2.COLOR_RGB2BGR))
    return png.tobytes()


class RatingSession:
    """One annotator's pass over the items: order, saved ratings, media."""

    def __init__(self, release: Path, items: list[Item], out: Path, annotator: str, seed: int = 0):
        if not items:
            raise RatingError("nothing to rate: no generated video found for the chosen suites and seeds")
        self.release, self.out, self.annotator = Path(release), Path(out), annotator
        slug = annotator_slug(annotator)
        self.out.mkdir(parents=True, exist_ok=True)
        self.path = self.out / RATINGS.format(annotator=slug)
        digest = int(hashlib.sha256(slug.encode()).hexdigest()[:8], 16)
        order = np.random.default_rng([seed, digest]).permutation(len(items))
        self.items = [items[i] for i in order]
        self.by_id = {it.item_id: it for it in self.items}
        self.rated: dict[str, int] = {}
        if self.path.exists():
            for n, line in enumerate(self.path.read_text().splitlines(), 1):
                try:
                    rec = json.loads(line)
                    self.rated[rec["item_id"]] = int(rec["rating"])
                except (ValueError, KeyError, TypeError):
                    raise RatingError(f"{self.path}, line {n}: not a rating record") from None
        self._lock = threading.Lock()

    def state(self) -> dict:
        """What the page needs: progress and the next item (opaque id, frame count, fps) or none left."""
        nxt = next((it for it in self.items if it.item_id not in self.rated), None)
        out = {"annotator": self.annotator, "rated": sum(i in self.rated for i in self.by_id),
               "total": len(self.items), "ratings_file": str(self.path)}
        if nxt is not None:
            out["item"] = {"item_id": nxt.item_id, "num_frames": nxt.num_frames, "fps": nxt.fps,
                           "columns": SPRITE_COLUMNS}
        return out

    def media(self, item_id: str, which: str) -> bytes:
        it = self.by_id.get(item_id)
        if it is None or which not in ("generated", "reference"):
            raise RatingError(f"no media {which!r} for item {item_id!r}")
        if which == "reference":
            frames = reference_frames(self.release / it.config, it.episode_index)
        else:
            path = Path(it.submission) / Expected(it.config, it.episode_id, it.seed, it.num_frames, it.fps).relpath
            try:
                frames, _ = read_video(path, max_frames=it.num_frames, lossless=False)
            except VideoError as e:
                raise RatingError(f"the generated video cannot be shown: {e}") from None
        return sprite(frames)

    def rate(self, item_id: str, rating) -> dict:
        it = self.by_id.get(item_id)
        if it is None:
            raise RatingError(f"unknown item {item_id!r}")
        if isinstance(rating, bool) or not isinstance(rating, int) or not 1 <= rating <= 5:
            raise RatingError(f"a rating is a whole number from 1 to 5, got {rating!r}")
        rec = {**asdict(it), "annotator": self.annotator, "rating": rating,
               "time": datetime.now(timezone.utc).isoformat(timespec="seconds")}
        with self._lock, open(self.path, "a") as f:
            f.write(json.dumps(rec) + "\n")
            self.rated[item_id] = rating
        return self.state()


class RatingServer(ThreadingHTTPServer):
    """The rating page and its API on 127.0.0.1:`port` (0 = any free port)."""

    daemon_threads = True

    def __init__(self, session: RatingSession, port: int = 0):
        self.session = session
        self.page = PAGE.read_bytes()
        super().__init__(("127.0.0.1", int(port)), _Handler)

    @property
    def url(self) -> str:
        return f"http://127.0.0.1:{self.server_address[1]}/"


class _Handler(JsonRequestHandler):
    server: RatingServer

    def do_GET(self) -> None:  # noqa: N802
        path = self.path.split("?", 1)[0]
        try:
            if path in ("/", "/index.html"):
                self._send(200, self.server.page, "text/html; charset=utf-8")
            elif path == "/state":
                self._json(self.server.session.state())
            elif m := re.fullmatch(r"/media/([0-9a-f]{16})/(generated|reference)\.png", path):
                self._send(200, self.server.session.media(m[1], m[2]), "image/png")
            else:
                self._json({"error": f"no such page {path!r}"}, 404)
        except RatingError as e:
            self._json({"error": str(e)}, 400)

    def do_POST(self) -> None:  # noqa: N802
        path = self.path.split("?", 1)[0]
        try:
            body = self._json_body(MAX_BODY, RatingError)
            if path != "/rate":
                raise RatingError(f"expected POST /rate, got {path!r}")
            self._json(self.server.session.rate(str(body.get("item_id")), body.get("rating")))
        except RatingError as e:
            self._json({"error": str(e)}, 400)
