"""`wsp generate --model ws://HOST:PORT`: run a release through a model server (`wsp-serve`, protocol in
`wsp_serve.protocol`, docs/guides/model-server.md).

The episodes go out in requests of the server's batch size, one config per request, and each reply is checked as
an in-process model's output is (shape, count, dtype, resolution), naming the config, episode and seed of a bad
one; a bad reply writes nothing of its batch. A lost or refused connection is retried for `reconnect` seconds and
the batch in flight sent again; past that, or when no reply comes within `timeout` seconds, the run stops with
what it wrote kept, and the same command resumes it (`wsp_eval.generate.write_submission`). submission.json
records the server's handshake and the seconds its model spent (key "model_server", accumulated over resumed
runs) and, for a model that generates at another size or frame rate, the conversion made (key "resampling",
`wsp_eval.model_resampling`).
"""

from __future__ import annotations

import time
from collections.abc import Sequence
from pathlib import Path

import numpy as np
from websockets.exceptions import ConnectionClosed, InvalidHandshake, InvalidURI
from websockets.sync.client import ClientConnection, connect

from wsp_eval.episode import EpisodeContext
from wsp_eval.generate import GenerateError, GenerateResult, request_of, write_submission
from wsp_eval.model_resampling import Resampling
from wsp_serve import callables
from wsp_serve.callables import CallableError
from wsp_serve.protocol import (Episode, Handshake, ProtocolError, ServerError, decode, encode, read_reply,
                                request_message)

SCHEMES = ("ws://", "wss://")
TIMEOUT = 1800.0  # seconds to wait for one reply
RECONNECT = 120.0  # seconds to keep retrying a lost or refused connection
RETRY_PAUSE = (0.2, 5.0)  # the first and the longest pause between connection attempts


def is_server_url(model: str) -> bool:
    return model.startswith(SCHEMES)


class ModelServerClient:
    """A connection to the model server at `url`, made on first use and remade when lost."""

    def __init__(self, url: str, *, timeout: float = TIMEOUT, reconnect: float = RECONNECT):
        self.url, self.timeout, self.reconnect = url, timeout, reconnect
        self.connection: ClientConnection | None = None
        self.handshake: Handshake | None = None
        self.next_id = 0
        self.seconds = 0.0  # spent in the server's model by this client's requests

    def connect(self, where: str = "") -> Handshake:
        """The server's handshake, connecting (and waiting up to `reconnect` seconds for it) if not connected."""
        if self.connection is not None:
            return self.handshake
        deadline, pause = time.monotonic() + self.reconnect, RETRY_PAUSE[0]
        while True:
            try:
                connection = connect(self.url, compression=None, max_size=None, proxy=None,
                                     open_timeout=min(30.0, self.timeout))
                connection.__enter__()  # held as a context, closed by `close()` (websockets 17 warns otherwise)
                break
            except (InvalidURI, ValueError) as e:
                raise GenerateError(f"{self.url}: not a websocket address ({e}); expected ws://HOST:PORT") from None
            except (OSError, InvalidHandshake, TimeoutError) as e:
                if time.monotonic() + pause > deadline:
                    raise GenerateError(f"{self.url}: no model server answers ({type(e).__name__}: {e}) after "
                                        f"{self.reconnect:g} s{_while(where)}; start it (`wsp-serve "
                                        "module:callable --port P`) and re-run the same command: the videos "
                                        "written are kept") from None
                time.sleep(pause)
                pause = min(2 * pause, RETRY_PAUSE[1])
        try:
            handshake = Handshake.from_message(decode(connection.recv(timeout=self.timeout)))
        except (ProtocolError, ConnectionClosed, TimeoutError) as e:
            connection.close()
            raise GenerateError(f"{self.url}: not a WorldSimProbe model server: its handshake is unusable ({e})") \
                from None
        if self.handshake is not None and _identity(handshake) != _identity(self.handshake):
            connection.close()
            raise GenerateError(f"{self.url}: the server now serves {_describe(handshake)}, not "
                                f"{_describe(self.handshake)} as before{_while(where)}; the videos written are kept")
        self.connection, self.handshake = connection, handshake
        return handshake

    def generate(self, config: str, episodes: list[Episode]) -> list[np.ndarray]:
        """The server's frames for `episodes` (one config), each an (N, H, W, 3) uint8 array; a GenerateError
        naming the episodes for a lost server, a late, unreadable or refused reply, or frames off the protocol."""
        where = ", ".join(e.label for e in episodes[:3]) + (f" (+{len(episodes) - 3} more)" if len(episodes) > 3
                                                              else "")
        self.next_id += 1
        data = encode(request_message(self.next_id, config, episodes))
        deadline = time.monotonic() + self.reconnect
        while True:
            self.connect(where)
            try:
                self.connection.send(data)
                reply = self.connection.recv(timeout=self.timeout)
                break
            except TimeoutError:
                self.close()
                raise GenerateError(f"{where}: no reply from the model server at {self.url} within "
                                    f"{self.timeout:.0f} s (raise --timeout for a slower model); the videos "
                                    "written are kept: re-run the same command to resume") from None
            except (ConnectionClosed, OSError) as e:
                self.close()
                if time.monotonic() > deadline:
                    raise GenerateError(f"{where}: the connection to the model server at {self.url} was lost "
                                        f"({type(e).__name__}: {e}); the videos written are kept: re-run the "
                                        "same command to resume") from None
        try:
            videos, seconds = read_reply(decode(reply), self.next_id, len(episodes))
        except ServerError as e:
            raise GenerateError(f"{where}: the model server at {self.url} answered with an error: {e}") from None
        except ProtocolError as e:
            self.close()
            raise GenerateError(f"{where}: the model server at {self.url} sent an unusable reply: {e}") from None
        for video, episode in zip(videos, episodes):
            if not isinstance(video, np.ndarray) or video.dtype != np.uint8:
                got = f"dtype {video.dtype}" if isinstance(video, np.ndarray) else f"a {type(video).__name__}"
                raise GenerateError(f"{episode.label}: the model server at {self.url} sent frames of {got}; the "
                                    "protocol carries (N, H, W, 3) uint8 frames")
        self.seconds += seconds
        return videos

    def close(self) -> None:
        if self.connection is not None:
            self.connection.close()
            self.connection = None


