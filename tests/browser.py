"""Headless Chromium driven over the DevTools protocol on a pipe, for the report tests.

``--remote-debugging-pipe``: commands on fd 3, replies on fd 4, NUL-terminated JSON.  That gives
console messages, exceptions, network requests, element positions and screenshots without any extra
package.
"""

from __future__ import annotations

import base64
import io
import json
import os
import select
import subprocess
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from matplotlib import image as mpimg

CHROMIUM_FLAGS = ("--headless", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
                  "--disable-background-networking", "--disable-component-update", "--disable-sync",
                  "--remote-debugging-pipe")


class Browser:
    """Minimal DevTools client: ``send`` a command, collect events until a reply or a deadline (hang
    guards: a niced Chromium's start alone can take a minute on a loaded machine)."""

    def __init__(self, exe: str, profile: Path) -> None:
        to_chrome_r, self._to_chrome = os.pipe()
        self._from_chrome, from_chrome_w = os.pipe()

        def wire_fds() -> None:  # the child finds the protocol on fds 3 (in) and 4 (out)
            os.dup2(to_chrome_r, 3)
            os.dup2(from_chrome_w, 4)

        self.proc = subprocess.Popen([exe, *CHROMIUM_FLAGS, f"--user-data-dir={profile}", "about:blank"],
                                     stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
                                     preexec_fn=wire_fds, pass_fds=(3, 4))
        os.close(to_chrome_r)
        os.close(from_chrome_w)
        self._buf = b""
        self._id = 0
        self.events: list[dict] = []

    def _read(self, deadline: float) -> dict:
        while b"\0" not in self._buf:
            left = deadline - time.monotonic()
            ready, _, _ = select.select([self._from_chrome], [], [], max(left, 0))
            if not ready:
                raise TimeoutError("chromium did not answer in time")
            chunk = os.read(self._from_chrome, 1 << 20)
            if not chunk:
                raise RuntimeError("chromium closed the DevTools pipe")
            self._buf += chunk
        msg, self._buf = self._buf.split(b"\0", 1)
        return json.loads(msg)

    def send(self, method: str, params: dict | None = None, session: str | None = None,
             timeout_s: float = 300.0) -> dict:
        self._id += 1
        cmd = {"id": self._id, "method": method, "params": params or {}}
        if session:
            cmd["sessionId"] = session
        os.write(self._to_chrome, json.dumps(cmd).encode() + b"\0")
        deadline = time.monotonic() + timeout_s
        while True:
            msg = self._read(deadline)
            if msg.get("id") == self._id:
                if "error" in msg:
                    raise RuntimeError(f"{method}: {msg['error']}")
                return msg["result"]
            self.events.append(msg)

    def navigate(self, session: str, url: str, timeout_s: float = 300.0) -> None:
        """Load ``url`` in the tab of ``session``; return once that document's load event has ended and
        its ``Page.loadEventFired`` came.  Checked on the new document itself (its URL, a mark the old
        one carries, its navigation entry), not on "a load event in the list": one of an earlier
        document (the tab's about:blank, a previous load of the same URL) can come late on a loaded
        machine."""
        self.send("Runtime.evaluate", {"expression": "window.__flexmodalOld = true"}, session)
        seen = len(self.events)
        self.send("Page.navigate", {"url": url}, session)
        done = (f"document.URL === {json.dumps(url)} && !window.__flexmodalOld && "
                "performance.getEntriesByType('navigation')[0]?.loadEventEnd > 0")
        deadline = time.monotonic() + timeout_s
        while not (self.send("Runtime.evaluate", {"returnByValue": True, "expression": done}, session)
                   ["result"].get("value") and any(e.get("method") == "Page.loadEventFired"
                                                   and e.get("sessionId") == session
                                                   for e in self.events[seen:])):
            if time.monotonic() > deadline:
                raise TimeoutError(f"{url} did not load within {timeout_s} s")
            time.sleep(0.02)

    def close(self) -> None:
        try:
            self.send("Browser.close", timeout_s=30)
        except (RuntimeError, TimeoutError, OSError):
            pass
        try:
            self.proc.wait(timeout=30)
        except subprocess.TimeoutExpired:
            self.proc.kill()
            self.proc.wait()
        os.close(self._to_chrome)
        os.close(self._from_chrome)


