"""Headless Debian Chromium driven over the DevTools protocol on a pipe (no websocket, no extra package).

``with Browser() as b: page = b.open(url)`` loads a page; ``page.eval(js)`` evaluates an
expression (awaiting promises), ``page.screenshot()`` returns PNG bytes, ``page.drag(...)`` and
``page.wheel(...)`` send mouse input, ``page.console`` collects console messages and
``page.requests`` every URL the page asked for. Chromium runs with the project's flags
(--headless --no-sandbox --disable-gpu --disable-quic --no-first-run --disable-background-networking
--disable-component-update --disable-sync, a fresh --user-data-dir) and WebGL on SwiftShader.
"""

from __future__ import annotations

import base64
import json
import os
import shutil
import subprocess
import tempfile
import time

CHROMIUM = shutil.which("chromium") or shutil.which("chromium-browser")
FLAGS = ["--headless", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
         "--disable-background-networking", "--disable-component-update", "--disable-sync",
         "--enable-unsafe-swiftshader", "--use-angle=swiftshader", "--hide-scrollbars", "--mute-audio"]


class Page:
    def __init__(self, browser: "Browser", session: str) -> None:
        self.b, self.session = browser, session
        self.console: list[str] = []
        self.requests: list[str] = []

    def send(self, method: str, **params):
        return self.b.send(method, params, session=self.session)

    def eval(self, expression: str, *, timeout: float = 60.0):
        r = self.b.send("Runtime.evaluate", {"expression": expression, "awaitPromise": True, "returnByValue": True,
                                             "timeout": int(timeout * 1000)}, session=self.session, timeout=timeout + 5)
        if "exceptionDetails" in r:
            raise RuntimeError(f"page exception: {r['exceptionDetails']}")
        return r["result"].get("value")

    def wait_for(self, expression: str, *, timeout: float = 60.0) -> object:
        """Poll ``expression`` until it is truthy; returns its value."""
        end = time.monotonic() + timeout
        while True:
            v = self.eval(expression)
            if v or time.monotonic() > end:
                return v
            time.sleep(0.2)

    def screenshot(self, *, clip: dict | None = None) -> bytes:
        params = {"format": "png", "captureBeyondViewport": clip is not None}
        if clip is not None:
            params["clip"] = {**clip, "scale": 1}
        return base64.b64decode(self.send("Page.captureScreenshot", **params)["data"])

    def drag(self, x0: float, y0: float, x1: float, y1: float, *, steps: int = 12, button: str = "left") -> None:
        self.send("Input.dispatchMouseEvent", type="mouseMoved", x=x0, y=y0)
        self.send("Input.dispatchMouseEvent", type="mousePressed", x=x0, y=y0, button=button, clickCount=1,
                  buttons=1 if button == "left" else 2)
        for k in range(1, steps + 1):
            x, y = x0 + (x1 - x0) * k / steps, y0 + (y1 - y0) * k / steps
            self.send("Input.dispatchMouseEvent", type="mouseMoved", x=x, y=y, button=button,
                      buttons=1 if button == "left" else 2)
        self.send("Input.dispatchMouseEvent", type="mouseReleased", x=x1, y=y1, button=button, clickCount=1)

    def wheel(self, x: float, y: float, delta: float) -> None:
        self.send("Input.dispatchMouseEvent", type="mouseWheel", x=x, y=y, deltaX=0, deltaY=delta)

    def click(self, x: float, y: float) -> None:
        for t in ("mousePressed", "mouseReleased"):
            self.send("Input.dispatchMouseEvent", type=t, x=x, y=y, button="left", clickCount=1)


