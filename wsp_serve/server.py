"""`wsp-serve module:callable --port P`: serve a per-episode or batched model callable (`wsp_serve.callables`)
to `wsp generate --model ws://HOST:PORT` over the protocol of `wsp_serve.protocol`.

Each connection gets the handshake, then one reply per request, in order. A request the server cannot read, a
model that raises and frames that fail the checks `wsp generate` makes in process (shape, count, resolution, NaN,
range) are answered with an "error" message naming the episode; the connection stays open, and the traceback of a
model's exception goes to the server's log (stderr). Each connection has a thread of its own and the model runs one
request at a time; websockets answers pings beside it, so a long generation keeps the connection alive.
`GET /healthz` answers "OK".
"""

from __future__ import annotations

import argparse
import http
import sys
import threading
import time
import traceback
from collections.abc import Callable

import numpy as np
from websockets.exceptions import ConnectionClosed
from websockets.sync.server import Server, ServerConnection, serve

from wsp_serve.callables import CallableError, batch_size_of, check_frames, load_callable, run_batch
from wsp_serve.protocol import (ACTION_KEYS, Handshake, ProtocolError, decode, encode, error_message,
                                frames_message, read_request)


class ModelServer:
    """Answers the protocol's requests with `model`, as `handshake` states it."""

    def __init__(self, model: Callable, handshake: Handshake, log: Callable[[str], None] | None = None):
        self.model, self.handshake = model, handshake
        self.hello = encode(handshake.message())  # fails here, at start, on a wsp_info msgpack cannot carry
        self.lock = threading.Lock()
        self.log = log or (lambda line: print(f"wsp-serve: {line}", file=sys.stderr, flush=True))

    def handle(self, connection: ServerConnection) -> None:
        """One client: the handshake, then a reply to every message until it disconnects."""
        try:
            connection.send(self.hello)
            for data in connection:
                connection.send(encode(self.answer(data)))
        except ConnectionClosed:
            pass

    def answer(self, data: bytes | str) -> dict:
        """The reply to one message: its frames, or an error saying what is wrong."""
        request_id = None
        try:
            message = decode(data)
            request_id = message.get("id") if isinstance(message.get("id"), int) else None
            request_id, config, episodes = read_request(message, self.handshake.batch_size)
        except ProtocolError as e:
            return error_message(request_id, f"bad request: {e}")
        where = ", ".join(e.label for e in episodes[:3]) + (f" (+{len(episodes) - 3} more)" if len(episodes) > 3
                                                              else "")
        with self.lock:
            start = time.perf_counter()
            try:
                videos = run_batch(self.model, [e.request for e in episodes])
            except Exception as e:  # the model's own failure: reported to the client, the server keeps serving
                self.log(f"the model failed on {where}:\n{traceback.format_exc()}")
                return error_message(request_id, f"{where}: the model raised {type(e).__name__}: {e}")
            seconds = time.perf_counter() - start
        if not isinstance(videos, (list, tuple)) or len(videos) != len(episodes):
            got = f"{len(videos)} item(s)" if isinstance(videos, (list, tuple)) else f"a {type(videos).__name__}"
            return error_message(request_id, f"{where}: asked for {len(episodes)} video(s), the model returned "
                                             f"{got}; a batched model returns one frame array per request, in order")
        try:
            checked = [check_frames(v, len(e.request.actions), e.label, e.request.first_frame.shape[:2],
                                    of="the request's") for v, e in zip(videos, episodes)]
        except CallableError as e:
            return error_message(request_id, str(e))
        return frames_message(request_id, [np.ascontiguousarray(v) for v in checked], seconds)


def start(model: Callable, handshake: Handshake, host: str = "127.0.0.1", port: int = 8000) -> Server:
    """A server of `model` bound to `host:port` (0: any free port), not yet serving: call `serve_forever()` (and
    `shutdown()` from another thread to stop it)."""
    server = ModelServer(model, handshake)
    return serve(server.handle, host, port, compression=None, max_size=None, process_request=health_check)


def health_check(connection: ServerConnection, request) -> object:
    """`GET /healthz` answers 200 OK without a websocket; every other path goes on to the handshake."""
    if request.path == "/healthz":
        return connection.respond(http.HTTPStatus.OK, "OK\n")
    return None


def resolution(text: str) -> tuple[int, int]:
    """'256x256' (width x height) as (256, 256)."""
    try:
        width, height = (int(v) for v in text.lower().replace("×", "x").split("x"))
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r}: expected WIDTHxHEIGHT, e.g. 256x256") from None
    return width, height


def parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="wsp-serve", description="Serve a world model to `wsp generate --model "
                                "ws://HOST:PORT` (docs/guides/model-server.md).")
    p.add_argument("model", help="MODULE:CALLABLE: a per-episode callable (first_frame, actions, fps, seed) -> "
                                 "frames, or a batched one with wsp_batch_size")
    p.add_argument("--port", type=int, default=8000, help="port (default 8000; 0 = any free port)")
    p.add_argument("--host", default="127.0.0.1", help="address to listen on (default 127.0.0.1; 0.0.0.0 for "
                                                       "other machines)")
    p.add_argument("--name", help="model name stated in the handshake (default: MODULE:CALLABLE)")
    p.add_argument("--model-version", help="model version stated in the handshake (default: wsp_info's "
                                           "'version', else 'unspecified')")
    p.add_argument("--action-key", choices=ACTION_KEYS, default="action",
                   help="the action stream the model wants (default: the platform's native 'action')")
    p.add_argument("--resolution", type=resolution, help="WIDTHxHEIGHT the model generates at, when not the "
                                                         "reference's: the client converts (documented resampling)")
    p.add_argument("--fps", type=float, help="frame rate the model generates at, when not the release's")
    return p


def main(argv: list[str] | None = None) -> int:
    args = parser().parse_args(argv)
    try:
        model = load_callable(args.model)
        info = getattr(model, "wsp_info", None)
        info = info if isinstance(info, dict) else {}
        version = args.model_version or str(info.get("version", "unspecified"))
        handshake = Handshake(args.name or args.model, version, args.action_key, args.resolution, args.fps,
                              batch_size_of(model) or 1, info)
        server = start(model, handshake, args.host, args.port)
    except (CallableError, ProtocolError) as e:
        print(f"wsp-serve: error: {e}", file=sys.stderr)
        return 2
    except (TypeError, ValueError) as e:  # msgpack cannot carry the model's wsp_info
        print(f"wsp-serve: error: the model's wsp_info cannot be sent ({e}): keep to strings, numbers, lists and "
              "maps", file=sys.stderr)
        return 2
    except OSError as e:
        print(f"wsp-serve: error: cannot listen on {args.host}:{args.port} ({e})", file=sys.stderr)
        return 2
    host, port = server.socket.getsockname()[:2]
    size = "x".join(map(str, handshake.resolution)) if handshake.resolution else "the reference's"
    rate = handshake.fps or "the release's"
    print(f"wsp-serve: serving {handshake.model} (version {handshake.version}) on ws://{host}:{port}; batch size "
          f"{handshake.batch_size}, action key {handshake.action_key}, resolution {size}, fps "
          f"{rate}", file=sys.stderr, flush=True)
    try:
        server.serve_forever()
    except KeyboardInterrupt:
        print("wsp-serve: stopped", file=sys.stderr)
    finally:
        server.server_close()
    return 0
