"""The view's HTTP server on localhost: the page and its script from the package's static
files, and the run's state as Server-Sent Events (``/events``, at most ``max_rate_hz`` frames
a second per browser) or one JSON snapshot (``/state``).

Each browser gets a thread (``ThreadingHTTPServer``); a handler waits on the
:class:`~haptic.view.state.ViewState` for a newer frame and sends it, so frames go out as fast
as they arrive up to the cap, the cap scaled by :attr:`ViewState.scale` (the view backs off
while a loop overruns: view/state.py). ``/stats`` reports what was served.
"""

from __future__ import annotations

import json
import threading
import time
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer
from importlib import resources
from typing import Any

from haptic.common.runtime.summary import json_safe
from haptic.view.state import ViewState

#: Default frame cap per browser, Hz.
DEFAULT_MAX_RATE_HZ = 60.0

_TYPES = {".html": "text/html; charset=utf-8", ".js": "text/javascript; charset=utf-8",
          ".css": "text/css; charset=utf-8"}


def static_file(name: str) -> bytes | None:
    """A file of the package's ``static`` folder (None when there is none)."""
    if "/" in name or name.startswith("."):
        return None
    entry = resources.files("haptic.view").joinpath("static", name)
    return entry.read_bytes() if entry.is_file() else None


class _QuietServer(ThreadingHTTPServer):
    """A browser or client that goes away mid-request is normal, not an error to print."""

    daemon_threads = True

    def handle_error(self, request: Any, client_address: Any) -> None:
        import sys

        if not isinstance(sys.exc_info()[1], (ConnectionError, TimeoutError)):
            super().handle_error(request, client_address)


class ViewServer:
    """Serves ``state`` on ``host:port`` (port 0: any free port; see :attr:`port`)."""

    def __init__(self, state: ViewState, port: int = 8765, host: str = "127.0.0.1",
                 max_rate_hz: float = DEFAULT_MAX_RATE_HZ) -> None:
        self.state = state
        self.min_interval_s = 1.0 / max_rate_hz
        self.frames_sent = 0
        self.clients = 0
        self._stop = threading.Event()
        server = self

        class Handler(BaseHTTPRequestHandler):
            protocol_version = "HTTP/1.1"

            def log_message(self, *_args: Any) -> None:  # quiet
                pass

            def do_GET(self) -> None:  # noqa: N802 - the stdlib's name
                path = self.path.split("?", 1)[0]
                if path == "/events":
                    server._serve_events(self)
                elif path == "/state":
                    self._send(json.dumps(json_safe(server.state.snapshot())).encode(),
                               "application/json")
                elif path == "/stats":
                    self._send(json.dumps(server.stats()).encode(), "application/json")
                else:
                    name = "index.html" if path in ("/", "/index.html") else path.rsplit("/", 1)[-1]
                    data = static_file(name) if path.startswith(("/static/", "/index")) \
                        or path == "/" else None
                    if data is None:
                        self._send(b"not found\n", "text/plain", status=404)
                    else:
                        suffix = name[name.rfind("."):]
                        self._send(data, _TYPES.get(suffix, "application/octet-stream"))

            def _send(self, body: bytes, content_type: str, status: int = 200) -> None:
                self.send_response(status)
                self.send_header("Content-Type", content_type)
                self.send_header("Content-Length", str(len(body)))
                self.send_header("Cache-Control", "no-store")
                self.end_headers()
                self.wfile.write(body)

        self._httpd = _QuietServer((host, port), Handler)
        self.host = host
        self.port = self._httpd.server_address[1]
        self._thread: threading.Thread | None = None

    @property
    def url(self) -> str:
        return f"http://{self.host}:{self.port}/"

    def start(self) -> ViewServer:
        self._thread = threading.Thread(target=self._httpd.serve_forever, name="view-http",
                                        daemon=True)
        self._thread.start()
        return self

    def stop(self) -> None:
        self._stop.set()
        self._httpd.shutdown()
        self._httpd.server_close()
        if self._thread is not None:
            self._thread.join(timeout=5.0)

    def __enter__(self) -> ViewServer:
        return self.start()

    def __exit__(self, *_exc: object) -> None:
        self.stop()

    def stats(self) -> dict[str, Any]:
        state = self.state
        elapsed = time.monotonic() - state.started
        return {"frames_sent": self.frames_sent, "clients": self.clients,
                "state_updates": state.updates,
                "state_update_rate_hz": state.updates / elapsed if elapsed > 0 else 0.0,
                "frame_scale": state.scale, "lowest_frame_scale": state.lowest_scale,
                "bad_loop_counts": state.bad_loop_counts}

    def _serve_events(self, handler: BaseHTTPRequestHandler) -> None:
        handler.send_response(200)
        handler.send_header("Content-Type", "text/event-stream")
        handler.send_header("Cache-Control", "no-store")
        handler.send_header("Connection", "close")
        handler.end_headers()
        handler.close_connection = True
        self.clients += 1
        seen = clay_seen = layout_seen = -1
        last_sent = 0.0
        try:
            while not self._stop.is_set():
                version = self.state.wait_newer(seen, 1.0)
                if version == seen:
                    handler.wfile.write(b": idle\n\n")
                    handler.wfile.flush()
                    continue
                wait = last_sent + self.min_interval_s / self.state.scale - time.monotonic()
                if wait > 0:
                    time.sleep(wait)
                snapshot = self.state.snapshot(clay_seen, layout_seen)
                seen = snapshot["version"]
                clay_seen = snapshot["clay_version"]
                layout_seen = snapshot["layout_version"]
                handler.wfile.write(b"data: " + json.dumps(json_safe(snapshot)).encode() + b"\n\n")
                handler.wfile.flush()
                last_sent = time.monotonic()
                self.frames_sent += 1
        except (BrokenPipeError, ConnectionResetError, OSError):
            pass
        finally:
            self.clients -= 1
