"""The page's JavaScript modules in the system Chromium, against a ground server with no
vehicle: the forms built from the command table (checked against ``commands.py`` itself), the
keyboard's speed, the modules' MIME type, and unit tests of the helpers (form generation,
validation and clamping, unit conversions, telemetry formatting, plot data) run by importing the
modules in the page (``page.evaluate`` with a dynamic ``import()``)."""

from __future__ import annotations

import math
import os
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import httpx
import pytest

from skeye.ground.commands import (
    COMMANDS,
    KEYBOARD,
    VehicleLimits,
    describe_commands,
    describe_keyboard,
)
from tests.ground.conftest import CHROMIUM, CHROMIUM_ARGS, UvicornThread
from tests.ports import free_port as _free_port

STATIC = Path(__file__).resolve().parents[2] / "skeye" / "ground" / "static"
LIMITS = VehicleLimits.for_robot("hummingbird")  # what create_app uses by default
FIXED = {("pad_mode", "mode")}  # set by the page's buttons, not a field


@pytest.fixture(scope="module")
def web() -> Iterator[UvicornThread]:
    from skeye.ground.app import create_app
    from skeye.ground.bridge import VehicleBridge
    from skeye.ground.guard import GroundSecurity

    security = GroundSecurity()
    with VehicleBridge(f"tcp://127.0.0.1:{_free_port()}", retry_s=0.5) as bridge:
        server = UvicornThread(create_app(bridge, security=security), security.token)
        try:
            yield server
        finally:
            server.close()


@pytest.fixture(scope="module")
def page(web: UvicornThread) -> Iterator[Any]:
    if not os.path.exists(CHROMIUM):
        pytest.skip(f"no system Chromium at {CHROMIUM} (apt-get install chromium)")
    playwright_api = pytest.importorskip("playwright.sync_api", reason="pip install playwright")
    with playwright_api.sync_playwright() as p:
        browser = p.chromium.launch(executable_path=CHROMIUM, args=CHROMIUM_ARGS)
        pg = browser.new_page(viewport={"width": 1500, "height": 1000})
        errors: list[str] = []
        pg.on("pageerror", lambda e: errors.append(str(e)))
        pg.goto(web.page_url)
        pg.wait_for_function("window.S && S.commands !== null && document.getElementById("
                             "'kbd-speed') !== null", timeout=30_000)
        yield pg
        browser.close()
        assert not errors, f"JavaScript errors on the page: {errors}"


def js(pg: Any, body: str) -> Any:
    """Run ``body`` (an async function body) with the page's modules imported as
    ``units, forms, telemetry, plots, keyboard, command, events``; returns what it returns."""
    return pg.evaluate(
        "async () => {"
        " const [units, forms, telemetry, plots, keyboard, command, events] ="
        " await Promise.all(["
        " import('/static/js/units.js'), import('/static/js/forms.js'),"
        " import('/static/js/telemetry.js'), import('/static/js/plots.js'),"
        " import('/static/js/keyboard.js'), import('/static/js/command.js'),"
        " import('/static/js/events.js')]);"
        f" {body} }}"
    )


def close(a: float, b: float) -> bool:
    return math.isclose(a, b, rel_tol=1e-9, abs_tol=1e-9)


# -- served as modules ---------------------------------------------------------------------------
def test_modules_and_vendored_files_are_served_as_they_must_be(web: UvicornThread) -> None:
    names = [p.relative_to(STATIC).as_posix() for p in STATIC.rglob("*") if p.is_file()]
    assert "js/forms.js" in names and "vendor/uplot/uPlot.iife.min.js" in names
    assert "vendor/uplot/LICENSE" in names
    for name in names:
        r = httpx.get(f"{web.url}/static/{name}", timeout=30)  # public: no token
        assert r.status_code == 200, name
        if name.endswith(".js"):
            assert r.headers["content-type"].startswith("text/javascript"), name
        if name.endswith(".css"):
            assert r.headers["content-type"].startswith("text/css"), name
        for marker in ("http://", "https://", "//cdn", "@import"):
            assert marker not in r.text, (name, marker)
    page = httpx.get(web.page_url, follow_redirects=True, timeout=30).text
    assert '<script type="module" src="/static/app.js">' in page
    assert "1.6.32" in (STATIC / "vendor" / "uplot" / "README.md").read_text("utf-8")


