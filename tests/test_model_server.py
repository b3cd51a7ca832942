"""`wsp generate --model ws://HOST:PORT` against `wsp-serve`, on the tiny real T1 release.

The server runs from a virtual environment of its own holding numpy, msgpack, websockets and `wsp_serve` only (no
WorldSimProbe, no torch) and serves `docs/example_adapter.py`: its submission is byte-identical to the in-process
call's. A server killed mid-run loses at most the batch in flight (re-run, or reconnect, and only what is missing is
generated); a server answering with a wrong frame count, a wrong dtype or garbage bytes is named with the episode,
and nothing is written for it; a model of another size or frame rate is converted once, and submission.json says so.
"""

from __future__ import annotations

import json
import re
import shutil
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

import numpy as np
import pytest
from websockets.sync.server import serve

from wsp_eval.cli import main as wsp
from wsp_eval.generate import GenerateError, generate, load_model
from wsp_eval.model_client import ModelServerClient, generate_remote
from wsp_eval.model_resampling import model_frames
from wsp_eval.report import markdown
from wsp_eval.submission import validate
from wsp_eval.video import read_video
from wsp_serve.callables import Request
from wsp_serve.protocol import (Episode, Handshake, ProtocolError, decode, encode, frames_message, read_request)
from wsp_serve.server import main as wsp_serve_main
from wsp_serve.server import start

ROOT = Path(__file__).resolve().parents[1]
CONFIG = "t1_maniskill"
FIRST = f"{CONFIG}/episode_000000/seed0"
SERVED_MODELS = '''
import time

import numpy as np


class Slow:  # the example adapter's still frame, 0.3 s per batch of two
    wsp_batch_size = 2
    wsp_info = {"version": "slow-1"}

    def __call__(self, requests):
        time.sleep(0.3)
        return [np.repeat(r.first_frame[None], len(r.actions), axis=0) for r in requests]


slow = Slow()
'''


def count_episodes(release: Path) -> int:
    import pyarrow.parquet as pq

    return sum(map(len, pq.read_table(release / CONFIG / "instances.parquet", columns=["episode_ids"])
                   .column(0).to_pylist()))


@pytest.fixture(scope="module")
def server_env(tmp_path_factory) -> tuple[Path, Path]:
    """(python, folder): a venv whose only packages are links to numpy, msgpack, websockets and wsp_serve, and a
    folder (its working directory) holding the example adapter and `served_models.py`."""
    base = tmp_path_factory.mktemp("server-env")
    venv = base / "venv"
    subprocess.run([getattr(sys, "_base_executable", sys.executable), "-m", "venv", "--without-pip", str(venv)],
                   check=True, capture_output=True, timeout=120)
    links = base / "packages"
    links.mkdir()
    site = Path(np.__file__).resolve().parents[1]
    for name in ("numpy", "numpy.libs", "msgpack", "websockets"):
        if (site / name).is_dir():
            (links / name).symlink_to(site / name)
    (links / "wsp_serve").symlink_to(ROOT / "wsp_serve")
    python = venv / "bin" / "python"
    own_site = subprocess.run([str(python), "-c", "import sysconfig; print(sysconfig.get_paths()['purelib'])"],
                              capture_output=True, text=True, check=True).stdout.strip()
    (Path(own_site) / "wsp_packages.pth").write_text(f"{links}\n")
    work = base / "work"
    work.mkdir()
    shutil.copy(ROOT / "docs" / "example_adapter.py", work / "example_adapter.py")
    (work / "served_models.py").write_text(SERVED_MODELS)
    return python, work


class Served:
    """A `python -m wsp_serve MODULE:CALLABLE --port 0` process of the server venv, and the port it listens on."""

    def __init__(self, env: tuple[Path, Path], spec: str, *args: str):
        python, work = env
        self.process = subprocess.Popen([str(python), "-m", "wsp_serve", spec, "--port", "0", *args], cwd=work,
                                        stderr=subprocess.PIPE, text=True)
        line = self.process.stderr.readline()
        match = re.search(r"on ws://127\.0\.0\.1:(\d+);", line)
        assert match, line + self.process.stderr.read() if self.process.poll() is not None else line
        self.port = int(match.group(1))
        self.url = f"ws://127.0.0.1:{self.port}"

    def kill(self) -> None:
        self.process.send_signal(signal.SIGKILL)
        self.process.wait(timeout=30)
        self.process.stderr.close()