class Browser:
    def __init__(self, width: int = 1280, height: int = 900) -> None:
        self.width, self.height = width, height

    def __enter__(self) -> "Browser":
        self._profile = tempfile.TemporaryDirectory()
        r_cmd, w_cmd = os.pipe()  # we write commands, Chromium reads fd 3
        r_out, w_out = os.pipe()  # Chromium writes fd 4, we read
        cmd = [CHROMIUM, *FLAGS, f"--user-data-dir={self._profile.name}", f"--window-size={self.width},{self.height}",
               "--remote-debugging-pipe", "about:blank"]

        # Chromium reads commands on fd 3 and writes on fd 4: move the pipe ends there (high fds first, so that
        # placing one cannot clobber the other) and keep just those two open
        hi_r, hi_w = os.dup(r_cmd) + 100, os.dup(w_out) + 100
        os.dup2(r_cmd, hi_r)
        os.dup2(w_out, hi_w)

        def fds() -> None:
            os.dup2(hi_r, 3)
            os.dup2(hi_w, 4)

        self.proc = subprocess.Popen(cmd, preexec_fn=fds, pass_fds=(3, 4, hi_r, hi_w), stdout=subprocess.DEVNULL,
                                     stderr=subprocess.DEVNULL)
        os.close(hi_r)
        os.close(hi_w)
        os.close(r_cmd)
        os.close(w_out)
        self._w, self._r = os.fdopen(w_cmd, "wb", buffering=0), os.fdopen(r_out, "rb", buffering=0)
        self._buf, self._id, self._events = b"", 0, []
        self._pages: dict[str, Page] = {}
        return self

    def __exit__(self, *exc) -> None:
        try:
            self.send("Browser.close", {}, timeout=10)
        except Exception:
            pass
        try:
            self.proc.wait(timeout=15)
        except subprocess.TimeoutExpired:
            self.proc.kill()
            self.proc.wait()
        for f in (self._w, self._r):
            f.close()
        self._profile.cleanup()

    def _read(self, timeout: float) -> dict:
        import select

        end = time.monotonic() + timeout
        while b"\0" not in self._buf:
            left = end - time.monotonic()
            if left <= 0 or not select.select([self._r], [], [], left)[0]:
                raise TimeoutError("Chromium did not answer in time")
            chunk = self._r.read(1 << 20)
            if not chunk:
                raise RuntimeError("Chromium closed the DevTools pipe")
            self._buf += chunk
        msg, self._buf = self._buf.split(b"\0", 1)
        return json.loads(msg)

    def _event(self, msg: dict) -> None:
        page = self._pages.get(msg.get("sessionId"))
        if page is None:
            return
        p = msg.get("params", {})
        if msg["method"] == "Runtime.consoleAPICalled":
            page.console.append(" ".join(str(a.get("value", a.get("description", ""))) for a in p.get("args", [])))
        elif msg["method"] == "Runtime.exceptionThrown":
            page.console.append("exception: " + json.dumps(p.get("exceptionDetails", {}))[:500])
        elif msg["method"] == "Network.requestWillBeSent":
            page.requests.append(p["request"]["url"])

    def send(self, method: str, params: dict, *, session: str | None = None, timeout: float = 60.0) -> dict:
        self._id += 1
        msg = {"id": self._id, "method": method, "params": params}
        if session:
            msg["sessionId"] = session
        self._w.write(json.dumps(msg).encode() + b"\0")
        while True:
            r = self._read(timeout)
            if r.get("id") == self._id:
                if "error" in r:
                    raise RuntimeError(f"{method}: {r['error']}")
                return r.get("result", {})
            if "method" in r:
                self._event(r)

    def open(self, url: str, *, timeout: float = 60.0, scripts: bool = True) -> Page:
        """A new tab on ``url``, loaded; ``scripts=False``: the page's own scripts do not run (what a capture taken
        before they ran shows; ``Page.eval`` still works)."""
        target = self.send("Target.createTarget", {"url": "about:blank"})["targetId"]
        session = self.send("Target.attachToTarget", {"targetId": target, "flatten": True})["sessionId"]
        page = Page(self, session)
        self._pages[session] = page
        for domain in ("Page", "Runtime", "Network"):
            page.send(f"{domain}.enable")
        page.send("Emulation.setDeviceMetricsOverride", width=self.width, height=self.height, deviceScaleFactor=1,
                  mobile=False)
        if not scripts:
            page.send("Emulation.setScriptExecutionDisabled", value=True)
        page.send("Page.navigate", url=url)
        page.wait_for("document.readyState === 'complete'", timeout=timeout)
        return page