def test_the_package_data_ships_every_static_file() -> None:
    import fnmatch
    import tomllib

    pyproject = tomllib.loads((STATIC.parents[2] / "pyproject.toml").read_text("utf-8"))
    patterns = pyproject["tool"]["setuptools"]["package-data"]["skeye"]
    for path in STATIC.rglob("*"):
        if path.is_file():
            name = path.relative_to(STATIC.parents[1]).as_posix()  # ground/static/...
            assert any(fnmatch.fnmatchcase(name, p) and name.count("/") == p.count("/")
                       for p in patterns), f"{name} is not in the wheel's package data"


# -- forms from the table ----------------------------------------------------------------------
def test_every_field_comes_from_the_command_table(page: Any) -> None:
    fields = page.evaluate(
        "[...document.querySelectorAll('[data-form] [data-arg]')].map(el => ({id: el.id,"
        " tag: el.tagName, min: el.getAttribute('min'), max: el.getAttribute('max'),"
        " step: el.getAttribute('step'), value: el.value,"
        " options: el.tagName === 'SELECT' ? [...el.options].map(o => o.value) : null,"
        " label: el.closest('label').textContent.trim(), title: el.title}))"
    )
    shown = {f["id"]: f for f in fields}
    expected = {f"arg-{c.name}-{a.name}" for c in COMMANDS.values() for a in c.args
                if (c.name, a.name) not in FIXED}
    assert set(shown) == expected
    table = {c["name"]: {a["name"]: a for a in c["args"]} for c in describe_commands(LIMITS)}
    for spec in COMMANDS.values():
        for arg in spec.args:
            if (spec.name, arg.name) in FIXED:
                continue
            f = shown[f"arg-{spec.name}-{arg.name}"]
            described = table[spec.name][arg.name]
            assert f["label"].startswith(arg.label), f
            assert f["label"].endswith(arg.display_unit), f
            if arg.choices:
                assert f["tag"] == "SELECT" and tuple(f["options"]) == arg.choices
                assert f["value"] == arg.start_value
                continue
            k = arg.display_factor
            assert close(float(f["min"]), described["min"] * k), f
            assert close(float(f["max"]), described["max"] * k), f
            assert float(f["step"]) == arg.step, f
            start = arg.start_value
            if start is None:
                assert f["value"] == "", f
            else:
                assert isinstance(start, float) and close(float(f["value"]), start * k), f
            if arg.help:
                assert arg.help in f["title"], f
            if arg.limit:
                assert described["limit"]["key"] in f["title"], f
                # the limit in the field's own unit (degrees per second for the yaw rate)
                at_most = round(described["limit"]["value"] * k, 3)
                assert f"at most {at_most:g} {arg.display_unit}".rstrip() in f["title"], f
    # A latitude to 1 cm fits its field (it showed "50.812").
    width = page.evaluate("document.getElementById('arg-goto_gps-latitude_deg')"
                          ".getBoundingClientRect().width")
    assert width >= 120, width
    # The vehicle's limits reach the fields: yaw rate 100 °/s, speeds 3 m/s.
    assert close(float(shown["arg-velocity-yaw_rate_rad_s"]["max"]),
                 math.degrees(LIMITS.max_yaw_rate_rad_s))
    assert shown["arg-move_by-speed_m_s"]["max"] == "3"


def test_keyboard_speed_comes_from_the_table(page: Any) -> None:
    kbd = page.evaluate("(() => { const el = document.getElementById('kbd-speed');"
                        " return {min: el.min, max: el.max, step: el.step, value: el.value}; })()")
    described = describe_keyboard(LIMITS)["speed"]
    assert float(kbd["max"]) == described["max"] == LIMITS.max_speed_m_s == 3.0
    assert float(kbd["min"]) == described["min"] == KEYBOARD.speed.lo
    assert float(kbd["value"]) == KEYBOARD.speed.start_value
    assert float(kbd["step"]) == KEYBOARD.speed.step
    # the same bound as the velocity command's speeds
    velocity = {a["name"]: a for a in describe_commands(LIMITS)[0]["args"]}
    assert described["max"] == velocity["forward_m_s"]["max"]
    assert page.evaluate("S.keyboard.yaw_rate_rad_s") == KEYBOARD.yaw_rate_rad_s
    assert page.evaluate("S.keyboard.repeat_s") == KEYBOARD.repeat_s


def test_a_field_typed_out_of_range_is_marked(page: Any) -> None:
    page.fill("#arg-move_by-speed_m_s", "3.5")
    assert page.evaluate("document.getElementById('arg-move_by-speed_m_s')"
                         ".classList.contains('out-of-range')")
    assert "over the maximum 3 m/s" in page.get_attribute("#arg-move_by-speed_m_s", "title")
    page.fill("#arg-move_by-speed_m_s", "0.5")
    assert page.get_attribute("#arg-move_by-speed_m_s", "class") in ("", None)