@pytest.fixture
def served(server_env):
    started: list[Served] = []

    def run(spec: str, *args: str) -> Served:
        started.append(Served(server_env, spec, *args))
        return started[-1]

    yield run
    for s in started:
        if s.process.poll() is None:
            s.kill()


def test_the_server_environment_has_neither_worldsimprobe_nor_torch(server_env):
    python, work = server_env
    for module in ("wsp_eval", "wsp_data", "torch", "cv2", "pyarrow"):
        r = subprocess.run([str(python), "-c", f"import {module}"], cwd=work, capture_output=True, text=True)
        assert r.returncode != 0 and "ModuleNotFoundError" in r.stderr, module
    r = subprocess.run([str(python), "-c", "import json, sys, wsp_serve.server, example_adapter; "
                                           "print(json.dumps(sorted(m for m in sys.modules if m.startswith('wsp'))))"],
                       cwd=work, capture_output=True, text=True)
    assert r.returncode == 0, r.stderr
    assert json.loads(r.stdout) == ["wsp_serve", "wsp_serve.callables", "wsp_serve.protocol", "wsp_serve.server"]


def test_served_example_adapter_is_byte_identical_to_the_in_process_call(t1_release, served, tmp_path, monkeypatch):
    server = served("example_adapter:model", "--name", "example", "--model-version", "1.0")
    assert wsp(["generate", "--model", server.url, "--release", str(t1_release), "--out", str(tmp_path / "served"),
                "--seeds", "0", "1", "--quiet"]) == 0
    monkeypatch.chdir(ROOT)
    generate(load_model("docs.example_adapter:model"), t1_release, tmp_path / "local", seeds=(0, 1),
             name="example", progress=False)
    videos = sorted(p.relative_to(tmp_path / "local") for p in (tmp_path / "local").rglob("*.mp4"))
    assert len(videos) == 2 * count_episodes(t1_release)
    assert videos == sorted(p.relative_to(tmp_path / "served") for p in (tmp_path / "served").rglob("*.mp4"))
    for video in videos:
        assert (tmp_path / "served" / video).read_bytes() == (tmp_path / "local" / video).read_bytes()
    assert validate(tmp_path / "served", t1_release) == []
    meta = json.loads((tmp_path / "served" / "submission.json").read_text())
    assert meta["model"] == "example" and meta["seeds"] == [0, 1] and "resampling" not in meta
    server_meta = meta["model_server"]
    assert {k: server_meta[k] for k in ("url", "model", "version", "action_key", "batch_size", "protocol")} == {
        "url": server.url, "model": "example", "version": "1.0", "action_key": "action", "batch_size": 8,
        "protocol": 1}
    assert 0 <= server_meta["generation_seconds"] <= meta["generation_seconds"]


def test_killed_server_loses_at_most_the_batch_in_flight(t1_release, served, tmp_path):
    total = count_episodes(t1_release)
    server = served("served_models:slow")
    errors: list[Exception] = []

    def run() -> None:
        try:
            generate_remote(server.url, t1_release, tmp_path, seeds=(0,), progress=False, reconnect=0.5)
        except GenerateError as e:
            errors.append(e)

    thread = threading.Thread(target=run)
    thread.start()
    deadline = time.monotonic() + 60
    while len(list(tmp_path.rglob("*.mp4"))) < 2 and time.monotonic() < deadline:
        time.sleep(0.02)
    server.kill()
    thread.join(timeout=60)
    assert len(errors) == 1 and re.search(r"(connection to the model server .* was lost|no model server answers)",
                                          str(errors[0])), errors
    assert "the videos written are kept" in str(errors[0])
    done = len(list(tmp_path.rglob("*.mp4")))
    assert 2 <= done < total and not list(tmp_path.rglob(".*.mp4"))

    server = served("served_models:slow")
    result, hello = generate_remote(server.url, t1_release, tmp_path, seeds=(0,), progress=False)
    assert (result.written, result.skipped) == (total - done, done) and hello.version == "slow-1"
    assert validate(tmp_path, t1_release) == []
    meta = json.loads((tmp_path / "submission.json").read_text())
    assert meta["model"] == "served_models:slow" and meta["model_info"] == {"version": "slow-1"}


