"""A local OpenAI-compatible chat-completions server for tests (stdlib http.server, 127.0.0.1 only).

It serves recorded responses from ``tests/data/llm/*.json`` (complete
``chat.completion`` bodies) and can simulate a misbehaving endpoint::

    with ChatServer(routes=[("Failure category", "sg_fixed.json")], default="sg_first.json") as server:
        client = ChatClient(server.base_url, "gpt-4o")
        ...
        server.requests        # every request body (parsed JSON), in order
        server.request_count   # how many requests arrived

Which recorded response answers a request:

* ``queue``: file names served in order, one per request (the last one repeats);
* otherwise ``routes``: ``(substring, file name)`` pairs, the first whose
  substring occurs in the text of the request's last user message wins;
* otherwise ``default``.

Fault modes (``mode=``):

* ``"ok"``: answer normally;
* ``"slow"``: wait ``delay`` seconds before answering (client timeouts);
* ``"flaky"``: answer the first ``fail_times`` requests with ``fail_status``
  (500 by default; 429 works too), then normally (retries);
* ``"status"``: always answer ``fail_status`` (401, 404...) with an OpenAI-style error body;
* ``"malformed"``: answer 200 with a body that is not JSON;
* ``"no_choices"``: answer 200 with a completion whose ``choices`` is empty.

:func:`closed_port_url` gives a URL on which nothing listens (connection refused).
"""

from __future__ import annotations

import json
import socket
import threading
import time
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer
from pathlib import Path
from typing import Any, Dict, List, Optional, Sequence, Tuple

DATA = Path(__file__).resolve().parent / "data" / "llm"
MODES = ("ok", "slow", "flaky", "status", "malformed", "no_choices")

__all__ = ["ChatServer", "closed_port_url", "load_recorded", "last_user_text", "DATA"]


def load_recorded(name: str) -> Dict[str, Any]:
    """A recorded chat-completion body from ``tests/data/llm``."""
    return json.loads((DATA / name).read_text(encoding="utf-8"))


def last_user_text(body: Dict[str, Any]) -> str:
    """The text of the last user message of a chat request (text parts joined)."""
    for message in reversed(body.get("messages", [])):
        if message.get("role") == "user":
            content = message.get("content")
            if isinstance(content, str):
                return content
            return " ".join(p.get("text", "") for p in content or [] if isinstance(p, dict))
    return ""


def closed_port_url() -> str:
    """``http://127.0.0.1:<port>/v1`` for a port nothing listens on (connection refused)."""
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as sock:
        sock.bind(("127.0.0.1", 0))
        port = sock.getsockname()[1]
    return f"http://127.0.0.1:{port}/v1"


