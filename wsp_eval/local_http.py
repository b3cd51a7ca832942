"""The request handler the local pages share (`wsp rate`, `wsp teleop`): quiet, JSON in and out, no caching."""

from __future__ import annotations

import json
from http.server import BaseHTTPRequestHandler


class JsonRequestHandler(BaseHTTPRequestHandler):
    """A quiet HTTP/1.1 handler with helpers to send bytes or JSON and to read a bounded JSON-object body."""

    protocol_version = "HTTP/1.1"

    def log_message(self, format, *args) -> None:  # noqa: A002 - quiet terminal: one request per click or key
        pass

    def _send(self, status: int, body: bytes, ctype: str) -> None:
        self.send_response(status)
        self.send_header("Content-Type", ctype)
        self.send_header("Content-Length", str(len(body)))
        self.send_header("Cache-Control", "no-store")
        self.end_headers()
        self.wfile.write(body)

    def _json(self, obj, status: int = 200) -> None:
        self._send(status, json.dumps(obj).encode(), "application/json")

    def _json_body(self, limit: int, error: type[Exception]) -> dict:
        """The request body as a JSON object (empty: {}), or `error` saying why not (over `limit` bytes, not
        JSON, not an object)."""
        n = int(self.headers.get("Content-Length") or 0)
        if n > limit:
            raise error("request body too large")
        raw = self.rfile.read(n) if n else b""
        try:
            obj = json.loads(raw or b"{}")
        except json.JSONDecodeError as e:
            raise error(f"request body is not JSON: {e}") from None
        if not isinstance(obj, dict):
            raise error("request body must be a JSON object")
        return obj
