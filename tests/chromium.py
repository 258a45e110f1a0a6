"""Load a page in headless Chromium over the DevTools protocol (a pipe, no extra package).

``load(path)`` opens the file, waits for its load event and returns what the page did:
the console messages and exceptions, the log entries, every URL it requested, and the
value of a JavaScript expression evaluated in the loaded page; ``width`` emulates a
window that wide (a phone's with touch and the page's viewport tag below 600 px). Chromium
talks the
protocol over file descriptors 3 (commands in) and 4 (events out), one JSON message per
NUL-terminated chunk (``--remote-debugging-pipe``).
"""

from __future__ import annotations

import contextlib
import json
import os
import select
import shutil
import signal
import subprocess
import tempfile
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

NAMES = ("chromium", "chromium-browser", "google-chrome", "chrome")


def find() -> str | None:
    """Return the path of a Chromium binary, or None."""
    for name in NAMES:
        path = shutil.which(name)
        if path:
            return path
    return None


@dataclass
class Page:
    console: list[dict] = field(default_factory=list)
    exceptions: list[dict] = field(default_factory=list)
    log: list[dict] = field(default_factory=list)
    requests: list[str] = field(default_factory=list)
    value: Any = None


class _Pipe:
    def __init__(self, binary: str, profile: str) -> None:
        r_in, self.w_in = os.pipe()
        self.r_out, w_out = os.pipe()

        def child() -> None:
            os.dup2(r_in, 3)
            os.dup2(w_out, 4)

        args = [binary, "--headless", "--no-sandbox", "--disable-gpu", "--no-first-run",
                "--remote-debugging-pipe", f"--user-data-dir={profile}", "about:blank"]  # fmt: skip
        self.proc = subprocess.Popen(
            args, pass_fds=(3, 4), preexec_fn=child, start_new_session=True,
            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
        )  # fmt: skip
        os.close(r_in)
        os.close(w_out)
        self.buf, self.next_id, self.events = b"", 0, []

    def send(self, method: str, params: dict | None = None, session: str | None = None) -> int:
        self.next_id += 1
        msg: dict[str, Any] = {"id": self.next_id, "method": method, "params": params or {}}
        if session:
            msg["sessionId"] = session
        os.write(self.w_in, json.dumps(msg).encode() + b"\0")
        return self.next_id

    def wait(self, pred, timeout: float = 60.0) -> dict:
        end = time.monotonic() + timeout
        while time.monotonic() < end:
            while b"\0" in self.buf:
                raw, self.buf = self.buf.split(b"\0", 1)
                msg = json.loads(raw)
                self.events.append(msg)
                if pred(msg):
                    return msg
            ready, _, _ = select.select([self.r_out], [], [], 0.5)
            if ready:
                chunk = os.read(self.r_out, 1 << 20)
                if not chunk:
                    raise RuntimeError("chromium closed the DevTools pipe")
                self.buf += chunk
        raise TimeoutError("no answer from chromium")

    def call(self, method: str, params: dict | None = None, session: str | None = None) -> dict:
        i = self.send(method, params, session)
        reply = self.wait(lambda m: m.get("id") == i)
        if "error" in reply:
            raise RuntimeError(f"{method}: {reply['error']}")
        return reply.get("result", {})

    def close(self) -> None:
        # the whole group: Chromium's helper processes still write into the profile
        # after the browser process has gone (the profile's removal then fails)
        group = self.proc.pid  # its own session: the group's id is its pid
        with contextlib.suppress(ProcessLookupError):
            os.killpg(group, signal.SIGTERM)
        try:
            self.proc.wait(timeout=10)
        except subprocess.TimeoutExpired:
            self.proc.kill()
            self.proc.wait()
        with contextlib.suppress(ProcessLookupError):
            os.killpg(group, signal.SIGKILL)
        os.close(self.w_in)
        os.close(self.r_out)


def load(path: Path, expression: str, binary: str | None = None, width: int | None = None) -> Page:
    """Open ``path`` in headless Chromium; return what the page did and ``expression``.

    ``width``: the window's width in CSS pixels (default Chromium's own, 800).
    """
    binary = binary or find()
    if binary is None:
        raise FileNotFoundError("no chromium binary")
    with tempfile.TemporaryDirectory(ignore_cleanup_errors=True) as profile:
        pipe = _Pipe(binary, profile)
        try:
            target = pipe.call("Target.createTarget", {"url": "about:blank"})["targetId"]
            attach = {"targetId": target, "flatten": True}
            session = pipe.call("Target.attachToTarget", attach)["sessionId"]
            for method in ("Runtime.enable", "Log.enable", "Network.enable", "Page.enable"):
                pipe.call(method, session=session)
            if width is not None:
                metrics = {"width": width, "height": 900, "deviceScaleFactor": 1}
                metrics["mobile"] = width < 600  # honours <meta name="viewport">
                pipe.call("Emulation.setDeviceMetricsOverride", metrics, session)
            pipe.call("Page.navigate", {"url": Path(path).resolve().as_uri()}, session)
            pipe.wait(lambda m: m.get("method") == "Page.loadEventFired")
            result = pipe.call(
                "Runtime.evaluate",
                {"expression": expression, "returnByValue": True, "awaitPromise": True},
                session,
            )
        finally:
            pipe.close()
    page = Page(value=result.get("result", {}).get("value"))
    for m in pipe.events:
        method, params = m.get("method"), m.get("params", {})
        if method == "Runtime.consoleAPICalled":
            page.console.append(params)
        elif method == "Runtime.exceptionThrown":
            page.exceptions.append(params)
        elif method == "Log.entryAdded":
            page.log.append(params.get("entry", {}))
        elif method == "Network.requestWillBeSent":
            page.requests.append(params["request"]["url"])
    return page
