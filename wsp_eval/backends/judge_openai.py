"""The optional VLM primitive judge (spec §4.6): a model served behind any OpenAI-compatible
`POST {base_url}/chat/completions` endpoint (vLLM, Ollama), as the paper runs Qwen3-VL-8B: greedy decoding,
12 frames, the eight primitive specifications, a strict JSON answer.

One request per clip: the frames go as lossless PNG data URLs, the object's frame-0 position is converted
from the 256×256 scoring frame into the frames' own pixels (same pixel-centre convention as
`wsp_eval.tracking`). The prompt never names the intended label, the action stream or the evaluated model.
Requests go straight to `base_url` (environment proxies are ignored); nothing is downloaded.
An unreachable server or an HTTP error raises `JudgeUnavailable`; a bad answer is an unparseable `Verdict`.
"""

from __future__ import annotations

import base64
import http.client
import io
import json
import re
import time
import urllib.error
import urllib.parse
import urllib.request

import numpy as np
from PIL import Image

from wsp_eval.backends.errors import BackendUnavailable
from wsp_eval.backends.judge import JUDGE_FRAMES, PRIMITIVE_SPECS, PRIMITIVES, Verdict
from wsp_eval.tracking import frame_xy

MAX_TOKENS = 200  # the JSON answer needs ~40 tokens
RETRY_BACKOFF_S = 1.0  # first wait before retrying a transient failure; doubles each retry
RETRY_STATUSES = frozenset({408, 429, 500, 502, 503, 504})
ANSWER_KEYS = ("label", "agent_motion_matches", "object_motion_matches")
SYSTEM_PROMPT = ("You are a careful annotator of robot manipulation videos. "
                 "You answer with a single JSON object and nothing else.")
_BOOLEAN_WORDS = {"true": True, "yes": True, "false": False, "no": False}
_THINK = re.compile(r"<think>.*?</think>", re.DOTALL | re.IGNORECASE)
_NO_PROXY = urllib.request.build_opener(urllib.request.ProxyHandler({}))


class JudgeUnavailable(BackendUnavailable):
    """The judge's endpoint could not be reached or answered with an HTTP error."""


def prompt_text(object_xy_in_frame: tuple[float, float], frame_size: tuple[int, int]) -> str:
    """The user-message text: task, object position in the frames' own pixels, specifications, answer format."""
    (x, y), (width, height) = object_xy_in_frame, frame_size
    specs = "\n".join(f"- {name}: {PRIMITIVE_SPECS[name]}" for name in PRIMITIVES)
    return (
        f"You see {JUDGE_FRAMES} frames sampled uniformly in time from one video of a robot arm acting on objects "
        f"on a table, in temporal order (frame 1 first, frame {JUDGE_FRAMES} last). Each frame is "
        f"{width}×{height} pixels. The object of interest is at pixel (x, y) = ({x:.0f}, {y:.0f}) of frame 1, "
        "in that frame's own pixel coordinates (x to the right, y downward, origin at the top-left corner).\n\n"
        "Decide which one of these eight manipulation primitives the robot performs on that object:\n"
        f"{specs}\n\n"
        "Then judge separately whether the robot's (gripper's) motion matches the specification of the primitive "
        "you chose, and whether the object's motion matches it. If no primitive clearly happens, still choose "
        "the closest one and answer false where the motion does not match.\n\n"
        "Answer with strict JSON only, no other text:\n"
        f'{{"label": "<one of: {", ".join(PRIMITIVES)}>", '
        '"agent_motion_matches": true or false, "object_motion_matches": true or false}'
    )


def _unparseable(text: str, why: str) -> Verdict:
    return Verdict(None, False, False, {"raw": text, "error": why})


def _first_object(text: str) -> dict | None:
    """The first `{...}` in `text` that parses as a JSON object."""
    decoder = json.JSONDecoder()
    for start in (m.start() for m in re.finditer(r"\{", text)):
        try:
            value, _ = decoder.raw_decode(text, start)
        except json.JSONDecodeError:
            continue
        if isinstance(value, dict):
            return value
    return None


def _label(value: object) -> str | None:
    """A primitive name, case-insensitive, with spaces/underscores as hyphens and "knockover" → "knock-over"."""
    if not isinstance(value, str):
        return None
    name = re.sub(r"[\s_-]+", "-", value.strip().strip(".").lower())
    name = "knock-over" if name == "knockover" else name
    return name if name in PRIMITIVES else None


def _boolean(value: object) -> bool | None:
    """A JSON boolean or a "yes"/"no"/"true"/"false" string; None otherwise."""
    if isinstance(value, bool):
        return value
    return _BOOLEAN_WORDS.get(value.strip().lower()) if isinstance(value, str) else None


def parse_answer(text: str) -> Verdict:
    """The judge's answer → Verdict; anything unparseable → label None (scores 0). Never raises."""
    answer = _first_object(_THINK.sub("", text))
    if answer is None:
        return _unparseable(text, "no JSON object in the answer")
    missing = [key for key in ANSWER_KEYS if key not in answer]
    if missing:
        return _unparseable(text, f"missing keys: {', '.join(missing)}")
    label = _label(answer["label"])
    if label is None:
        return _unparseable(text, f"unknown label {answer['label']!r}")
    agent_ok, object_ok = _boolean(answer["agent_motion_matches"]), _boolean(answer["object_motion_matches"])
    if agent_ok is None or object_ok is None:
        return _unparseable(text, "agent_motion_matches/object_motion_matches are not booleans")
    return Verdict(label, agent_ok, object_ok, {"raw": text})