class ChatServer:
    """The server; use as a context manager (or :meth:`start` / :meth:`stop`)."""

    def __init__(
        self,
        *,
        routes: Sequence[Tuple[str, str]] = (),
        queue: Sequence[str] = (),
        default: Optional[str] = None,
        mode: str = "ok",
        delay: float = 0.0,
        fail_times: int = 0,
        fail_status: int = 500,
    ) -> None:
        if mode not in MODES:
            raise ValueError(f"mode must be one of {MODES}")
        self.routes = list(routes)
        self.queue = list(queue)
        self.default = default
        self.mode = mode
        self.delay = delay
        self.fail_times = fail_times
        self.fail_status = fail_status
        self.requests: List[Dict[str, Any]] = []
        self.headers: List[Dict[str, str]] = []
        self.paths: List[str] = []
        self.request_times: List[float] = []
        self._lock = threading.Lock()
        self._stopping = threading.Event()
        self._httpd: Optional[ThreadingHTTPServer] = None
        self._thread: Optional[threading.Thread] = None

    # ----------------------------------------------------------------- control
    @property
    def port(self) -> int:
        assert self._httpd is not None, "server not started"
        return self._httpd.server_address[1]

    @property
    def base_url(self) -> str:
        return f"http://127.0.0.1:{self.port}/v1"

    @property
    def request_count(self) -> int:
        with self._lock:
            return len(self.paths)

    def start(self) -> "ChatServer":
        server = self

        class Handler(BaseHTTPRequestHandler):
            protocol_version = "HTTP/1.1"

            def log_message(self, *args: Any) -> None:  # keep test output clean
                pass

            def do_POST(self) -> None:  # noqa: N802 (http.server naming)
                server._handle(self)

            def do_GET(self) -> None:  # noqa: N802
                server._send(self, 404, {"error": {"message": "only POST /v1/chat/completions is served"}})

        self._httpd = ThreadingHTTPServer(("127.0.0.1", 0), Handler)
        self._httpd.daemon_threads = True
        self._httpd.handle_error = lambda request, address: None  # a client that timed out closes early
        self._thread = threading.Thread(target=self._httpd.serve_forever, kwargs={"poll_interval": 0.05},
                                        daemon=True)
        self._thread.start()
        return self

    def stop(self) -> None:
        self._stopping.set()
        if self._httpd is not None:
            self._httpd.shutdown()
            self._httpd.server_close()
        if self._thread is not None:
            self._thread.join(timeout=5)

    def __enter__(self) -> "ChatServer":
        return self.start()

    def __exit__(self, *exc: Any) -> None:
        self.stop()

    # ---------------------------------------------------------------- serving
    def _send(self, handler: BaseHTTPRequestHandler, status: int, body: Any, raw: Optional[bytes] = None) -> None:
        data = raw if raw is not None else json.dumps(body).encode("utf-8")
        try:
            handler.send_response(status)
            handler.send_header("Content-Type", "application/json" if raw is None else "text/html")
            handler.send_header("Content-Length", str(len(data)))
            if status == 429:
                handler.send_header("Retry-After", "0")
            handler.end_headers()
            handler.wfile.write(data)
        except (BrokenPipeError, ConnectionResetError):
            pass

    def _pick(self, body: Dict[str, Any], index: int) -> str:
        if self.queue:
            return self.queue[min(index, len(self.queue) - 1)]
        text = last_user_text(body)
        for needle, name in self.routes:
            if needle in text:
                return name
        if self.default is None:
            raise LookupError(f"no recorded response matches: {text[:200]!r}")
        return self.default

    def _handle(self, handler: BaseHTTPRequestHandler) -> None:
        length = int(handler.headers.get("Content-Length") or 0)
        raw = handler.rfile.read(length) if length else b""
        try:
            body = json.loads(raw.decode("utf-8")) if raw else {}
        except ValueError:
            body = {"_unparsable": raw[:200].decode("utf-8", "replace")}
        with self._lock:
            index = len(self.paths)
            self.paths.append(handler.path)
            self.requests.append(body)
            self.headers.append({k: v for k, v in handler.headers.items()})
            self.request_times.append(time.monotonic())
        if not handler.path.rstrip("/").endswith("/chat/completions"):
            self._send(handler, 404, {"error": {"message": f"unknown path {handler.path}", "type": "invalid_request_error"}})
            return
        if self.mode == "slow":
            end = time.monotonic() + self.delay
            while time.monotonic() < end and not self._stopping.is_set():
                time.sleep(0.01)
        if self.mode == "flaky" and index < self.fail_times or self.mode == "status":
            status = self.fail_status
            messages = {
                401: ("Incorrect API key provided: sk-test***. You can find your API key at your account page.",
                      "invalid_request_error", "invalid_api_key"),
                404: (f"The model `{body.get('model')}` does not exist or you do not have access to it.",
                      "invalid_request_error", "model_not_found"),
                429: ("Rate limit reached for requests. Please try again in 20ms.", "requests", "rate_limit_exceeded"),
            }
            message, kind, code = messages.get(status, ("The server had an error while processing your request.",
                                                        "server_error", None))
            self._send(handler, status, {"error": {"message": message, "type": kind, "param": None, "code": code}})
            return
        if self.mode == "malformed":
            self._send(handler, 200, None, raw=b"<html><body>502 Bad Gateway: upstream unavailable</body></html>")
            return
        if self.mode == "no_choices":
            self._send(handler, 200, {"id": "chatcmpl-empty", "object": "chat.completion", "created": 0,
                                      "model": body.get("model"), "choices": [], "usage": {}})
            return
        try:
            name = self._pick(body, index)
        except LookupError as error:
            self._send(handler, 400, {"error": {"message": str(error), "type": "invalid_request_error"}})
            return
        self._send(handler, 200, load_recorded(name))
