"""Serve a tileset beside tests/browser/tileset.html and run the page in headless Chromium.

Used by ``tests/browser/test_cesium_client.py`` and ``studies/cesium_screenshot.py``. It needs
Debian's ``chromium`` (``apt-get install chromium``) and the ``cesium`` npm package
(``npm install --prefix tests/browser``); :func:`missing` says which is absent.

The server (``http.server`` in a thread, on 127.0.0.1, a free port) maps ``/`` to this
folder (the page and ``node_modules``) and ``/tileset/`` to the tileset's folder, and sends
what a terrain server must: gzip-compressed tiles with ``Content-Encoding: gzip``, tiles as
``application/vnd.quantized-mesh`` and ``layer.json`` as ``application/json``. The query
string Cesium adds to tile URLs (``?v=1.0.0``) is ignored.
"""

from __future__ import annotations

import contextlib
import functools
import json
import os
import shutil
import subprocess
import tempfile
import threading
import urllib.parse
from http.server import SimpleHTTPRequestHandler, ThreadingHTTPServer
from pathlib import Path

HERE = Path(__file__).resolve().parent
PAGE = "tileset.html"
CESIUM_JS = HERE / "node_modules" / "cesium" / "Build" / "Cesium" / "Cesium.js"
_GZIP_MAGIC = b"\x1f\x8b"


def chromium() -> str | None:
    """The path of Debian's ``chromium`` (or ``chromium-browser``), None when neither is on PATH."""
    return shutil.which("chromium") or shutil.which("chromium-browser")


def missing() -> str | None:
    """What is absent to run the page, with the command that installs it; None when nothing is."""
    absent = []
    if chromium() is None:
        absent.append("Chromium (apt-get install chromium)")
    if not CESIUM_JS.is_file():
        absent.append(f"the cesium npm package ({CESIUM_JS.relative_to(HERE.parents[1])} is absent: "
                      "npm install --prefix tests/browser)")
    return " and ".join(absent) + " needed to load the tileset in CesiumJS" if absent else None


class _Handler(SimpleHTTPRequestHandler):
    """This folder at ``/``, the tileset at ``/tileset/``, with a terrain server's headers."""

    tileset: Path = HERE
    gzip_header: bool = True

    def translate_path(self, path: str) -> str:
        path = urllib.parse.unquote(urllib.parse.urlsplit(path).path)
        if path == "/tileset" or path.startswith("/tileset/"):
            root, rest = self.tileset, path[len("/tileset"):]
        else:
            root, rest = HERE, path
        parts = [p for p in rest.split("/") if p and p not in (".", "..")]
        return str(root.joinpath(*parts))

    def guess_type(self, path) -> str:
        name = os.fspath(path)
        if name.endswith(".terrain"):
            return "application/vnd.quantized-mesh"
        if name.endswith(".json"):
            return "application/json"
        return super().guess_type(path)

    def end_headers(self) -> None:
        path = self.translate_path(self.path)
        if self.gzip_header and path.endswith(".terrain") and os.path.isfile(path):
            with open(path, "rb") as f:
                if f.read(2) == _GZIP_MAGIC:
                    self.send_header("Content-Encoding", "gzip")
        self.send_header("Cache-Control", "no-store")
        super().end_headers()

    def log_message(self, format, *args) -> None:  # noqa: A002 (the base class's name)
        pass


@contextlib.contextmanager
def serve(tileset, *, gzip_header: bool = True):
    """Serve this folder and ``tileset`` over HTTP in a thread; yields the base URL (``http://127.0.0.1:PORT/``).

    ``gzip_header=False`` leaves out ``Content-Encoding: gzip`` (a misconfigured server, for the tests).
    """
    handler = type("Handler", (_Handler,), {"tileset": Path(tileset).resolve(), "gzip_header": gzip_header})
    server = ThreadingHTTPServer(("127.0.0.1", 0), functools.partial(handler))
    server.daemon_threads = True
    thread = threading.Thread(target=server.serve_forever, name="tileset-server", daemon=True)
    thread.start()
    try:
        yield f"http://127.0.0.1:{server.server_address[1]}/"
    finally:
        server.shutdown()
        server.server_close()
        thread.join(timeout=10)


def page_url(base: str, *, positions=None, view: str | None = None, wireframe: bool = False) -> str:
    """The page's URL on server ``base``: the tileset at ``tileset/``; ``positions`` (n, 2) lon, lat in degrees;
    ``view`` ``"whole"`` or ``"inside"`` (the page's Viewer, its camera on the whole rectangle or inside it)."""
    query = {"tileset": "tileset/"}
    if positions is not None:
        query["positions"] = ";".join(f"{float(lon)!r},{float(lat)!r}" for lon, lat in positions)
    if view:
        query["view"] = view
    if wireframe:
        query["wireframe"] = "1"
    return base + PAGE + "?" + urllib.parse.urlencode(query)


def run_page(url: str, *, timeout: float = 120.0, budget_ms: int = 60000, screenshot=None,
             size: tuple = (1200, 800)) -> dict:
    """Run the page in headless Chromium and return its result (the JSON of ``<pre id="result">``).

    Chromium prints the DOM once the page has been idle for ``budget_ms`` of virtual time
    (``--virtual-time-budget``: timers run at once, network requests are waited for); with
    ``screenshot`` (a PNG path) it takes a screenshot of ``size`` pixels instead, rendering
    with software WebGL (SwiftShader). A Chromium that runs longer than ``timeout`` seconds
    is killed and ``subprocess.TimeoutExpired`` raised; one that prints no result raises
    RuntimeError with its output.
    """
    exe = chromium()
    if exe is None:
        raise RuntimeError(missing())
    with tempfile.TemporaryDirectory(prefix="terrainvis-chromium-") as profile:
        argv = [exe, "--headless=new", "--no-sandbox", "--disable-gpu-sandbox", "--no-first-run",
                "--no-default-browser-check", "--disable-extensions", "--disable-background-networking",
                "--disable-component-update", "--disable-sync", "--mute-audio", f"--user-data-dir={profile}",
                f"--virtual-time-budget={int(budget_ms)}"]
        argv += ["--use-angle=swiftshader", "--enable-unsafe-swiftshader", "--ignore-gpu-blocklist",
                 f"--window-size={size[0]},{size[1]}", "--hide-scrollbars"]
        argv += ["--dump-dom"]
        if screenshot is not None:
            argv += [f"--screenshot={Path(screenshot).resolve()}"]
        proc = subprocess.run(argv + [url], capture_output=True, text=True, timeout=timeout,
                              env={**os.environ, "HOME": profile})
    start = proc.stdout.rfind('<pre id="result">')
    end = proc.stdout.find("</pre>", start)
    if proc.returncode != 0 or start < 0 or end < 0:
        raise RuntimeError(f"chromium printed no result (exit {proc.returncode}): stdout {proc.stdout[-1000:]!r}, "
                           f"stderr {proc.stderr[-2000:]!r}")
    text = proc.stdout[start + len('<pre id="result">'):end]
    if text.strip() == "pending":
        raise RuntimeError(f"the page had not finished within {budget_ms} ms of virtual time: {proc.stderr[-2000:]!r}")
    import html

    return json.loads(html.unescape(text))
