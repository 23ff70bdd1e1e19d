"""The browser viewer at /viewer, driven in headless Chromium against a real server.

One page walks the whole workflow (so the test stays well under a minute): token, a pasted
cutting scene on a small grid, the WebGL canvas, a mouse drag of the electrode (read back over
REST), the power slider and on/off switch, running until the cut appears, a dropped connection,
and deleting the session.
"""

from __future__ import annotations

import io
import json
import time
from pathlib import Path
from typing import Any

import httpx
import numpy as np
from PIL import Image
from playwright.sync_api import Browser, Page

from diathermy.service.engine import DefaultEngine
from tests.service.conftest import CUT, TOKEN_A, LiveServer, make_settings
from tests.viewer.conftest import page_errors

SCENE = {**CUT["scene"], "grid": [9, 9, 17]}
"""The service tests' quick cut (2 x 1 x 1 cm, 200 W) on a 9 x 9 x 17 grid: cuts from step 2."""


def canvas_pixels(page: Page) -> np.ndarray:
    """The canvas as rendered, (h, w, 3) uint8."""
    png = page.locator("#view").screenshot()
    return np.asarray(Image.open(io.BytesIO(png)).convert("RGB"))


def wait_for(page: Page, expr: str, timeout_s: float = 20.0) -> Any:
    page.wait_for_function(expr, timeout=timeout_s * 1e3)
    return page.evaluate(expr)


def electrode(api: httpx.Client, sid: str) -> dict[str, Any]:
    r = api.get(f"/v1/sessions/{sid}/electrodes/active")
    assert r.status_code == 200, r.text
    return r.json()


def test_viewer_is_served_from_package_files(live: LiveServer) -> None:
    with httpx.Client(base_url=live.url) as c:
        r = c.get("/viewer", follow_redirects=False)
        assert r.status_code == 307 and r.headers["location"] == "/viewer/"
        page = c.get("/viewer/")
        assert page.status_code == 200 and "text/html" in page.headers["content-type"]
        assert 'src="viewer.js"' in page.text
        assert "http://" not in page.text and "https://" not in page.text  # nothing from a CDN
        js = c.get("/viewer/viewer.js")
        assert js.status_code == 200 and "javascript" in js.headers["content-type"]
        assert len(js.content) > 100_000  # three.js and msgpack are bundled in
        assert c.get("/viewer/viewer.css").status_code == 200
        missing = c.get("/viewer/nothing.js")
        assert missing.status_code == 404 and missing.json()["error"] == "not_found"


