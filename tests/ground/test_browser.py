"""The page in a real browser (the system Chromium through Playwright) against the full stack.

The tests run in order on one page, as a researcher would: load, watch telemetry, take off,
fly with a velocity command, hold over the pad, get a command refused, land, and survive the
pilot restarting.
"""

from __future__ import annotations

import math
import os
from collections.abc import Iterator
from typing import Any

import pytest

from tests.ground.conftest import CHROMIUM, CHROMIUM_ARGS, Stack, wait_until

pytestmark = pytest.mark.skipif(
    not os.path.exists(CHROMIUM),
    reason=f"no system Chromium at {CHROMIUM} (apt-get install chromium)",
)
playwright_api = pytest.importorskip("playwright.sync_api", reason="pip install playwright")


@pytest.fixture(scope="module")
def page(stack: Stack) -> Iterator[Any]:
    with playwright_api.sync_playwright() as p:
        browser = p.chromium.launch(executable_path=CHROMIUM, args=CHROMIUM_ARGS)
        pg = browser.new_page(viewport={"width": 1500, "height": 1000})
        errors: list[str] = []
        pg.on("pageerror", lambda e: errors.append(str(e)))
        pg.goto(stack.web.page_url)  # the URL skeye ground prints
        yield pg
        browser.close()
        assert not errors, f"JavaScript errors on the page: {errors}"


def value(pg: Any, selector: str) -> float:
    text = pg.get_attribute(selector, "data-value")
    assert text not in (None, ""), f"{selector} shows no value"
    return float(text)


def wait_js(pg: Any, expr: str, timeout_s: float, what: str) -> None:
    try:
        pg.wait_for_function(expr, timeout=timeout_s * 1000)
    except playwright_api.TimeoutError:
        raise AssertionError(f"timed out after {timeout_s} s waiting for {what}") from None


def test_page_loads_and_telemetry_updates(page: Any, stack: Stack) -> None:
    assert page.title() == "skeye ground control"
    wait_js(page, "document.querySelector('#link-state').dataset.state === 'connected'", 20,
            "the vehicle link to show connected")
    wait_js(page, "document.querySelector('#flight-state').dataset.state === 'landed'", 10,
            "the landed state")
    t0 = page.evaluate("S.telemetry.nav.time_s")
    wait_js(page, f"S.telemetry.nav.time_s > {t0} + 0.5", 10, "vehicle time to advance")
    assert value(page, "#lq-rate") > 5
    assert "3D fix" in page.inner_text("#ro-gpsfix")
    assert page.inner_text("#ro-battery").endswith(" V")
    wait_js(page, "document.querySelector('#video-info').textContent.includes('320')", 20,
            "camera frames to show")


def test_take_off_raises_the_shown_height(page: Any, stack: Stack) -> None:
    assert value(page, "#ro-height") < 0.5
    page.fill("#to-height", "1.5")
    page.click("#btn-takeoff")
    wait_js(page, "document.querySelector('#last-result').dataset.ok === 'true'", 5,
            "take-off to be accepted")
    wait_js(page, "Number(document.querySelector('#ro-height').dataset.value) > 1.3", 20,
            "the shown height to pass 1.3 m")
    wait_js(page, "document.querySelector('#flight-state').dataset.state === 'holding'", 20,
            "the climb to finish")
    assert -stack.pilot.ground_truth()[2] > 1.2


