"""Headless Chromium for the report tests: find it (installing Debian's package when missing and
possible), load a page over the DevTools protocol, report image loads, console errors and
exceptions, and save a screenshot."""

from __future__ import annotations

import base64
import fcntl
import json
import os
import re
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

NAMES = ("chromium", "chromium-browser", "google-chrome", "google-chrome-stable")
INSTALL_LOCK = Path(tempfile.gettempdir()) / "posedyn-chromium-install.lock"


def _on_path() -> str | None:
    return next((shutil.which(name) for name in NAMES if shutil.which(name)), None)


def _why_not_installable() -> str:
    """Empty when Debian's chromium package can be installed here, else why not."""
    if os.environ.get("POSEDYN_NO_BROWSER_INSTALL"):
        return "no Chromium on PATH and POSEDYN_NO_BROWSER_INSTALL is set"
    if not shutil.which("apt-get"):
        return "no Chromium on PATH and no apt-get to install Debian's chromium package"
    if os.geteuid() != 0:
        return "no Chromium on PATH and not root, so Debian's chromium package cannot be installed"
    return ""


def find_or_install_chromium() -> tuple[str | None, str]:
    """(path, reason): the browser, or None and why it could not be had. One install at a time
    (a file lock): a call during `prefetch_chromium`'s install waits for it."""
    found = _on_path()
    if found:
        return found, ""
    reason = _why_not_installable()
    if reason:
        return None, reason
    with open(INSTALL_LOCK, "a") as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)
        found = _on_path()
        if found:
            return found, ""
        env = dict(os.environ, DEBIAN_FRONTEND="noninteractive")
        try:
            subprocess.run(["apt-get", "update", "-qq"], check=True, capture_output=True, timeout=600, env=env)
            subprocess.run(["apt-get", "install", "-y", "-qq", "--no-install-recommends", "chromium"], check=True, capture_output=True, timeout=900, env=env)
        except (subprocess.SubprocessError, OSError) as exc:
            detail = getattr(exc, "stderr", b"") or b""
            return None, f"installing Debian's chromium package failed: {exc} {detail.decode(errors='replace')[-300:]}"
    found = _on_path()
    return (found, "") if found else (None, "apt-get installed chromium but no browser binary is on PATH")


def prefetch_chromium() -> subprocess.Popen | None:
    """Start `find_or_install_chromium` in a background process when it would install: `make
    test` calls it at the start, so the download (about 45 s) overlaps the CPU-bound tests instead
    of holding a worker idle at the report test. None when there is nothing to install."""
    if _on_path() or _why_not_installable():
        return None
    return subprocess.Popen([sys.executable, __file__], stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)


def inspect_page(browser: str, page: Path, screenshot: Path, timeout_s: float = 60.0) -> dict:
    """Load `page` and return {"images": [{"src", "complete", "width", "height"}], "errors": [...]},
    writing a full-page PNG screenshot."""
    import websocket

    profile = tempfile.mkdtemp(prefix="posedyn-chromium-")
    args = [
        browser, "--headless=new", "--no-sandbox", "--disable-gpu", "--disable-dev-shm-usage", "--no-first-run",
        "--remote-debugging-port=0", f"--user-data-dir={profile}", "--window-size=1400,1000", "about:blank",
    ]
    proc = subprocess.Popen(args, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
    try:
        url = _devtools_url(proc, timeout_s)
        ws = websocket.create_connection(url, timeout=timeout_s, suppress_origin=True)
        session = _Session(ws)
        target = session.call("Target.createTarget", {"url": "about:blank"})["targetId"]
        sid = session.call("Target.attachToTarget", {"targetId": target, "flatten": True})["sessionId"]
        for domain in ("Page", "Runtime", "Log"):
            session.call(f"{domain}.enable", {}, sid)
        session.call("Page.navigate", {"url": page.resolve().as_uri()}, sid)
        session.wait_for("Page.loadEventFired", timeout_s)
        images = session.call(
            "Runtime.evaluate",
            {"expression": "JSON.stringify(Array.from(document.images).map(i => ({src: i.src.slice(0, 40), complete: i.complete, width: i.naturalWidth, height: i.naturalHeight})))", "returnByValue": True},
            sid,
        )["result"]["value"]
        metrics = session.call("Page.getLayoutMetrics", {}, sid)
        size = metrics.get("cssContentSize") or metrics["contentSize"]
        shot = session.call("Page.captureScreenshot", {"format": "png", "captureBeyondViewport": True, "clip": {"x": 0, "y": 0, "width": size["width"], "height": size["height"], "scale": 1}}, sid)
        screenshot.write_bytes(base64.b64decode(shot["data"]))
        time.sleep(0.2)
        session.drain()
        ws.close()
        return {"images": json.loads(images), "errors": session.errors}
    finally:
        proc.terminate()
        try:
            proc.wait(10)
        except subprocess.TimeoutExpired:
            proc.kill()
        shutil.rmtree(profile, ignore_errors=True)


def _devtools_url(proc, timeout_s: float) -> str:
    deadline = time.monotonic() + timeout_s
    lines = []
    while time.monotonic() < deadline:
        line = proc.stderr.readline()
        if not line:
            if proc.poll() is not None:
                break
            continue
        lines.append(line)
        match = re.search(r"DevTools listening on (ws://\S+)", line)
        if match:
            return match.group(1)
    raise RuntimeError("Chromium did not start its DevTools endpoint:\n" + "".join(lines[-20:]))


class _Session:
    """A minimal DevTools client: numbered calls, events kept, errors collected."""

    def __init__(self, ws):
        self.ws, self.next_id, self.events, self.errors = ws, 0, [], []

    def call(self, method: str, params: dict, session_id: str | None = None) -> dict:
        self.next_id += 1
        message = {"id": self.next_id, "method": method, "params": params}
        if session_id:
            message["sessionId"] = session_id
        self.ws.send(json.dumps(message))
        while True:
            reply = self._receive()
            if reply.get("id") == self.next_id:
                if "error" in reply:
                    raise RuntimeError(f"{method}: {reply['error']}")
                return reply.get("result", {})

    def wait_for(self, event: str, timeout_s: float) -> None:
        deadline = time.monotonic() + timeout_s
        if any(e.get("method") == event for e in self.events):
            return
        while time.monotonic() < deadline:
            if self._receive().get("method") == event:
                return
        raise TimeoutError(event)

    def drain(self) -> None:
        self.ws.settimeout(0.2)
        try:
            while True:
                self._receive()
        except Exception:  # noqa: BLE001 - the socket's timeout ends the drain
            pass

    def _receive(self) -> dict:
        message = json.loads(self.ws.recv())
        method = message.get("method")
        if method:
            self.events.append(message)
            params = message.get("params", {})
            if method == "Runtime.exceptionThrown":
                self.errors.append(f"exception: {params.get('exceptionDetails', {}).get('text')}")
            elif method == "Runtime.consoleAPICalled" and params.get("type") in ("error", "assert"):
                self.errors.append(f"console.{params['type']}: {params.get('args')}")
            elif method == "Log.entryAdded" and params.get("entry", {}).get("level") == "error":
                self.errors.append(f"log: {params['entry'].get('text')} {params['entry'].get('url', '')}")
        return message


if __name__ == "__main__":  # prefetch_chromium's background install
    find_or_install_chromium()