def test_a_new_hello_updates_the_fields_and_keeps_what_was_typed(page: Any) -> None:
    count = page.evaluate("document.querySelectorAll('[data-arg]').length")
    page.fill("#arg-velocity-forward_m_s", "0.7")
    hellos = page.evaluate("S.hellos")
    page.evaluate("S.ws.close()")  # the page reconnects and gets a new hello
    page.wait_for_function(f"S.hellos > {hellos} && S.ws.readyState === WebSocket.OPEN",
                           timeout=30_000)
    assert page.evaluate("document.querySelectorAll('[data-arg]').length") == count
    assert page.input_value("#arg-velocity-forward_m_s") == "0.7"
    assert page.get_attribute("#arg-velocity-forward_m_s", "max") == "3"


# -- helpers, unit by unit ---------------------------------------------------------------------
def test_unit_conversions(page: Any) -> None:
    from skeye.ground.commands import DISPLAY_FACTORS

    factors = js(page, "return units.DISPLAY_FACTORS;")
    assert factors == {f"{si}→{shown}": k for (si, shown), k in DISPLAY_FACTORS.items()}
    r = js(page, "return {deg: units.toDisplay(1, 'rad/s', '°/s'),"
                 " back: units.fromDisplay(100, 'rad/s', '°/s'), same: units.factor('m', 'm'),"
                 " tidy: units.toDisplay(100 * Math.PI / 180, 'rad', '°'),"
                 " bad: (() => { try { units.factor('m/s', 'km/h'); return ''; }"
                 " catch (e) { return e.message; } })()};")
    assert close(r["deg"], 57.29577951) and close(r["back"], math.radians(100))
    assert r["same"] == 1 and r["tidy"] == 100
    assert r["bad"] == "no conversion from m/s to km/h"


SPEED = {"name": "speed_m_s", "min": 0.05, "max": 3.0, "limit": None, "default": 1.0,
         "choices": None, "help": "", "label": "at", "si_unit": "m/s", "unit": "m/s",
         "step": 0.1, "initial": 0.5}
YAW = {**SPEED, "name": "yaw_rate_rad_s", "min": -1.0, "max": 1.0, "label": "yaw",
       "si_unit": "rad/s", "unit": "°/s", "step": 5.0, "initial": 0.5}


def test_form_generation_and_reading(page: Any) -> None:
    r = js(page, f"const speed = {SPEED}, yaw = {YAW};".replace("None", "null") + """
        const label = forms.buildField(document, yaw, 'test-yaw');
        const input = label.querySelector('input');
        const out = {text: label.textContent, min: input.min, max: input.max, step: input.step,
                     value: input.value, id: input.id, read: forms.readField(input, yaw)};
        input.value = '';
        try { forms.readField(input, yaw); } catch (e) {
          out.blank = e.message; out.isBlank = e instanceof forms.BlankField; }
        const sel = forms.buildField(document, {name: 'frame', choices: ['body', 'world'],
          label: 'frame', unit: '', initial: 'world', help: 'h', limit: null}, 'test-frame');
        const chosen = sel.querySelector('select');
        out.select = [chosen.value, chosen.options.length];
        out.range = [forms.rangeProblem(speed, 3.5), forms.rangeProblem(speed, 0.01),
                     forms.rangeProblem(speed, 2)];
        out.clamp = [forms.clampToArg(speed, 7), forms.clampToArg(speed, 0),
                     forms.clampToArg(speed, 1)];
        return out;""")
    assert r["text"] == "yaw  °/s" and r["id"] == "test-yaw"
    assert close(float(r["max"]), 57.29577951) and float(r["min"]) == -float(r["max"])
    assert r["step"] == "5" and close(float(r["value"]), 28.64788976)
    assert close(r["read"], 0.5)
    assert r["isBlank"] and r["blank"] == ('the "yaw" field is blank; fill it in '
                                           "(0 where you mean none)")
    assert r["select"] == ["world", 2]
    assert r["range"] == ["at: 3.5 m/s is over the maximum 3 m/s",
                          "at: 0.01 m/s is under the minimum 0.05 m/s", ""]
    assert r["clamp"] == [3, 0.05, 1]


