"""The model-server protocol (docs/guides/model-server.md): binary websocket messages, each one msgpack map with
numpy arrays in openpi's msgpack-numpy form (`{b"__ndarray__": True, b"data", b"dtype", b"shape"}`; object,
void and complex arrays refused), so `openpi_client.msgpack_numpy` reads them too.

1. On connecting, the server sends the handshake (`Handshake.message()`, type "hello").
2. The client sends requests (type "generate"): an `id`, a `config` and up to `batch_size` episodes of it, each
   `{"episode": "config/episode_id/seedK", "first_frame", "actions", "fps", "seed"}`.
3. The server answers every request, in order, with type "frames" (`id`, `videos`: one (T, H, W, 3) uint8 array
   per episode, `seconds` spent in the model) or type "error" (`id`, `message`); the connection stays open.

Every decoder here raises `ProtocolError` with a one-line message; both ends use this module.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass, field

import msgpack
import numpy as np

from wsp_serve.callables import MAX_BATCH, Request

PROTOCOL_VERSION = 1
ACTION_KEYS = ("action", "action.ee", "action.joint")  # the native stream and the ones stored beside it
REFUSED_KINDS = "VOc"  # void, object, complex: no raw-bytes round trip, or none a frame or action needs


class ProtocolError(ValueError):
    """A message that does not follow the protocol; the message says what is wrong."""


def pack_array(obj: object) -> object:
    """msgpack's `default` hook: numpy arrays and scalars as openpi's msgpack-numpy maps."""
    if isinstance(obj, (np.ndarray, np.generic)) and obj.dtype.kind in REFUSED_KINDS:
        raise ValueError(f"unsupported dtype: {obj.dtype}")
    if isinstance(obj, np.ndarray):
        data = memoryview(np.ascontiguousarray(obj).reshape(-1).view(np.uint8))  # its bytes, not copied
        return {b"__ndarray__": True, b"data": data, b"dtype": obj.dtype.str, b"shape": obj.shape}
    if isinstance(obj, np.generic):
        return {b"__npgeneric__": True, b"data": obj.item(), b"dtype": obj.dtype.str}
    raise TypeError(f"cannot send a {type(obj).__name__}")


def unpack_array(obj: dict) -> object:
    """msgpack's `object_hook`: the inverse of `pack_array` (read-only arrays over the message's bytes)."""
    if b"__ndarray__" in obj:
        dtype = np.dtype(obj[b"dtype"])
        if dtype.kind in REFUSED_KINDS:
            raise ValueError(f"unsupported dtype: {dtype}")
        return np.ndarray(buffer=obj[b"data"], dtype=dtype, shape=tuple(obj[b"shape"]))
    if b"__npgeneric__" in obj:
        return np.dtype(obj[b"dtype"]).type(obj[b"data"])
    return obj


packb = functools.partial(msgpack.packb, default=pack_array)
unpackb = functools.partial(msgpack.unpackb, object_hook=unpack_array)


def encode(message: dict) -> bytes:
    """`message` as the bytes of one websocket message."""
    return packb(message)


def decode(data: object) -> dict:
    """The message in `data` (one websocket message), or a ProtocolError."""
    if isinstance(data, str):
        raise ProtocolError(f"a text message where a binary one was expected: {data[:200]!r}")
    try:
        message = unpackb(data)
    except Exception as e:  # msgpack's and numpy's many errors on malformed bytes
        raise ProtocolError(f"unreadable message of {len(data)} bytes ({type(e).__name__}: {e})") from None
    if not isinstance(message, dict) or not isinstance(message.get("type"), str):
        raise ProtocolError(f"a message must be a map with a 'type'; got {_preview(message)}")
    return message


@dataclass(frozen=True)
class Handshake:
    """What a server states about its model on every connection."""
    model: str  # the model's name
    version: str  # its version (checkpoint, commit)
    action_key: str = "action"  # the action stream it wants: "action" (native) or one stored beside it
    resolution: tuple[int, int] | None = None  # (width, height) it generates at; None: the first frame's
    fps: float | None = None  # the frame rate it generates at; None: the release's
    batch_size: int = 1  # episodes per request, at most
    info: dict = field(default_factory=dict)  # anything else it reports (the callable's `wsp_info`)

    def __post_init__(self) -> None:
        problems = []
        if not (isinstance(self.model, str) and self.model) or not (isinstance(self.version, str) and self.version):
            problems.append("model and version must be non-empty strings")
        if self.action_key not in ACTION_KEYS:
            problems.append(f"action_key {self.action_key!r} is not one of {', '.join(ACTION_KEYS)}")
        res = self.resolution
        if res is not None and not (isinstance(res, tuple) and len(res) == 2 and all(
                isinstance(v, int) and not isinstance(v, bool) and 1 <= v <= 4096 for v in res)):
            problems.append(f"resolution {res!r} is not a (width, height) pair of positive integers")
        if self.fps is not None and not (isinstance(self.fps, (int, float)) and not isinstance(self.fps, bool)
                                         and math.isfinite(self.fps) and 0 < self.fps <= 1000):
            problems.append(f"fps {self.fps!r} is not a positive number")
        if isinstance(self.batch_size, bool) or not isinstance(self.batch_size, int) \
                or not 1 <= self.batch_size <= MAX_BATCH:
            problems.append(f"batch_size {self.batch_size!r} is not an integer from 1 to {MAX_BATCH}")
        if not isinstance(self.info, dict):
            problems.append("info must be a map")
        if problems:
            raise ProtocolError("handshake: " + "; ".join(problems))

    def message(self) -> dict:
        return {"type": "hello", "protocol": PROTOCOL_VERSION, "model": self.model, "version": self.version,
                "action_key": self.action_key, "resolution": list(self.resolution) if self.resolution else None,
                "fps": self.fps, "batch_size": self.batch_size, "info": self.info}

    @classmethod
    def from_message(cls, message: dict) -> Handshake:
        if message.get("type") != "hello":
            raise ProtocolError(f"expected the server's handshake (type 'hello'), got type {message.get('type')!r}")
        if message.get("protocol") != PROTOCOL_VERSION:
            raise ProtocolError(f"the server speaks protocol {message.get('protocol')!r}; this side speaks "
                                f"{PROTOCOL_VERSION}")
        res = message.get("resolution")
        try:
            return cls(message.get("model"), message.get("version"), message.get("action_key", "action"),
                       tuple(res) if isinstance(res, (list, tuple)) else res, message.get("fps"),
                       message.get("batch_size", 1), message.get("info") or {})
        except TypeError as e:
            raise ProtocolError(f"handshake: {e}") from None


@dataclass(frozen=True)
class Episode:
    """One episode of a request: the callable's `Request` and the label errors name it by."""
    label: str  # "config/episode_id/seedK"
    request: Request