def test_a_restarted_server_is_reconnected_to_within_the_window(t1_release, served, tmp_path):
    server = served("served_models:slow")
    results: list = []
    thread = threading.Thread(target=lambda: results.append(
        generate_remote(server.url, t1_release, tmp_path, seeds=(0,), progress=False, reconnect=60)))
    thread.start()
    deadline = time.monotonic() + 60
    while not list(tmp_path.rglob("*.mp4")) and time.monotonic() < deadline:
        time.sleep(0.02)
    server.kill()
    time.sleep(0.5)
    served("served_models:slow", "--port", str(server.port))  # the last --port wins: the same address again
    thread.join(timeout=120)
    (result, _), = results
    assert result.written == count_episodes(t1_release) and validate(tmp_path, t1_release) == []


class FakeServer:
    """A websocket server stating a valid handshake and answering every request with `reply(message)`'s bytes."""

    def __init__(self, reply, handshake: Handshake | None = None):
        hello = encode((handshake or Handshake("fake", "0", batch_size=3)).message())

        def handle(connection):
            connection.send(hello)
            for data in connection:
                answer = reply(decode(data))
                if answer is not None:
                    connection.send(answer)

        self.server = serve(handle, "127.0.0.1", 0, compression=None, max_size=None)
        self.url = f"ws://127.0.0.1:{self.server.socket.getsockname()[1]}"
        threading.Thread(target=self.server.serve_forever, daemon=True).start()

    def close(self) -> None:
        self.server.shutdown()


def still_frames(message: dict, drop: int = 0, dtype=np.uint8) -> list[np.ndarray]:
    return [np.repeat(e["first_frame"][None], len(e["actions"]) - drop, axis=0).astype(dtype)
            for e in message["episodes"]]


@pytest.mark.parametrize("reply, problem", [
    (lambda m: encode(frames_message(m["id"], still_frames(m, drop=1), 0.1)),
     r"62 frames; the request's horizon is 63 \(from the model server at ws://"),
    (lambda m: encode(frames_message(m["id"], still_frames(m, dtype=np.float32), 0.1)),
     r"the model server at ws://\S+ sent frames of dtype float32; the protocol carries \(N, H, W, 3\) uint8"),
    (lambda m: bytes(range(256)) * 8, r"sent an unusable reply: unreadable message of 2048 bytes"),
    (lambda m: "Traceback (most recent call last): ...", r"sent an unusable reply: a text message"),
    (lambda m: encode({"type": "frames", "id": m["id"], "videos": still_frames(m)[:1]}),
     r"sent an unusable reply: asked for 3 video\(s\), the reply holds 1 video\(s\)"),
    (lambda m: encode({"type": "error", "id": m["id"], "message": "out of GPU memory"}),
     r"answered with an error: out of GPU memory"),
    (lambda m: None, r"no reply from the model server at ws://\S+ within 1 s"),
])
def test_bad_replies_name_the_episode_and_write_nothing(t1_release, tmp_path, reply, problem):
    fake = FakeServer(reply)
    try:
        with pytest.raises(GenerateError, match=rf"^{FIRST}(, \S+)*: .*{problem}"):
            generate_remote(fake.url, t1_release, tmp_path, seeds=(0,), progress=False, timeout=1)
    finally:
        fake.close()
    assert not list(tmp_path.rglob("*.mp4"))


def test_the_command_line_names_the_episode_in_one_line(t1_release, tmp_path, capsys):
    fake = FakeServer(lambda m: encode(frames_message(m["id"], still_frames(m, drop=1), 0.1)))
    try:
        assert wsp(["generate", "--model", fake.url, "--release", str(t1_release), "--out", str(tmp_path),
                    "--quiet"]) == 2
    finally:
        fake.close()
    err = capsys.readouterr().err
    assert err.startswith(f"wsp: error: {FIRST}: 62 frames") and "Traceback" not in err


