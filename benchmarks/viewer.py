"""Viewer benchmark: the browser viewer's frame rate in headless Chromium (SwiftShader WebGL).

    python benchmarks/viewer.py [--seconds 20] [--default-steps 40] [--out benchmarks/results]

A real ``diathermy serve`` (child process) and the page at /viewer, driven by playwright:

1. the default grid (33x33x65, the default scene at 200 W so it cuts within ~15 steps): steps
   over REST until the cut is 2 mm deep, opens the session in the page, runs it at the server's
   maximum rate for ``--seconds`` and counts frames drawn per second (both streams: the cut
   surface and the tissue's top layer), then re-draws the newest frames to measure what the
   viewer itself can draw (decode, geometry, colours, render; GPU synced);
2. the same on the 9x9x17 quick-cut scene, side by side (ratios);
3. a picture of a cut in progress: the quick-cut block on 17x17x33 while the electrode is dragged
   with the mouse, saved as viewer.png.

Writes viewer.md and viewer.png to ``--out``. Needs chromium (scripts/setup.sh installs it).
"""

from __future__ import annotations

import argparse
import os
import shutil
import socket
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

import httpx
from playwright.sync_api import Page, sync_playwright

ROOT = Path(__file__).resolve().parents[1]
TOKEN = "viewer-bench"
CHROMIUM_ARGS = ["--use-angle=swiftshader", "--enable-unsafe-swiftshader", "--use-gl=angle"]
DEFAULT_200W = {"name": "default-200w", "electrodes": [{"power_w": 200.0}]}
QUICK_CUT = {
    "name": "quick-cut",
    "block_m": [0.02, 0.01, 0.01],
    "electrodes": [{"position_m": [0.01, 0.005], "power_w": 200.0}],
}


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


class Server:
    """``diathermy serve`` in a child process with one token and no stream-rate cap to speak of."""

    def __init__(self, data_dir: Path) -> None:
        self.port = free_port()
        self.url = f"http://127.0.0.1:{self.port}"
        env = {
            **os.environ,
            "PYTHONPATH": os.pathsep.join([str(ROOT / "server"), str(ROOT / "client")]),
            "DIATHERMY_MAX_STREAM_RATE_HZ": "1000",
            "DIATHERMY_LOG_LEVEL": "WARNING",
            "DIATHERMY_AUTOSAVE_INTERVAL_S": "3600",
        }
        cmd = [sys.executable, "-m", "diathermy", "serve", "--port", str(self.port)]
        cmd += ["--data-dir", str(data_dir), "--token", TOKEN]
        self.proc = subprocess.Popen(cmd, env=env)
        deadline = time.monotonic() + 60
        while True:
            try:
                if httpx.get(self.url + "/readyz").status_code == 200:
                    break
            except httpx.TransportError:
                pass
            if time.monotonic() > deadline or self.proc.poll() is not None:
                raise RuntimeError("diathermy serve did not become ready")
            time.sleep(0.2)
        self.http = httpx.Client(
            base_url=self.url, headers={"Authorization": f"Bearer {TOKEN}"}, timeout=600
        )

    def session(self, scene: dict[str, Any], grid: list[int]) -> dict[str, Any]:
        r = self.http.post("/v1/sessions", json={"scene": {**scene, "grid": grid}})
        r.raise_for_status()
        return dict(r.json())

    def step_until(self, sid: str, depth_m: float, max_steps: int) -> dict[str, Any]:
        """Step one at a time until the crater is ``depth_m`` deep; returns the last report."""
        rep: dict[str, Any] = {}
        for _ in range(max_steps):
            rep = self.http.post(f"/v1/sessions/{sid}/step").json()["reports"][-1]
            print(f"  step {rep['step']}: crater {1e3 * rep['crater_depth_m']:.2f} mm", flush=True)
            if rep["crater_depth_m"] >= depth_m:
                break
        return rep

    def stop(self) -> None:
        self.http.close()
        self.proc.terminate()
        self.proc.wait(timeout=60)


def open_page(page: Page, server: Server, sid: str) -> None:
    page.goto(f"{server.url}/viewer/?token={TOKEN}#{sid}")
    page.wait_for_function(
        "window.viewer.state.session && window.viewer.stats.framesReceived.volume >= 1 "
        "&& window.viewer.stats.framesReceived.surface >= 1",
        timeout=300_000,
    )
    page.click("#focus")
    page.wait_for_timeout(500)