def test_velocity_command_moves_the_vehicle(page: Any, stack: Stack) -> None:
    n0, e0, _ = stack.pilot.ground_truth()
    yaw = math.radians(page.evaluate("S.telemetry.nav.yaw_deg"))
    page.fill("#v-fwd", "0.6")
    page.fill("#v-dur", "2.5")
    page.click("#btn-velocity")
    wait_js(page, "document.querySelector('#last-result').dataset.command === 'velocity' && "
                  "document.querySelector('#last-result').dataset.ok === 'true'", 5,
            "the velocity command to be accepted")
    wait_until(lambda: math.hypot(stack.pilot.ground_truth()[0] - n0,
                                  stack.pilot.ground_truth()[1] - e0) > 0.8, 10,
               "the vehicle to move 0.8 m (ground truth)")
    n1, e1, _ = stack.pilot.ground_truth()
    along = (n1 - n0) * math.cos(yaw) + (e1 - e0) * math.sin(yaw)
    across = -(n1 - n0) * math.sin(yaw) + (e1 - e0) * math.cos(yaw)
    assert along > 0.8 and abs(across) < 0.3, (along, across)
    wait_js(page, "document.querySelector('#flight-state').dataset.state !== 'flying'", 10,
            "the timed velocity to end")
    shown = (value(page, "#ro-north"), value(page, "#ro-east"))
    truth = stack.pilot.ground_truth()
    assert math.hypot(shown[0] - truth[0], shown[1] - truth[1]) < 0.5  # INS vs truth


def test_move_back_over_the_pad_and_hold_shows_detections(page: Any, stack: Stack) -> None:
    north, east, _ = stack.pilot.ground_truth()
    page.fill("#m-fwd", f"{-north:.2f}")
    page.fill("#m-right", f"{-east:.2f}")
    page.select_option("#m-frame", "world")
    page.fill("#m-speed", "0.8")
    page.click("#btn-move")
    wait_js(page, "document.querySelector('#last-result').dataset.command === 'move_by' && "
                  "document.querySelector('#last-result').dataset.ok === 'true'", 5,
            "the move to be accepted")
    wait_until(lambda: math.hypot(*stack.pilot.ground_truth()[:2]) < 0.35, 15,
               "the vehicle back over the pad (ground truth)")
    page.click("#btn-pad-hold")
    wait_js(page, "document.querySelector('#pad-mode').dataset.mode === 'hold'", 5,
            "the vehicle to report pad mode hold")
    wait_js(page, "document.querySelector('#det-found').dataset.found === 'true'", 15,
            "the camera overlay to show the pad")
    assert value(page, "#det-rings") >= 2
    ellipses = page.evaluate("camera.meta.detection.ellipses.length")
    assert ellipses >= 2
    # The pilot's own PAD report: found only once the pilot feeds detections (see docs).
    pad = page.evaluate("S.telemetry.pad")
    assert pad is not None and set(pad) >= {"found", "rings", "dx_m", "dy_m", "quality"}


def test_refused_command_shows_its_reason(page: Any, stack: Stack) -> None:
    page.click("#btn-takeoff")  # already in the air
    wait_js(page, "document.querySelector('#last-result').dataset.ok === 'false'", 5,
            "the refusal")
    text = page.inner_text("#last-result")
    code = page.get_attribute("#last-result", "data-code")
    assert code in ("4", "5") and "REFUSED by the vehicle" in text and "take off" in text
    assert "take_off" in page.inner_text("#cmd-log")


def test_land_lands(page: Any, stack: Stack) -> None:
    page.click("#btn-pad-off")
    page.click("#btn-land")
    wait_js(page, "document.querySelector('#flight-state').dataset.state === 'landed'", 30,
            "the landed state")
    assert -stack.pilot.ground_truth()[2] < 0.3
    assert value(page, "#ro-height") < 0.4


def test_page_survives_pilot_restart(page: Any, stack: Stack) -> None:
    connects = value(page, "#lq-connects")
    stack.pilot.stop()  # the pilot goes away: the page must say so
    wait_js(page, "document.querySelector('#link-state').dataset.state !== 'connected'",
            15, "the page to show the link down")
    stack.restart_pilot(down_s=0.5)
    wait_js(page, f"Number(document.querySelector('#lq-connects').dataset.value) > {connects}"
                  " && document.querySelector('#link-state').dataset.state === 'connected'",
            20, "the page to reconnect to the restarted pilot")
    t0 = page.evaluate("S.telemetry.nav.time_s")
    wait_js(page, f"S.telemetry.nav.time_s > {t0}", 10, "telemetry from the new pilot")
    page.click("#btn-hold")  # landed: refused, but answered
    wait_js(page, "document.querySelector('#last-result').dataset.command === 'hold'", 5,
            "an answer from the new pilot")
