"""The view's HTTP server: static files from the package, one JSON snapshot, SSE frames with
the clay only when it changed."""

from __future__ import annotations

import json
import urllib.error
import urllib.request

import pytest

from haptic.view.server import ViewServer
from haptic.view.state import ViewState


def _get(url: str) -> tuple[int, bytes, str]:
    with urllib.request.urlopen(url, timeout=5) as response:
        return response.status, response.read(), response.headers["Content-Type"]


def test_static_files_snapshot_and_events() -> None:
    state = ViewState()
    with ViewServer(state, port=0) as server:
        status, body, kind = _get(server.url)
        assert status == 200 and b"/static/view.js" in body and kind.startswith("text/html")
        status, body, kind = _get(server.url + "static/view.js")
        assert status == 200 and b"EventSource" in body and "javascript" in kind
        with pytest.raises(urllib.error.HTTPError):
            _get(server.url + "static/../cli.py")
        state.update(tool={"tool_position_m": [0.01, float("nan")]},
                     layout={"cells_x": 2, "cells_y": 1}, clay=({"cells_x": 2}, b"\x01\x00"))
        snapshot = json.loads(_get(server.url + "state")[1])
        assert snapshot["tool"]["tool_position_m"] == [0.01, None]  # NaN -> null
        assert snapshot["clay"]["heights_u16_b64"] == "AQA="
        with urllib.request.urlopen(server.url + "events", timeout=5) as stream:
            frames = []
            while len(frames) < 2:
                line = stream.readline()
                if line.startswith(b"data: "):
                    frames.append(json.loads(line[6:]))
                    state.update(handle={"handle_force_N": [1.0, 0.0]})
        assert "clay" in frames[0] and "layout" in frames[0]
        assert "clay" not in frames[1] and frames[1]["handle"]["handle_force_N"] == [1.0, 0.0]
        assert server.stats()["frames_sent"] >= 1