def stats(page: Page) -> dict[str, Any]:
    return dict(
        page.evaluate(
            "({drawn: window.viewer.stats.framesDrawn, received: window.viewer.stats.framesReceived,"
            " bytes: window.viewer.stats.bytes, step: (window.viewer.report() || {step: 0}).step,"
            " dropped: Number(window.viewer.panel()['dropped frames']),"
            " faces: window.viewer.cutFaces()})"
        )
    )


def measure(page: Page, seconds: float, redraws: int) -> dict[str, Any]:
    """Live: run at the server's cap for ``seconds``; then the viewer's own redraw rate."""
    a = stats(page)
    page.fill("#rate", "1000")
    t0 = time.monotonic()
    page.click("#run")
    page.wait_for_timeout(1000 * seconds)
    b = stats(page)
    wall = time.monotonic() - t0
    page.click("#pause")
    page.wait_for_timeout(500)
    frames = (b["received"]["surface"] - a["received"]["surface"]) + (
        b["received"]["volume"] - a["received"]["volume"]
    )
    redraw = page.evaluate(f"window.viewer.redrawBenchmark({redraws})")
    return {
        "live_received_per_s": frames / wall,
        "live_drawn_per_s": (b["drawn"] - a["drawn"]) / wall,
        "live_steps_per_s": (b["step"] - a["step"]) / wall,
        "dropped": b["dropped"] - a["dropped"],
        "kib_per_step": (b["bytes"] - a["bytes"]) / 1024 / max(1, frames / 2),
        "redraw_fps": redraw["fps"],
        "apply_ms": redraw["applyMs"],
        "render_ms": redraw["renderMs"],
        "cut_faces": b["faces"],
        "step": b["step"],
    }


def picture(page: Page, server: Server, out: Path) -> dict[str, Any]:
    """A cut in progress: the quick-cut block on 17x17x33, the electrode dragged along x."""
    info = server.session(QUICK_CUT, [17, 17, 33])
    open_page(page, server, info["id"])
    page.click("#overview")

    def drag_to(x: float) -> None:
        start = page.evaluate("window.viewer.electrodeScreenPosition()")
        end = page.evaluate(f"window.viewer.screenOf({x}, 0.005)")
        page.mouse.move(start["x"], start["y"] - 2)
        page.mouse.down()
        page.mouse.move(end["x"], end["y"] - 2, steps=4)
        page.mouse.up()

    drag_to(0.006)
    page.fill("#rate", "10")
    page.click("#run")
    for k in range(1, 21):  # 8 mm along x, one step per 0.4 mm
        step = page.evaluate("(window.viewer.report() || {step: 0}).step")
        page.wait_for_function(
            f"(window.viewer.report() || {{step: 0}}).step > {step}", timeout=120_000
        )
        drag_to(0.006 + 0.0004 * k)
    page.click("#pause")
    page.wait_for_function(
        "document.getElementById('status').textContent === 'paused'", timeout=120_000
    )
    panel: dict[str, Any] = {}
    for _ in range(10):  # a step already under way when paused still arrives: wait it out
        page.wait_for_timeout(1000)
        before = page.evaluate("window.viewer.panel()")
        page.screenshot(path=str(out))
        panel = dict(page.evaluate("window.viewer.panel()"))
        if panel["step"] == before["step"]:
            break
    return panel


def run(
    out_dir: Path,
    seconds: float,
    default_steps: int,
    grid: list[int] | None = None,
    picture_too: bool = True,
    redraws: int = 20,
) -> str:
    """Both measurements (``redraws`` re-applications each, and the picture); writes and
    returns viewer.md."""
    grid = grid or [33, 33, 65]
    out_dir.mkdir(parents=True, exist_ok=True)
    results: dict[str, dict[str, Any]] = {}
    with tempfile.TemporaryDirectory() as tmp, sync_playwright() as p:
        server = Server(Path(tmp) / "data")
        chromium = shutil.which("chromium") or shutil.which("chromium-browser")
        if chromium is None:
            raise SystemExit("chromium is not installed (scripts/setup.sh installs it)")
        browser = p.chromium.launch(executable_path=chromium, args=CHROMIUM_ARGS)
        try:
            cases = [
                ("x".join(map(str, grid)), DEFAULT_200W, grid, 0.002, default_steps),
                ("9x9x17 (quick cut)", QUICK_CUT, [9, 9, 17], 0.004, 40),
            ]
            for label, scene, grid, depth, steps in cases:
                print(f"{label}: stepping to a {1e3 * depth:.0f} mm crater", flush=True)
                info = server.session(scene, grid)
                server.step_until(info["id"], depth, steps)
                page = browser.new_page(viewport={"width": 1280, "height": 760})
                open_page(page, server, info["id"])
                results[label] = {
                    "nodes": info["grid"]["n_nodes"],
                    **measure(page, seconds, redraws),
                }
                print(f"  {results[label]}", flush=True)
                page.close()
            panel: dict[str, Any] = {}
            if picture_too:
                page = browser.new_page(viewport={"width": 1280, "height": 760})
                panel = picture(page, server, out_dir / "viewer.png")
                page.close()
        finally:
            browser.close()
            server.stop()
    text = report(results, panel, seconds, redraws)
    (out_dir / "viewer.md").write_text(text, encoding="utf-8")
    return text