def test_table_errors_and_fixed_choices(page: Any) -> None:
    r = js(page, """
        const pad = S.commands.get('pad_mode');
        const err = (f) => { try { f(); return ''; } catch (e) { return e.message; } };
        return {
          fixed: forms.fixedArgs(pad, 'mode=land'),
          badChoice: err(() => forms.fixedArgs(pad, 'mode=fly')),
          badUnit: err(() => forms.indexCommands([{name: 'x', args: [{name: 'a_m', si_unit: 'm',
            unit: 'ft', choices: null}]}])),
          read: forms.readArgs(document, pad, {mode: 'hold'}),
          summary: forms.limitsSummary([...S.commands.values()]).text,
        };""")
    assert r["fixed"] == {"mode": "land"}
    assert r["badChoice"] == "page layout: pad_mode has no choice mode=fly"
    assert r["badUnit"] == "no conversion from m to ft"
    assert r["read"] == {"mode": "hold", "deadband_m": 0.05, "max_speed_m_s": 0.3}
    assert r["summary"] == ("vehicle limits: speed 3 m/s · climb 1.5 m/s · yaw 100 °/s "
                            "(robot file hummingbird)")


def test_keyboard_velocity_is_clamped_to_the_table(page: Any) -> None:
    r = js(page, """
        const v = S.commands.get('velocity'), k = S.keyboard;
        return [keyboard.keyVelocity(v, k, {fwd: 1, right: -1, up: 1, yaw: -1}, 3, true),
                keyboard.keyVelocity(v, k, {fwd: 0, right: 0, up: 0, yaw: 0}, 0.5, false)];""")
    held, stop = r
    assert held == {"forward_m_s": 3, "right_m_s": -3, "up_m_s": LIMITS.max_climb_m_s,
                    "yaw_rate_rad_s": -KEYBOARD.yaw_rate_rad_s, "duration_s": KEYBOARD.duration_s}
    assert stop == {"forward_m_s": 0, "right_m_s": 0, "up_m_s": 0, "yaw_rate_rad_s": 0,
                    "duration_s": 0}


def test_telemetry_formatting(page: Any) -> None:
    r = js(page, """
        const t = {link: {packet_rate_hz: 19.6, round_trip_ms: 12.4, last_packet_age_s: null,
                          frame_errors: 2, connects: 3},
                   nav: {height_m: 1.234, north_m: -0.5, east_m: 2, vel_ned_m_s: [0.1, 0, -0.2],
                         speed_m_s: 0.1, climb_m_s: 0.2, battery_v: 12.345},
                   status: {motors_on: true, flying: true, height_control: true,
                            position_control: false, up_time_s: 42, battery_v: 12},
                   gps: {latitude_deg: 47.1, longitude_deg: 8.5, fix: true, height_m: 500.04,
                         horizontal_accuracy_m: 2.5, num_sv: 9}};
        return {rows: Object.fromEntries(telemetry.readouts(t).map(([id, text, value]) =>
                  [id, [text, value === undefined ? 'none' : value]])),
                blank: [telemetry.fmt(null), telemetry.fmt(undefined), telemetry.fmt(NaN),
                        telemetry.fmt(1.005, 1, ' m')],
                results: [command.describeResult('land', {ok: true}).text,
                  command.describeResult('take_off', {ok: false, code: 4, code_name: 'REFUSED',
                    reason: 'busy'}).text,
                  command.describeResult('velocity', {status: 422, error: 'bad'}).text]};""")
    rows = r["rows"]
    assert rows["lq-rate"] == ["20", 19.6] and rows["lq-rtt"] == ["12 ms", "none"]
    assert rows["lq-age"] == ["—", None] and rows["lq-connects"] == ["2", 3]
    assert rows["ro-height"] == ["1.23 m", 1.234] and rows["ro-battery"] == ["12.35 V", 12.345]
    assert rows["ro-vd"] == ["-0.20", "none"]
    assert rows["ro-motors"] == ["on · flying", "none"] and rows["ro-fmode"][0] == "alt"
    assert rows["ro-latlon"][0] == "47.1000000, 8.5000000" and rows["ro-gpsfix"][0] == "3D fix"
    assert "ro-roll" not in rows  # no IMU in this message: nothing shown for it
    assert r["blank"] == ["—", "—", "—", "1.0 m"]
    assert r["results"] == ["land: accepted",
                            "take_off: REFUSED by the vehicle — code 4 REFUSED: busy",
                            "velocity: not sent (422) — bad"]


def test_a_sticks_take_over_is_logged_with_the_state_it_ended(page: Any) -> None:
    r = js(page, """
        return {lines: [telemetry.stateChangeLine('failsafe', 'manual'),
                        telemetry.stateChangeLine('taking_off', 'manual'),
                        telemetry.stateChangeLine('manual', 'manual'),
                        telemetry.stateChangeLine('holding', 'flying'),
                        telemetry.stateChangeLine(null, 'manual')],
                cls: telemetry.FLIGHT_CLASSES.manual};""")
    assert r["lines"] == ["vehicle: manual sticks took over (was failsafe)",
                          "vehicle: manual sticks took over (was taking off)", None, None, None]
    assert r["cls"] == "warn"