def png_data_url(frame: np.ndarray) -> str:
    """(H, W, 3) uint8 RGB → a `data:image/png;base64,...` URL (lossless)."""
    buffer = io.BytesIO()
    Image.fromarray(frame, "RGB").save(buffer, format="PNG")
    return "data:image/png;base64," + base64.b64encode(buffer.getvalue()).decode("ascii")


def _content(response: object) -> str | None:
    """choices[0].message.content as text (string or list of text parts); None when absent."""
    try:
        content = response["choices"][0]["message"]["content"]
    except (KeyError, IndexError, TypeError):
        return None
    if isinstance(content, list):
        content = "".join(p.get("text", "") for p in content if isinstance(p, dict)) or None
    return content if isinstance(content, str) else None


class OpenAIJudge:
    """A primitive judge asking a VLM behind an OpenAI-compatible chat-completions endpoint."""

    name = "openai"
    cacheable = False  # a remote model may answer differently behind the same name: verdicts are never reused

    def __init__(self, base_url: str, model: str, api_key: str | None = None, timeout: float = 120.0,
                 max_retries: int = 2):
        if urllib.parse.urlsplit(base_url).scheme not in ("http", "https"):
            raise ValueError(f"base_url must be an http(s) URL such as http://localhost:8000/v1, got {base_url!r}")
        if max_retries < 0:
            raise ValueError(f"max_retries must be ≥ 0, got {max_retries}")
        self.base_url = base_url.rstrip("/")
        self.model = model
        self.api_key = api_key
        self.timeout = timeout
        self.max_retries = max_retries
        self.version = f"{model}@{self.base_url}"

    def judge(self, frames: np.ndarray, object_px: tuple[float, float], platform: str | None = None) -> Verdict:
        """Ask the served model about one clip's 12 frames; `object_px` is the frame-0 (x, y) in the 256² frame.
        The prompt is the paper's, the same on every platform (`platform` is not used)."""
        frames = np.asarray(frames)
        if frames.ndim != 4 or frames.shape[0] != JUDGE_FRAMES or frames.shape[3] != 3 or frames.dtype != np.uint8:
            raise ValueError(f"expected ({JUDGE_FRAMES}, H, W, 3) uint8 frames, got {frames.shape} {frames.dtype}")
        height, width = frames.shape[1:3]
        text = prompt_text(frame_xy(object_px, width, height), (width, height))
        images = [{"type": "image_url", "image_url": {"url": png_data_url(f)}} for f in frames]
        body = {
            "model": self.model,
            "messages": [{"role": "system", "content": SYSTEM_PROMPT},
                         {"role": "user", "content": [{"type": "text", "text": text}, *images]}],
            "temperature": 0,
            "max_tokens": MAX_TOKENS,
        }
        raw = self._request("/chat/completions", body)
        try:
            response = json.loads(raw)
        except ValueError:
            return _unparseable(raw.decode("utf-8", "replace")[:2000], "the response body is not JSON")
        content = _content(response)
        if content is None:
            return _unparseable(json.dumps(response)[:2000], "no choices[0].message.content in the response")
        return parse_answer(content)

    def ping(self) -> list[str]:
        """GET {base_url}/models: fail fast (JudgeUnavailable) before scoring; returns the served model ids."""
        try:
            listing = json.loads(self._request("/models"))
            served = [m["id"] for m in listing["data"]]
        except (ValueError, KeyError, TypeError) as error:
            raise self._unavailable(f"{self.base_url}/models did not answer with a model list ({error!r})") from None
        if self.model not in served:
            raise self._unavailable(f"model {self.model!r} is not served there; served: {', '.join(served) or 'none'}")
        return served

    def _request(self, path: str, body: dict | None = None) -> bytes:
        """GET (no body) or POST JSON to base_url + path, retrying transient failures; the raw response body."""
        url = self.base_url + path
        data = None if body is None else json.dumps(body).encode()
        headers = {"Content-Type": "application/json"}
        if self.api_key:
            headers["Authorization"] = f"Bearer {self.api_key}"
        for attempt in range(self.max_retries + 1):
            try:
                with _NO_PROXY.open(urllib.request.Request(url, data, headers), timeout=self.timeout) as reply:
                    return reply.read()
            except urllib.error.HTTPError as error:
                detail = error.read()[:500].decode("utf-8", "replace").strip()
                failure = f"{url} answered HTTP {error.code} {error.reason}: {detail}"
                if error.code not in RETRY_STATUSES:
                    break
            except (OSError, http.client.HTTPException) as error:
                failure = f"cannot reach {url} ({getattr(error, 'reason', error)!r})"
            if attempt < self.max_retries:
                time.sleep(RETRY_BACKOFF_S * 2**attempt)
        raise self._unavailable(f"{failure} after {attempt + 1} attempt(s)")

    def _unavailable(self, failure: str) -> JudgeUnavailable:
        port = urllib.parse.urlsplit(self.base_url).port or "<port>"
        return JudgeUnavailable(
            f"VLM judge at {self.base_url} (model {self.model!r}) is unavailable: {failure}. Check that an "
            f"OpenAI-compatible server is running there and serves that model, e.g. "
            f"`vllm serve Qwen/Qwen3-VL-8B-Instruct --port {port}` (base_url http://localhost:{port}/v1), "
            "that base_url ends in /v1, and the API key if the server needs one.")