def report(
    results: dict[str, dict[str, Any]], panel: dict[str, Any], seconds: float, redraws: int = 20
) -> str:
    (big, b), (small, s) = list(results.items())
    lines = [
        "# Viewer frame rate (headless Chromium, SwiftShader WebGL)",
        "",
        "`python benchmarks/viewer.py`: a real `diathermy serve` and the /viewer page driven by",
        "playwright in Debian's chromium with `--use-angle=swiftshader` (software WebGL on the CPU),",
        "on a shared 2-core machine: read the ratios, not the absolute rates. Each session is first",
        "stepped over REST until it has cut; the page then shows two streams (the cut surface,",
        "`region: surface`, and the tissue's top face from `region: top`, float16, every step; until 2026-12-07 the whole volume, float32).",
        "",
        f"*Live* runs the session at the server's maximum rate for {seconds:g} s: frames received",
        "per second (both streams, two per step) are bounded by the engine's step rate; the page",
        "draws the newest of what arrived once per animation frame, so frames drawn per second",
        "(counting both streams) are bounded by the render time too. *Redraw* re-applies the",
        f"newest frames {redraws} times (msgpack decode, top layer and colours, cut-surface geometry,",
        "render, `readPixels` to wait for the GPU): what the viewer itself can draw.",
        "",
        "| grid | nodes | cut faces | live steps/s | live frames received/s | live frames drawn/s "
        "| dropped | KiB per step | redraw frames/s | decode+geometry ms | render ms |",
        "|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for label, r in results.items():
        lines.append(
            f"| {label} | {r['nodes']} | {r['cut_faces']} | {r['live_steps_per_s']:.2f} | "
            f"{r['live_received_per_s']:.2f} | {r['live_drawn_per_s']:.2f} | {r['dropped']} | {r['kib_per_step']:.0f} | "
            f"{r['redraw_fps']:.1f} | {r['apply_ms']:.1f} | {r['render_ms']:.1f} |"
        )
    lines += [
        "",
        f"Ratios {big} / {small}: nodes {b['nodes'] / s['nodes']:.0f}x, redraw frames/s "
        f"{b['redraw_fps'] / s['redraw_fps']:.2f}x, live steps/s "
        f"{b['live_steps_per_s'] / max(s['live_steps_per_s'], 1e-9):.3f}x.",
        "",
    ]
    if panel:
        lines += [
            "![a cut in progress](viewer.png)",
            "",
            "viewer.png: the 2 x 1 x 1 cm quick-cut block (200 W) on 17x17x33; the electrode was",
            "dragged 8 mm along x with the mouse, 0.4 mm per step; panel at the picture: "
            + ", ".join(f"{k} {v}" for k, v in panel.items())
            + ".",
            "",
        ]
    return "\n".join(lines)


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    p.add_argument("--seconds", type=float, default=20.0, help="live run per grid (s)")
    p.add_argument("--default-steps", type=int, default=40, help="most steps to the 2 mm crater")
    p.add_argument("--grid", default="33x33x65", help="the large grid NZxNYxNX (the default's)")
    p.add_argument("--no-picture", action="store_true", help="skip viewer.png")
    p.add_argument("--out", type=Path, default=ROOT / "benchmarks" / "results")
    args = p.parse_args()
    grid = [int(v) for v in args.grid.lower().split("x")]
    print(run(args.out, args.seconds, args.default_steps, grid, not args.no_picture))


if __name__ == "__main__":
    main()