# page positions (CSS px) of every table and image, and the page height
LAYOUT_JS = """(() => {
  const box = e => { const r = e.getBoundingClientRect();
    return {x: r.left + scrollX, y: r.top + scrollY, width: r.width, height: r.height}; };
  const img = e => ({...box(e), ok: e.complete && e.naturalWidth > 0});
  return {tables: [...document.querySelectorAll('table')].map(box),
          images: [...document.querySelectorAll('img')].map(img),
          height: document.documentElement.scrollHeight};
})()"""


def _crop_png(browser: Browser, session: str, rect: dict) -> np.ndarray:
    shot = browser.send("Page.captureScreenshot", {"format": "png", "captureBeyondViewport": True,
                                                   "clip": {**rect, "scale": 1}}, session)
    return mpimg.imread(io.BytesIO(base64.b64decode(shot["data"])), format="png")




@dataclass(frozen=True)
class Rendered:
    """A page as Chromium rendered it: layout boxes, pixels and every DevTools event seen."""

    layout: dict
    full: np.ndarray
    table_px: np.ndarray
    plot_px: np.ndarray
    events: list[dict]

    @property
    def errors(self) -> list[dict]:
        return [e for e in self.events if e.get("method") == "Runtime.exceptionThrown"
                or (e.get("method") == "Runtime.consoleAPICalled"
                    and e["params"]["type"] in ("error", "assert"))
                or (e.get("method") == "Log.entryAdded" and e["params"]["entry"]["level"] == "error")]

    @property
    def requests(self) -> list[str]:
        return [e["params"]["request"]["url"] for e in self.events
                if e.get("method") == "Network.requestWillBeSent"]


def open_page(browser: Browser, page: Path, width: int = 1280) -> str:
    """Open ``page`` in a new ``width`` x 900 tab of ``browser`` with the Runtime, Log, Page and Network
    events on; returns the tab's session id once the page has loaded."""
    target = browser.send("Target.createTarget", {"url": "about:blank"})["targetId"]
    session = browser.send("Target.attachToTarget", {"targetId": target, "flatten": True})["sessionId"]
    for domain in ("Runtime", "Log", "Page", "Network"):
        browser.send(f"{domain}.enable", {}, session)
    browser.send("Emulation.setDeviceMetricsOverride",
                 {"width": width, "height": 900, "deviceScaleFactor": 1, "mobile": False}, session)
    browser.navigate(session, page.resolve().as_uri())
    return session


def evaluate(exe: str, page: Path, profile: Path, width: int, expression: str):
    """The value of the JavaScript ``expression`` on ``page`` opened in a ``width`` px wide window."""
    browser = Browser(exe, profile)
    try:
        session = open_page(browser, page, width)
        return browser.send("Runtime.evaluate", {"returnByValue": True, "expression": expression},
                            session)["result"]["value"]
    finally:
        browser.close()


def page_width(exe: str, page: Path, profile: Path, width: int) -> int:
    """The width [CSS px] ``page`` lays out to in a ``width`` px wide window (its scrollWidth): more than
    ``width`` when something makes the whole page scroll sideways."""
    return int(evaluate(exe, page, profile, width, "document.documentElement.scrollWidth"))


def render(exe: str, page: Path, profile: Path) -> Rendered:
    """Open ``page`` in a fresh headless Chromium; screenshot the page, its first table and image."""
    browser = Browser(exe, profile)
    try:
        session = open_page(browser, page)
        layout = browser.send("Runtime.evaluate", {"returnByValue": True, "expression": LAYOUT_JS},
                              session)["result"]["value"]
        full = _crop_png(browser, session, {"x": 0, "y": 0, "width": 1280, "height": layout["height"]})
        table_px = _crop_png(browser, session, layout["tables"][0])
        plot_px = _crop_png(browser, session, layout["images"][0])
    finally:
        browser.close()
    return Rendered(layout, full, table_px, plot_px, browser.events)


def assert_table_and_plot_visible(page: Rendered) -> None:
    """The page loaded with no console errors, fetched nothing from a network, and shows a non-blank
    table and a non-blank plot."""
    assert any(e.get("method") == "Page.loadEventFired" for e in page.events)
    assert page.errors == []
    assert page.requests and all(u.startswith(("file:", "data:")) for u in page.requests), page.requests
    assert all(img["ok"] and img["width"] > 200 and img["height"] > 100 for img in page.layout["images"])
    assert page.full.shape[0] == page.layout["height"] and page.full.std() > 0.05
    assert page.table_px.std() > 0.05  # text and rules, not a blank box
    pixels = page.plot_px.reshape(-1, page.plot_px.shape[-1])
    assert page.plot_px.std() > 0.05 and len(np.unique(pixels, axis=0)) > 50
