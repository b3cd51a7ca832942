"""The OpenAI-compatible VLM judge against a real loopback HTTP server that answers like vLLM: the request it
sends (frames, prompt, greedy settings), answer parsing, and the failures (unreachable, timeout, HTTP errors)."""

from __future__ import annotations

import base64
import io
import json
import socket
import threading
import time
from dataclasses import dataclass, field
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer

import numpy as np
import pytest
from PIL import Image

from wsp_eval.backends import judge_openai
from wsp_eval.backends.judge import PRIMITIVE_SPECS, PRIMITIVES, Verdict, score_verdict
from wsp_eval.backends.judge_openai import JudgeUnavailable, OpenAIJudge, parse_answer

MODEL = "Qwen/Qwen3-VL-8B-Instruct"
GOOD = '{"label": "push", "agent_motion_matches": true, "object_motion_matches": false}'


@dataclass
class FakeServer:
    """What the loopback server answers (set per test) and the requests it got."""

    url: str = ""
    content: str | None = GOOD  # choices[0].message.content; None leaves `choices` out
    status: int = 200
    delay: float = 0.0
    models: tuple[str, ...] = (MODEL,)
    requests: list[dict] = field(default_factory=list)  # {"path", "headers", "body"}


def _handler(state: FakeServer) -> type[BaseHTTPRequestHandler]:
    class Handler(BaseHTTPRequestHandler):
        def log_message(self, *args) -> None:
            pass

        def _answer(self, payload: dict) -> None:
            time.sleep(state.delay)
            data = json.dumps(payload if state.status == 200 else {"error": "boom"}).encode()
            try:
                self.send_response(state.status)
                self.send_header("Content-Type", "application/json")
                self.send_header("Content-Length", str(len(data)))
                self.end_headers()
                self.wfile.write(data)
            except (BrokenPipeError, ConnectionResetError):  # the timeout test's client has already given up
                pass

        def _record(self, body: dict | None) -> None:
            state.requests.append({"path": self.path, "headers": dict(self.headers), "body": body})

        def do_GET(self) -> None:
            self._record(None)
            self._answer({"object": "list", "data": [{"id": m, "object": "model"} for m in state.models]})

        def do_POST(self) -> None:
            self._record(json.loads(self.rfile.read(int(self.headers["Content-Length"]))))
            message = {"role": "assistant", "content": state.content}
            self._answer({"id": "x", "choices": [{"index": 0, "message": message}]} if state.content is not None
                         else {"id": "x", "choices": []})

    return Handler


@pytest.fixture
def server():
    """A real OpenAI-compatible HTTP server on 127.0.0.1 (port 0), in a thread."""
    state = FakeServer()
    httpd = ThreadingHTTPServer(("127.0.0.1", 0), _handler(state))
    state.url = f"http://127.0.0.1:{httpd.server_address[1]}/v1"
    thread = threading.Thread(target=httpd.serve_forever, args=(0.02,), daemon=True)
    thread.start()
    yield state
    httpd.shutdown()
    httpd.server_close()


@pytest.fixture
def closed_port_url() -> str:
    """A loopback URL nobody listens on."""
    with socket.socket() as sock:
        sock.bind(("127.0.0.1", 0))
        port = sock.getsockname()[1]
    return f"http://127.0.0.1:{port}/v1"


def _frames(height: int = 120, width: int = 160) -> np.ndarray:
    return np.random.default_rng(0).integers(0, 256, (12, height, width, 3), dtype=np.uint8)


def _decode(url: str) -> np.ndarray:
    prefix = "data:image/png;base64,"
    assert url.startswith(prefix)
    return np.asarray(Image.open(io.BytesIO(base64.b64decode(url[len(prefix):]))).convert("RGB"))


# -- the request --------------------------------------------------------------------------------------------
def test_request_is_well_formed(server):
    frames = _frames()
    verdict = OpenAIJudge(server.url + "/", MODEL, api_key="secret").judge(frames, (64.0, 128.0))
    assert verdict == Verdict("push", True, False, {"raw": GOOD})
    (request,) = server.requests
    assert request["path"] == "/v1/chat/completions"
    assert request["headers"]["Authorization"] == "Bearer secret"
    body = request["body"]
    assert body["model"] == MODEL and body["temperature"] == 0 and 0 < body["max_tokens"] <= 300
    system, user = body["messages"]
    assert system["role"] == "system" and user["role"] == "user"
    text, *images = user["content"]
    assert text["type"] == "text" and [p["type"] for p in images] == ["image_url"] * 12
    for part, frame in zip(images, frames):
        np.testing.assert_array_equal(_decode(part["image_url"]["url"]), frame)
    prompt = text["text"]
    # (64, 128) in the 256² frame → ((64.5)·160/256 − 0.5, (128.5)·120/256 − 0.5) = (39.8, 59.7) in 160×120
    assert "(40, 60)" in prompt and "160×120" in prompt
    for name in PRIMITIVES:
        assert name in prompt and PRIMITIVE_SPECS[name] in prompt
    everything = (system["content"] + prompt).lower()
    for hint in ("intended", "correct answer", "action", "qwen", "cosmos", "model"):
        assert hint not in everything