def request_message(request_id: int, config: str, episodes: list[Episode]) -> dict:
    return {"type": "generate", "id": request_id, "config": config,
            "episodes": [{"episode": e.label, "first_frame": e.request.first_frame, "actions": e.request.actions,
                          "fps": float(e.request.fps), "seed": int(e.request.seed)} for e in episodes]}


def read_request(message: dict, batch_size: int) -> tuple[int, str, list[Episode]]:
    """(id, config, episodes) of a "generate" message, arrays copied (writable, as a model gets them in process)."""
    if message.get("type") != "generate":
        raise ProtocolError(f"unknown message type {message.get('type')!r}; a client sends 'generate'")
    request_id, config, items = message.get("id"), message.get("config"), message.get("episodes")
    if not isinstance(request_id, int) or not isinstance(config, str) or not isinstance(items, list):
        raise ProtocolError("a 'generate' message needs an integer 'id', a 'config' and a list 'episodes'")
    if not 1 <= len(items) <= batch_size:
        raise ProtocolError(f"{len(items)} episodes in one request; this server takes 1 to {batch_size}")
    episodes = []
    for i, item in enumerate(items):
        label = item.get("episode") if isinstance(item, dict) else None
        where = label if isinstance(label, str) else f"episode {i}"
        if not isinstance(item, dict) or not isinstance(label, str):
            raise ProtocolError(f"{where}: an episode is a map with a string 'episode'")
        frame, actions, fps, seed = (item.get(k) for k in ("first_frame", "actions", "fps", "seed"))
        if not (isinstance(frame, np.ndarray) and frame.dtype == np.uint8 and frame.ndim == 3 and frame.shape[2] == 3):
            raise ProtocolError(f"{where}: 'first_frame' must be an (H, W, 3) uint8 array, got {_preview(frame)}")
        if not (isinstance(actions, np.ndarray) and actions.dtype == np.float32 and actions.ndim == 2
                and len(actions)):
            raise ProtocolError(f"{where}: 'actions' must be a (T, D) float32 array, got {_preview(actions)}")
        if not isinstance(fps, (int, float)) or isinstance(fps, bool) or not isinstance(seed, int):
            raise ProtocolError(f"{where}: 'fps' must be a number and 'seed' an integer")
        episodes.append(Episode(label, Request(frame.copy(), actions.copy(), float(fps), int(seed))))
    return request_id, config, episodes


def frames_message(request_id: int, videos: list[np.ndarray], seconds: float) -> dict:
    return {"type": "frames", "id": request_id, "videos": videos, "seconds": float(seconds)}


def error_message(request_id: int | None, message: str) -> dict:
    return {"type": "error", "id": request_id, "message": message}


def read_reply(message: dict, request_id: int, count: int) -> tuple[list[np.ndarray], float]:
    """(videos, seconds) of the server's answer to request `request_id` of `count` episodes. An "error" reply is a
    ServerError carrying the server's message; anything else off the protocol a ProtocolError."""
    kind = message.get("type")
    if message.get("id") not in (request_id, None) or (kind == "frames" and message.get("id") != request_id):
        raise ProtocolError(f"a reply to request {message.get('id')!r} where {request_id} was expected")
    if kind == "error":
        raise ServerError(str(message.get("message")))
    if kind != "frames":
        raise ProtocolError(f"a reply of type {kind!r}; expected 'frames' or 'error'")
    videos, seconds = message.get("videos"), message.get("seconds", 0.0)
    if not isinstance(videos, list) or len(videos) != count:
        got = f"{len(videos)} video(s)" if isinstance(videos, list) else _preview(videos)
        raise ProtocolError(f"asked for {count} video(s), the reply holds {got}")
    if not isinstance(seconds, (int, float)) or isinstance(seconds, bool) or not math.isfinite(seconds):
        seconds = 0.0
    return videos, float(seconds)


class ServerError(RuntimeError):
    """The server's "error" reply: its model failed or refused the request; the message is the server's."""


def _preview(obj: object) -> str:
    if isinstance(obj, np.ndarray):
        return f"an array of shape {obj.shape} and dtype {obj.dtype}"
    return f"a {type(obj).__name__}"