def test_viewer_drives_a_cutting_session(live: LiveServer, browser: Browser) -> None:
    page = browser.new_page(viewport={"width": 1100, "height": 700})
    errors = page_errors(page)
    api = live.client()
    try:
        page.goto(f"{live.url}/viewer/")
        page.fill("#token", TOKEN_A)
        page.click("#connect")
        page.wait_for_function("document.querySelectorAll('#scene option').length >= 5")
        page.fill("#scene-json", json.dumps(SCENE))
        page.click("#create")
        wait_for(
            page,
            "window.viewer.stats.framesReceived.volume >= 1 && window.viewer.stats.framesDrawn >= 2",
        )
        sid = page.evaluate("window.viewer.state.session.id")
        assert api.get(f"/v1/sessions/{sid}").json()["grid"]["shape"] == [9, 9, 17]

        # the canvas shows a lit, coloured block, not a blank or missing WebGL context
        img = canvas_pixels(page)
        assert img.std() > 12, f"canvas looks blank (pixel std {img.std():.1f})"
        colours = np.unique(img.reshape(-1, 3) // 8, axis=0).shape[0]
        assert colours > 40, f"only {colours} distinct colours on the canvas"

        # drag the electrode with the mouse: the session's electrode follows (read over REST)
        before = electrode(api, sid)["position_m"]
        start = page.evaluate("window.viewer.electrodeScreenPosition()")
        end = page.evaluate("window.viewer.screenOf(0.015, 0.0065)")
        page.mouse.move(start["x"], start["y"] - 2)
        page.mouse.down()
        for f in np.linspace(0.1, 1.0, 10):
            page.mouse.move(
                start["x"] + f * (end["x"] - start["x"]),
                start["y"] - 2 + f * (end["y"] - start["y"] + 2),
            )
        page.mouse.up()
        deadline = time.monotonic() + 10
        after = electrode(api, sid)["position_m"]
        while after == before and time.monotonic() < deadline:
            time.sleep(0.1)
            after = electrode(api, sid)["position_m"]
        assert after[0] > before[0] + 0.003, (
            f"electrode did not follow the drag: {before} -> {after}"
        )
        assert abs(after[0] - 0.015) < 0.002 and abs(after[1] - 0.0065) < 0.002, after

        # power slider and on/off switch reach the session
        page.locator("#power").fill("150")
        page.locator("#power").dispatch_event("change")
        page.uncheck("#active")
        deadline = time.monotonic() + 10
        while time.monotonic() < deadline:
            e = electrode(api, sid)
            if e["power_w"] == 150 and not e["active"]:
                break
            time.sleep(0.1)
        assert e["power_w"] == 150 and not e["active"], e
        page.locator("#power").fill("200")
        page.locator("#power").dispatch_event("change")
        page.check("#active")

        # run until the cut appears: the readout shows a volume, the crater region changes
        spot = page.evaluate("window.viewer.electrodeScreenPosition()")
        before_img = canvas_pixels(page)
        page.fill("#rate", "20")
        page.click("#run")
        wait_for(
            page,
            "(window.viewer.report() || {}).cut_volume_m3 > 0 && window.viewer.report().step >= 6",
            40,
        )
        page.click("#pause")
        wait_for(page, "window.viewer.cutFaces() > 0")
        page.wait_for_timeout(300)
        cut_text = page.evaluate("window.viewer.panel()['cut volume']")
        assert float(cut_text.split()[0]) > 0, cut_text
        assert float(page.evaluate("window.viewer.panel()['crater depth']").split()[0]) > 0
        # a uniform grid is fine everywhere; a graded one says what left its fine region
        assert page.evaluate("window.viewer.panel()['fine region']") == "uniform grid"
        region = page.evaluate("window.viewer.fineRegionText({cut: 0.0021, vapor: 0.0})")
        assert region == "cut 2.1 mm beyond"
        assert page.evaluate("window.viewer.fineRegionText({cut: 0, vapor: 0})") == "inside"
        # the electrode's voltage from the electric report (no limit in this scene)
        assert page.evaluate("window.viewer.panel()['voltage']").endswith(" V")
        extra = "{voltage_v: 150.2, voltage_limited: true}"
        held = f"window.viewer.voltageText({{effects: {{electric: {{extra: {extra}}}}}}})"
        assert page.evaluate(held) == "150 V (limited)"
        # every effect is on: nothing left out would act
        assert page.evaluate("window.viewer.panel()['left out']") == "none"
        left = page.evaluate("window.viewer.leftOutText({vaporization: 'T up to 400 K'})")
        assert left == "vaporization would act"
        after_img = canvas_pixels(page)
        box = page.locator("#view").bounding_box()
        assert box is not None
        cx, cy = int(spot["x"] - box["x"]), int(spot["y"] - box["y"])
        region = (slice(max(cy - 60, 0), cy + 60), slice(max(cx - 60, 0), cx + 60))
        change = np.abs(after_img[region].astype(float) - before_img[region].astype(float))
        assert change.mean() > 4, f"crater region barely changed ({change.mean():.2f})"

        # colour by another field (the legend follows); exaggerate the displacement
        page.select_option("#colour", "pressure")
        wait_for(page, "document.getElementById('legend-labels').textContent.includes('MPa')")
        page.select_option("#colour", "thermal_damage")
        wait_for(page, "document.getElementById('legend-labels').textContent.includes('damaged')")
        plain = canvas_pixels(page)
        page.locator("#exag").fill("2.5")
        page.locator("#exag").dispatch_event("input")
        page.wait_for_timeout(300)
        assert page.inner_text("#exag-out") == "316"
        bent = canvas_pixels(page)
        assert np.abs(bent.astype(float) - plain.astype(float)).mean() > 0.5

        # a dropped connection: both streams come back and frames flow again
        step = page.evaluate("window.viewer.report().step")
        page.evaluate(
            "for (const s of Object.values(window.viewer.state.streams)) s.ws.close(4000)"
        )
        wait_for(page, "window.viewer.stats.reconnects >= 2", 15)
        page.click("#step")
        wait_for(page, f"window.viewer.report().step > {step}", 20)

        page.click("#delete")
        deadline = time.monotonic() + 10
        while api.get(f"/v1/sessions/{sid}").status_code != 404 and time.monotonic() < deadline:
            time.sleep(0.1)
        assert api.get(f"/v1/sessions/{sid}").status_code == 404
        assert errors == [], errors
    finally:
        api.close()
        page.close()


def test_viewer_reconnects_after_the_server_restarts(tmp_path: Path, browser: Browser) -> None:
    settings = make_settings(tmp_path / "data")
    server = LiveServer(settings, DefaultEngine()).start()
    with server.client() as api:
        sid = api.post("/v1/sessions", json={"scene": SCENE}).json()["id"]
    page = browser.new_page(viewport={"width": 900, "height": 600})
    errors = page_errors(page)
    try:
        page.goto(f"{server.url}/viewer/?token={TOKEN_A}#{sid}")  # opens the session at once
        wait_for(page, "window.viewer.report() === null && window.viewer.stats.framesDrawn >= 2")
        server.stop()  # checkpoints the session; both streams drop
        wait_for(page, "document.getElementById('status').textContent.includes('reconnecting')")
        server = LiveServer(settings, DefaultEngine()).start()  # same port and data directory
        wait_for(page, "window.viewer.stats.reconnects >= 2", 30)
        page.click("#step")
        wait_for(page, "(window.viewer.report() || {step: 0}).step === 1", 30)
        assert page.evaluate("window.viewer.panel()['step']") == "1"
    finally:
        page.close()
        server.stop()
    assert errors == [], errors