def generate_remote(url: str, release: Path, out: Path, *, seeds: Sequence[int] = (0, 1, 2),
                    configs: Sequence[str] | None = None, name: str | None = None, action_key: str | None = None,
                    progress: bool = True, timeout: float = TIMEOUT, reconnect: float = RECONNECT,
                    ) -> tuple[GenerateResult, Handshake]:
    """Run the model served at `url` over `release` and write, or resume, its submission in `out` (named `name`,
    default the server's model name; `action_key`, when given, must be the one the server wants)."""
    client = ModelServerClient(url, timeout=timeout, reconnect=reconnect)
    try:
        hello = client.connect()
        if action_key is not None and action_key != hello.action_key:
            raise GenerateError(f"{url}: the server's model wants {hello.action_key!r}, not {action_key!r}: drop "
                                "--action-key, or serve the model with `wsp-serve --action-key`")
        key, resampling = hello.action_key, Resampling(hello.resolution, hello.fps)

        def produce(ctxs: list[EpisodeContext]) -> list[np.ndarray]:
            episodes = [Episode(f"{c.config}/{c.episode_id}/seed{c.seed}", resampling.request(request_of(c, key)))
                        for c in ctxs]
            videos = client.generate(ctxs[0].config, episodes)
            try:
                checked = [callables.check_frames(v, len(e.request.actions), e.label, e.request.first_frame.shape[:2],
                                                  of="the request's") for v, e in zip(videos, episodes)]
            except CallableError as e:
                raise GenerateError(f"{e} (from the model server at {url})") from None
            return [resampling.frames(v, c.num_frames, c.fps, c.first_frame().shape[:2])
                    for v, c in zip(checked, ctxs)]

        def extra(previous: dict) -> dict:
            before = previous.get("model_server") if isinstance(previous.get("model_server"), dict) else {}
            if before and (before.get("model"), before.get("version")) != (hello.model, hello.version):
                raise GenerateError(f"{out}: holds videos of {before.get('model')!r} version "
                                    f"{before.get('version')!r}; the server serves {_describe(hello)}: write to "
                                    "another folder")
            _resume_resampling(resampling, previous.get("resampling"))
            seconds = before.get("generation_seconds", 0)
            seconds = seconds if isinstance(seconds, (int, float)) and not isinstance(seconds, bool) else 0
            server = {"url": url, **{k: v for k, v in hello.message().items() if k not in ("type", "info")},
                      "generation_seconds": round(seconds + client.seconds, 3)}
            described = resampling.describe()
            return {"model_server": server, **({"resampling": described} if described else {})}

        result = write_submission(produce, release, out, seeds=seeds, configs=configs, name=name or hello.model,
                                  progress=progress, batch_size=hello.batch_size, info=hello.info or None,
                                  extra=extra)
        return result, hello
    finally:
        client.close()


def _resume_resampling(resampling: Resampling, previous: object) -> None:
    """Keep the conversions a resumed run's earlier part recorded."""
    if not isinstance(previous, dict):
        return
    size, fps = previous.get("size"), previous.get("fps")
    if isinstance(size, dict) and isinstance(size.get("reference"), list):
        resampling.resized |= {tuple(s) for s in size["reference"] if isinstance(s, list) and len(s) == 2}
    if isinstance(fps, dict) and isinstance(fps.get("release"), list):
        resampling.retimed |= {float(f) for f in fps["release"] if isinstance(f, (int, float))}


def _identity(handshake: Handshake) -> tuple:
    return handshake.model, handshake.version, handshake.action_key, handshake.resolution, handshake.fps


def _describe(handshake: Handshake) -> str:
    return f"model {handshake.model!r} version {handshake.version!r}"


def _while(where: str) -> str:
    return f" while generating {where}" if where else ""