def test_no_server_and_not_a_model_server(t1_release, tmp_path):
    with pytest.raises(GenerateError, match=r"ws://127.0.0.1:9: no model server answers .* after 0 s; start it"):
        generate_remote("ws://127.0.0.1:9", t1_release, tmp_path, progress=False, reconnect=0)
    with pytest.raises(GenerateError, match="not a websocket address"):
        generate_remote("ws://127.0.0.1:notaport", t1_release, tmp_path, progress=False, reconnect=0)
    openpi_like = serve(lambda c: c.send(encode({"policy": "pi0"})) or c.recv(), "127.0.0.1", 0)
    threading.Thread(target=openpi_like.serve_forever, daemon=True).start()
    try:
        with pytest.raises(GenerateError, match=r"not a WorldSimProbe model server: its handshake is unusable "
                                                r"\(a message must be a map with a 'type'"):
            generate_remote(f"ws://127.0.0.1:{openpi_like.socket.getsockname()[1]}", t1_release, tmp_path,
                            progress=False, reconnect=0)
    finally:
        openpi_like.shutdown()
    assert not list(tmp_path.rglob("*"))


class Recorder:
    """A batched numpy model that records its requests and holds the first frame still."""
    wsp_batch_size = 4

    def __init__(self, fail_on_seed: int | None = None, nan: bool = False):
        self.requests: list[Request] = []
        self.fail_on_seed, self.nan = fail_on_seed, nan

    def __call__(self, requests):
        if any(r.seed == self.fail_on_seed for r in requests):
            raise RuntimeError("the model broke")
        self.requests += requests
        dtype = np.float64 if self.nan else np.uint8
        return [np.repeat(r.first_frame[None], len(r.actions), axis=0).astype(dtype) * (np.nan if self.nan else 1)
                for r in requests]


def in_process_server(model, handshake: Handshake):
    server = start(model, handshake, port=0)
    threading.Thread(target=server.serve_forever, daemon=True).start()
    return server, f"ws://127.0.0.1:{server.socket.getsockname()[1]}"


def test_a_model_of_another_size_and_rate_is_converted_once_and_said_so(t1_release, tmp_path):
    model = Recorder()
    server, url = in_process_server(model, Handshake("small", "2", "action.ee", (64, 48), 10.0, 4))
    try:
        result, _ = generate_remote(url, t1_release, tmp_path, seeds=(0,), progress=False)
    finally:
        server.shutdown()
    assert result.written == count_episodes(t1_release) == len(model.requests)
    first = model.requests[0]
    assert first.first_frame.shape == (48, 64, 3) and first.fps == 10.0
    assert len(first.actions) == model_frames(63, 20.0, 10.0) == 32 and first.actions.shape[1] == 7  # ee: 7-D
    video, _ = read_video(tmp_path / CONFIG / "episode_000000" / "seed0.mp4")
    assert video.shape == (63, 128, 128, 3)
    assert validate(tmp_path, t1_release) == []
    meta = json.loads((tmp_path / "submission.json").read_text())
    assert meta["resampling"]["size"]["model"] == [64, 48] and meta["resampling"]["size"]["reference"] == [[128, 128]]
    assert meta["resampling"]["fps"]["model"] == 10.0 and meta["resampling"]["fps"]["release"] == [20.0]
    assert meta["model_server"]["resolution"] == [64, 48] and meta["model_server"]["action_key"] == "action.ee"
    from test_report import make_report

    report = make_report("small")
    report["submission"].update(model_server=meta["model_server"], resampling=meta["resampling"])
    text = markdown(report)
    assert "Model server" in text and "generated at 64×48, converted from and to 128×128 (cv2.resize" in text
    assert "generated at 10.0 fps, converted from and to 20.0 fps (nearest by timestamp" in text


