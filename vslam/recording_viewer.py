"""A PNG of a recording as a person sees it: Rerun's web viewer (shipped in rerun-sdk) in headless Chromium.

Needs Debian's `chromium` (apt-get install chromium), the `rerun` command of rerun-sdk and `websocket-client`
(pip; the `view` extra). Works without a GPU: Chromium renders through SwiftShader. The viewer compiles its
WebAssembly in real time, so the shot waits `wait` seconds (30-40 s on 2 cores). Ports are picked free on
127.0.0.1 so that several shots can run at once; both processes are ended (their process groups) at the end.
"""
from __future__ import annotations

import base64
import json
import os
import shutil
import signal
import socket
import subprocess
import time
import urllib.parse
import urllib.request
from pathlib import Path

from odometry.shared.atomic_io import atomic_path
from vslam.errors import VslamError


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def viewer_available() -> str | None:
    """None when a screenshot can be taken here, else what is missing."""
    missing = [name for name in ("chromium", "rerun") if shutil.which(name) is None]
    try:
        import websocket  # noqa: F401
    except ImportError:
        missing.append("websocket-client (pip)")
    return ", ".join(missing) or None


def _devtools(port: int, timeout: float = 30.0):
    import websocket

    t0 = time.monotonic()
    while True:
        try:
            tabs = json.load(urllib.request.urlopen(f"http://127.0.0.1:{port}/json", timeout=2))
            page = next(t for t in tabs if t.get("type") == "page")
            break
        except (OSError, StopIteration, ValueError):
            if time.monotonic() - t0 > timeout:
                raise VslamError("chromium did not open its DevTools port") from None
            time.sleep(0.5)
    # suppress_origin: recent Chromium rejects DevTools websockets that carry an Origin it was not told to allow
    return websocket.create_connection(page["webSocketDebuggerUrl"], timeout=60, suppress_origin=True)


def screenshot(rrd: str | Path, png: str | Path, wait: float = 40.0, size: tuple[int, int] = (1600, 1000),
               settle: float = 5.0, max_wait: float = 300.0) -> Path:
    """Open `rrd` in Rerun's web viewer in headless Chromium and write what it shows to `png` once it has loaded:
    after `wait` seconds, shots are taken every `settle` seconds until two in a row are identical (the viewer
    streams the file in and moves its time cursor while it loads; on a busy machine that takes minutes), or until
    `max_wait` seconds have passed (the last shot is written then)."""
    rrd, png = Path(rrd), Path(png)
    if not rrd.is_file():
        raise VslamError(f"{rrd}: no such recording")
    missing = viewer_available()
    if missing:
        raise VslamError(f"cannot take a viewer screenshot: missing {missing}")
    web, grpc, devtools = _free_port(), _free_port(), _free_port()
    viewer = subprocess.Popen(["rerun", "--web-viewer", "--web-viewer-port", str(web), "--port", str(grpc),
                               "--bind", "127.0.0.1", str(rrd)],
                              stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, start_new_session=True)
    browser = subprocess.Popen(["chromium", "--headless=new", "--no-sandbox", "--use-angle=swiftshader",
                                "--enable-unsafe-swiftshader", "--ignore-gpu-blocklist",
                                f"--window-size={size[0]},{size[1]}", f"--remote-debugging-port={devtools}",
                                "about:blank"],
                               stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, start_new_session=True)
    try:
        ws = _devtools(devtools)
        seq = [0]

        def call(method: str, **params) -> dict:
            seq[0] += 1
            ws.send(json.dumps(dict(id=seq[0], method=method, params=params)))
            while True:
                msg = json.loads(ws.recv())
                if msg.get("id") == seq[0]:
                    return msg

        call("Page.enable")
        source = urllib.parse.quote(f"rerun+http://127.0.0.1:{grpc}/proxy", safe="")
        call("Page.navigate", url=f"http://127.0.0.1:{web}?url={source}")
        t0 = time.monotonic()
        time.sleep(wait)
        last = None
        while True:
            shot = call("Page.captureScreenshot", format="png")
            if "result" not in shot:
                raise VslamError(f"chromium gave no screenshot: {shot.get('error')}")
            data = base64.b64decode(shot["result"]["data"])
            if data == last or time.monotonic() - t0 > max_wait:
                break
            last = data
            time.sleep(settle)
        with atomic_path(png) as tmp:
            Path(tmp).write_bytes(data)
        ws.close()
    finally:
        for proc in (browser, viewer):   # each in its own process group: end the group (the rerun wrapper forks)
            try:
                os.killpg(proc.pid, signal.SIGTERM)
            except ProcessLookupError:
                pass
            proc.wait(10)
    return png
