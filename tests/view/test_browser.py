"""``haptic-view`` in a real browser: headless Chromium (Debian's ``chromium``, driven by
Playwright through its executable path) loads the page during a short networked run, sees the
workpiece change as the tool cuts, and takes a screenshot kept as an artifact
(``out/test-artifacts/haptic-view.png``, with ``haptic-view.json``: what the page saw).

Skipped, with the reason, when Playwright or Chromium is not installed (CI installs both
and sets HAPTIC_REQUIRE_BROWSER=1 so that it fails instead: .ci/run). The frame rate the
page saw is written to the artifact, never asserted.
Children are ended by their own PIDs and always reaped; every wait is bounded."""

from __future__ import annotations

import json
import os
import shutil
import socket
import time
import urllib.request
import uuid
from pathlib import Path

import pytest

from haptic.common.wire.ports import free_port
from tests.helpers.programs import Programs, python_module

CHROMIUM = os.environ.get("HAPTIC_CHROMIUM") or shutil.which("chromium") or "/usr/bin/chromium"
ARTIFACTS = Path(__file__).resolve().parents[2] / "out" / "test-artifacts"
LAUNCH_ARGS = ["--headless", "--no-sandbox", "--disable-gpu", "--disable-background-networking",
               "--disable-component-update", "--disable-sync", "--no-first-run"]
WAIT_S = 60.0


def _wait_http(url: str, deadline: float) -> None:
    while time.monotonic() < deadline:
        try:
            with urllib.request.urlopen(url, timeout=1.0):
                return
        except OSError:
            time.sleep(0.1)
    raise AssertionError(f"{url} did not answer")


def _unavailable(reason: str) -> None:
    """Skip with the reason; fail instead where the browser is required (CI sets
    HAPTIC_REQUIRE_BROWSER=1)."""
    if os.environ.get("HAPTIC_REQUIRE_BROWSER"):
        pytest.fail(f"HAPTIC_REQUIRE_BROWSER is set but {reason}")
    pytest.skip(reason)


def _wait_port(port: int, deadline: float) -> None:
    while time.monotonic() < deadline:
        try:
            with socket.create_connection(("127.0.0.1", port), timeout=1.0):
                return
        except OSError:
            time.sleep(0.1)
    raise AssertionError(f"nothing listens on port {port}")


def test_page_shows_the_cut_in_chromium(tmp_path: Path) -> None:
    try:
        from playwright import sync_api
    except ImportError:
        _unavailable("playwright is not installed (pip install playwright)")
    if not os.path.exists(CHROMIUM):
        _unavailable(f"chromium is not installed at {CHROMIUM} (apt-get install chromium)")
    config = tmp_path / "clay.toml"
    config.write_text('[slave]\nscenario = "constant-rate"\nenvironment = "clay"\n'
                      'clay_impl = "numpy"\ndevice = "cpu"\n')
    master_port = free_port()
    endpoint = f"tcp/127.0.0.1:{master_port}"
    prefix = f"test/{uuid.uuid4().hex[:8]}"
    port = free_port()
    common = ["--config", str(config), "--key-prefix", prefix]
    # The master's peer wait covers the view's start, Chromium's launch and first page, and
    # the slave's start (Python, Warp, Zenoh): 20-30 s on a slow, busy machine.
    run = ["--no-status", "--peer-wait", "120", "--duration", "8"]
    with Programs() as programs:
        # The master first (it listens and waits for the slave), then the view connects to
        # it, the page loads, and only then the slave starts: the page sees the whole cut.
        programs.start(python_module(
            "haptic.master.cli", *common, *run, "--listen", endpoint, "--rig", "model",
            "--operator", "regulate:fx=3.6,onset=0.1,max=5"))
        _wait_port(master_port, time.monotonic() + WAIT_S)
        programs.start(python_module(
            "haptic.view.cli", *common, "--connect", endpoint, "--port", str(port)))
        url = f"http://127.0.0.1:{port}/"
        _wait_http(url, time.monotonic() + WAIT_S)
        with sync_api.sync_playwright() as playwright:
            browser = playwright.chromium.launch(executable_path=CHROMIUM, headless=True,
                                                 args=LAUNCH_ARGS)
            try:
                page = browser.new_page(viewport={"width": 1300, "height": 700})
                page.goto(url)
                programs.start(python_module(
                    "haptic.slave_sim.cli", *common, *run, "--connect", endpoint))
                timeout_ms = WAIT_S * 1000
                page.wait_for_function("window.hapticView && window.hapticView.clayVersion > 0"
                                       " && window.hapticView.layout !== null",
                                       timeout=timeout_ms)
                first = page.evaluate("window.hapticView.claySumMm")
                first_image = page.evaluate("document.getElementById('work').toDataURL()")
                # The tool cuts: the clay the page shows loses height.
                page.wait_for_function(
                    f"window.hapticView.claySumMm < {first} * 0.995", timeout=timeout_ms)
                frames_before = page.evaluate("window.hapticView.frames")
                page.wait_for_timeout(1000)
                frames_after = page.evaluate("window.hapticView.frames")
                seen = page.evaluate(
                    "({frames: hapticView.frames, fps: hapticView.fps, draws: hapticView.draws, "
                    "scale: hapticView.scale, "
                    "clayVersion: hapticView.clayVersion, claySumMm: hapticView.claySumMm, "
                    "claySumInitialMm: hapticView.claySumInitialMm, "
                    "tool: hapticView.last.tool, status: hapticView.last.status})")
                last_image = page.evaluate("document.getElementById('work').toDataURL()")
                ARTIFACTS.mkdir(parents=True, exist_ok=True)
                page.screenshot(path=str(ARTIFACTS / "haptic-view.png"), full_page=True)
            finally:
                browser.close()
    seen["frames_in_one_second"] = frames_after - frames_before
    (ARTIFACTS / "haptic-view.json").write_text(json.dumps(seen, indent=2))
    assert seen["claySumMm"] < seen["claySumInitialMm"]
    assert seen["tool"]["tool_position_m"][0] is not None
    assert set(seen["status"]) == {"master", "slave"}
    assert first_image != last_image  # the canvas changed with the cut
    # the page draws only when a frame came (and once before the first): it follows the
    # server's rate, which backs off while a loop overruns
    assert 1 <= seen["draws"] <= seen["frames"] + 1
    assert 0.0 < seen["scale"] <= 1.0
    assert (ARTIFACTS / "haptic-view.png").stat().st_size > 10_000