def test_model_errors_come_back_as_messages_on_an_open_connection(t1_release, tmp_path):
    frame, actions = np.zeros((8, 8, 3), np.uint8), np.zeros((5, 8), np.float32)
    server, url = in_process_server(Recorder(fail_on_seed=1), Handshake("m", "1", batch_size=4))
    try:
        client = ModelServerClient(url, reconnect=5)
        with pytest.raises(GenerateError, match=r"^c/e/seed1: the model server at \S+ answered with an error: "
                                                r"c/e/seed1: the model raised RuntimeError: the model broke"):
            client.generate("c", [Episode("c/e/seed1", Request(frame, actions, 20.0, 1))])
        connection = client.connection
        assert client.generate("c", [Episode("c/e/seed0", Request(frame, actions, 20.0, 0))])[0].shape == (5, 8, 8, 3)
        assert client.connection is connection  # the same connection throughout
        client.connection.send(b"\xc1 not msgpack")
        assert "bad request: unreadable message" in decode(client.connection.recv(timeout=10))["message"]
        client.close()
    finally:
        server.shutdown()
    server, url = in_process_server(Recorder(nan=True), Handshake("m", "1", batch_size=4))
    try:
        with pytest.raises(GenerateError, match=rf"^{FIRST}.*answered with an error: {FIRST}: frames contain NaN"):
            generate_remote(url, t1_release, tmp_path, seeds=(0,), progress=False)
    finally:
        server.shutdown()
    assert not list(tmp_path.rglob("*.mp4"))


def test_action_key_of_the_command_must_match_the_servers(t1_release, tmp_path):
    server, url = in_process_server(Recorder(), Handshake("m", "1", "action.ee"))
    try:
        with pytest.raises(GenerateError, match=r"the server's model wants 'action.ee', not 'action'"):
            generate_remote(url, t1_release, tmp_path, action_key="action", progress=False)
    finally:
        server.shutdown()


def test_codec_is_openpis_and_refuses_what_it_cannot_carry():
    frames = np.arange(2 * 4 * 4 * 3, dtype=np.uint8).reshape(2, 4, 4, 3)
    message = decode(encode({"type": "x", "frames": frames, "fps": np.float32(20)}))
    assert np.array_equal(message["frames"], frames) and message["frames"].dtype == np.uint8
    assert message["fps"] == np.float32(20) and isinstance(message["fps"], np.float32)
    raw = __import__("msgpack").unpackb(encode({"a": frames}))["a"]  # openpi's layout, as openpi_client reads it
    assert raw[b"__ndarray__"] is True and raw[b"dtype"] == "|u1" and raw[b"shape"] == [2, 4, 4, 3]
    with pytest.raises(ValueError, match="unsupported dtype: object"):
        encode({"a": np.array([None])})
    for bad, problem in [(b"\xc1", "unreadable message"), (encode([1, 2]), "must be a map with a 'type'"),
                         ("text", "a text message")]:
        with pytest.raises(ProtocolError, match=problem):
            decode(bad)
    with pytest.raises(ProtocolError, match=r"4 episodes in one request; this server takes 1 to 3"):
        read_request({"type": "generate", "id": 1, "config": "c", "episodes": [{}] * 4}, 3)
    with pytest.raises(ProtocolError, match=r"c/e/seed0: 'actions' must be a \(T, D\) float32 array"):
        read_request({"type": "generate", "id": 1, "config": "c", "episodes": [
            {"episode": "c/e/seed0", "first_frame": frames[0], "actions": np.zeros((3, 2)), "fps": 20, "seed": 0}]},
            3)
    with pytest.raises(ProtocolError, match=r"action_key 'joints' is not one of .*; resolution \(0, 4\)"):
        Handshake("m", "1", "joints", (0, 4))


def test_wsp_serve_refuses_a_bad_model_in_one_line(capsys):
    assert wsp_serve_main(["no.such:model", "--port", "0"]) == 2
    assert capsys.readouterr().err.startswith("wsp-serve: error: model 'no.such:model': cannot import module")
    assert wsp_serve_main(["numpy:pi"]) == 2
    assert "'pi' is a float, not callable" in capsys.readouterr().err