def test_prompt_text_is_inspectable():
    prompt = judge_openai.prompt_text((10.2, 250.7), (256, 256))
    assert "(10, 251)" in prompt and "256×256" in prompt and '"agent_motion_matches"' in prompt


def test_identity_and_bad_arguments(server):
    judge = OpenAIJudge(server.url + "/", MODEL)
    assert judge.name == "openai" and judge.version == f"{MODEL}@{server.url}"
    with pytest.raises(ValueError, match="frames"):
        judge.judge(_frames()[:5], (1.0, 1.0))
    with pytest.raises(ValueError, match="base_url"):
        OpenAIJudge("localhost:8000/v1", MODEL)
    assert server.requests == []


# -- parsing ------------------------------------------------------------------------------------------------
@pytest.mark.parametrize("text, expected", [
    ('```json\n{"label": "drop", "agent_motion_matches": true, "object_motion_matches": true}\n```',
     ("drop", True, True)),
    ('Looking at the frames, the gripper hits the bottle. {"label": "Knock over", "agent_motion_matches": "yes", '
     '"object_motion_matches": "no"} That is my answer.', ("knock-over", True, False)),
    ('{"label": "KNOCK_OVER", "agent_motion_matches": "False", "object_motion_matches": "TRUE"}',
     ("knock-over", False, True)),
    ('{"label": "knockover", "agent_motion_matches": false, "object_motion_matches": false}',
     ("knock-over", False, False)),
    ('<think>{not json} maybe "tap"?</think> note {x} then {"label": " Rotate ", "agent_motion_matches": true, '
     '"object_motion_matches": true}', ("rotate", True, True)),
])
def test_parse_answer(text, expected):
    verdict = parse_answer(text)
    assert (verdict.label, verdict.agent_ok, verdict.object_ok) == expected
    assert verdict.evidence["raw"] == text


@pytest.mark.parametrize("text, why", [
    ("I think it is a push.", "no JSON"),
    ('{"label": "push", "agent_motion_matches": true', "no JSON"),
    ('{"label": "slide", "agent_motion_matches": true, "object_motion_matches": true}', "unknown label"),
    ('{"label": "push", "agent_motion_matches": true}', "missing keys"),
    ('{"label": "push", "agent_motion_matches": "maybe", "object_motion_matches": true}', "not booleans"),
    ("", "no JSON"),
])
def test_unparseable_answer_scores_zero(text, why):
    verdict = parse_answer(text)
    assert verdict.label is None and not verdict.agent_ok and not verdict.object_ok
    assert verdict.evidence["raw"] == text and why in verdict.evidence["error"]
    assert all(score_verdict(verdict, name) == 0 for name in PRIMITIVES)


def test_answers_over_http(server):
    judge = OpenAIJudge(server.url, MODEL)
    server.content = ('Sure!\n```json\n{"label": "Tap", "agent_motion_matches": "yes", '
                      '"object_motion_matches": "yes"}\n```')
    assert score_verdict(judge.judge(_frames(), (5.0, 5.0)), "tap") == 100.0
    server.content = "It is a push."
    assert judge.judge(_frames(), (5.0, 5.0)).label is None
    server.content = None  # a 200 answer without choices: unparseable, not an exception
    verdict = judge.judge(_frames(), (5.0, 5.0))
    assert verdict.label is None and "choices" in verdict.evidence["error"]


# -- failures -----------------------------------------------------------------------------------------------
def test_unreachable_endpoint_raises_quickly(closed_port_url):
    judge = OpenAIJudge(closed_port_url, MODEL, timeout=2.0, max_retries=0)
    start = time.monotonic()
    with pytest.raises(JudgeUnavailable) as raised:
        judge.judge(_frames(), (5.0, 5.0))
    assert time.monotonic() - start < 3.0
    message = str(raised.value)
    assert closed_port_url in message and MODEL in message and "vllm serve" in message
    with pytest.raises(JudgeUnavailable, match=closed_port_url):
        judge.ping()


def test_timeout_raises(server):
    server.delay = 0.5
    with pytest.raises(JudgeUnavailable, match=server.url):
        OpenAIJudge(server.url, MODEL, timeout=0.2, max_retries=0).judge(_frames(), (5.0, 5.0))


def test_http_errors_raise(server, monkeypatch):
    monkeypatch.setattr(judge_openai, "RETRY_BACKOFF_S", 0.0)
    server.status = 500
    with pytest.raises(JudgeUnavailable, match="HTTP 500") as raised:
        OpenAIJudge(server.url, MODEL, max_retries=1).judge(_frames(), (5.0, 5.0))
    assert server.url in str(raised.value) and len(server.requests) == 2  # a 5xx is retried
    server.status, server.requests = 404, []
    with pytest.raises(JudgeUnavailable, match="HTTP 404"):
        OpenAIJudge(server.url, MODEL, max_retries=1).judge(_frames(), (5.0, 5.0))
    assert len(server.requests) == 1  # a 4xx is not


def test_ping(server):
    assert OpenAIJudge(server.url, MODEL).ping() == [MODEL]
    assert server.requests[0]["path"] == "/v1/models"
    with pytest.raises(JudgeUnavailable, match="not served"):
        OpenAIJudge(server.url, "qwen3-vl:8b").ping()