def test_plot_data_helpers(page: Any) -> None:
    r = js(page, """
        const rows = [{t: 1, a: 1, b: null}, {t: 2, a: 2}, {t: 3, a: null, b: 5}];
        return {cols: plots.columns(rows, ['a', 'b'], 2), all: plots.columns(rows, ['a']),
                ranges: [plots.paddedRange(null, null), plots.paddedRange(1, 1),
                         plots.paddedRange(0, 10)],
                clock: plots.clockTime(new Date(2026, 0, 1, 13, 4, 5).getTime() / 1000)};""")
    assert r["cols"] == [[2, 3], [2, None], [None, 5]]
    assert r["all"] == [[1, 2, 3], [1, 2, None]]
    assert r["ranges"][0] == [-0.5, 0.5]
    assert [round(x, 9) for x in r["ranges"][1]] == [0.7, 1.3]
    assert r["ranges"][2] == [-1, 11]
    assert r["clock"] == "13:04:05"  # local clock, 24 h


# -- plots: legend, zoom, back to live ---------------------------------------------------------
def test_plots_have_legends_and_zoom(page: Any) -> None:
    page.evaluate("(() => { const now = Date.now() / 1000;"
                  " for (let i = 0; i < 200; i++) S.series.push({t: now - 40 + i * 0.2,"
                  " height: Math.sin(i / 10), dx: null, dy: null}); })()")
    page.wait_for_function("Number(document.getElementById('plot-height').dataset.points) >= 200",
                           timeout=30_000)
    legend = page.inner_text("#plot-height .u-legend")
    assert "height above ground" in legend
    # the cursor's time in the legend has seconds (uPlot's default shows minutes only)
    shown = page.evaluate("plots.height.plot.series[0].value(plots.height.plot, "
                          "new Date(2026, 0, 1, 13, 4, 5).getTime() / 1000)")
    assert shown == "13:04:05", shown
    assert "forward" in page.inner_text("#plot-pad .u-legend")
    assert page.is_visible("#plot-pad .plot-empty")  # no pad estimate in these rows
    box = page.locator("#plot-height .u-over").bounding_box()
    y = box["y"] + box["height"] / 2
    page.mouse.move(box["x"] + box["width"] * 0.3, y)
    page.mouse.down()
    page.mouse.move(box["x"] + box["width"] * 0.5, y, steps=5)
    page.mouse.up()
    page.wait_for_function("document.getElementById('plot-height').dataset.live === 'false'",
                           timeout=10_000)
    span = page.evaluate("plots.height.plot.scales.x.max - plots.height.plot.scales.x.min")
    assert span < 30, span  # zoomed in from the 60 s window
    page.mouse.dblclick(box["x"] + box["width"] * 0.5, y)
    page.wait_for_function("document.getElementById('plot-height').dataset.live === 'true'",
                           timeout=10_000)
    page.wait_for_function("(() => { const x = plots.height.plot.scales.x;"
                           " return Math.abs(x.max - x.min - 60) < 1e-6; })()", timeout=10_000)


def test_vehicle_events_are_rate_limited_per_kind(page: Any) -> None:
    """Issue 34 item 3: 69 on/off lines in 9 minutes buried the answers. Vehicle events have
    their own list, and a kind that comes again within a minute updates its line."""
    r = js(page, """
        const log = document.getElementById('event-log');
        log.replaceChildren();
        const t0 = 1e6;
        for (let i = 0; i < 40; i++) {  // on and off every 3 s for 2 minutes
          events.eventLine('vision', i % 2 ? 'in time again' : 'too slow', i % 2 ? 'ok' : 'bad',
                           t0 + 3 * i);
        }
        events.eventLine('pad-landed', 'pad landing finished', 'ok', t0 + 120);
        const lines = [...log.children].map(li => [li.dataset.kind, li.dataset.text,
                                                     Number(li.dataset.repeats)]);
        return {lines, answers: document.getElementById('cmd-log').children.length};""")
    lines = r["lines"]
    assert lines[0] == ["pad-landed", "pad landing finished", 1], lines
    vision = [line for line in lines if line[0] == "vision"]
    assert len(vision) == 2 and sum(n for _, _, n in vision) == 40, vision  # one a minute
    assert vision[0][1] == "in time again"  # the newest state on top
    assert r["answers"] == 0  # none of it in the commands' answers
