"""The HTML report in a real browser (headless Debian Chromium through Playwright): no console
or page error, every figure loads, the slider redraws the canvas and play advances frames."""

from __future__ import annotations

import importlib.util
import shutil
from pathlib import Path

import pytest

CHROMIUM = Path("/usr/bin/chromium")
ARGS = [
    "--no-sandbox",
    "--disable-gpu",
    "--disable-background-networking",
    "--disable-component-update",
    "--disable-sync",
    "--no-first-run",
]


def _browser_or_skip():
    try:
        from playwright.sync_api import sync_playwright
    except ImportError:
        pytest.skip("playwright is not installed (pip install '.[test]')")
    if not CHROMIUM.is_file() and shutil.which("chromium") is None:
        pytest.skip("Debian's chromium is not installed (apt-get install chromium)")
    return sync_playwright, str(CHROMIUM if CHROMIUM.is_file() else shutil.which("chromium"))


def _tiny_run():
    """The tiny fit + report of test_report.py (shared when both files run in one session)."""
    try:
        from test_report import tiny_run
    except ImportError:  # another import mode: load it by path (the fit is then redone)
        spec = importlib.util.spec_from_file_location(
            "report_tests", Path(__file__).with_name("test_report.py")
        )
        module = importlib.util.module_from_spec(spec)
        spec.loader.exec_module(module)
        tiny_run = module.tiny_run
    return tiny_run


@pytest.fixture(scope="module")
def page(tmp_path_factory):
    sync_playwright, executable = _browser_or_skip()
    tiny_run = _tiny_run()
    report = tiny_run(tmp_path_factory.mktemp("report"))[1]
    with sync_playwright() as p:
        browser = p.chromium.launch(executable_path=executable, args=ARGS)
        try:
            pg = browser.new_page(viewport={"width": 1200, "height": 900})
            errors: list[str] = []
            pg.on("console", lambda m: errors.append(m.text) if m.type == "error" else None)
            pg.on("pageerror", lambda e: errors.append(f"page error: {e}"))
            requests: list[str] = []
            pg.on("request", lambda r: requests.append(r.url))
            pg.goto(report.resolve().as_uri(), wait_until="load")
            pg.errors, pg.requests = errors, requests  # type: ignore[attr-defined]
            yield pg
        finally:
            browser.close()


def _canvas(pg) -> str:
    return pg.evaluate("document.getElementById('canvas').toDataURL('image/png')")


def test_page_loads_without_errors_and_offline(page):
    assert page.title().startswith("activebonds report")
    page.wait_for_timeout(200)
    assert page.errors == []
    # nothing but the file itself (and its data: URIs) was requested
    assert all(u.startswith(("file://", "data:")) for u in page.requests), page.requests


def test_every_figure_is_loaded(page):
    sizes = page.evaluate(
        "Array.from(document.images).map(i => [i.complete, i.naturalWidth, i.naturalHeight])"
    )
    assert len(sizes) >= 6
    assert all(done and w > 0 and h > 0 for done, w, h in sizes), sizes


def test_slider_redraws_the_canvas(page):
    label = page.locator("#frame-label")
    first_label, first = label.inner_text(), _canvas(page)
    page.focus("#frame")
    page.keyboard.press("End")  # as a user would move the slider to the last frame
    assert page.input_value("#frame") == page.get_attribute("#frame", "max") == "19"
    assert _canvas(page) != first
    assert label.inner_text() != first_label and "beyond the fit" in label.inner_text()
    page.select_option("#mode", "free")
    free_only = _canvas(page)
    page.select_option("#mode", "one")
    assert _canvas(page) != free_only
    page.select_option("#zoom", "0")  # around the first particle
    assert _canvas(page) != free_only
    page.select_option("#mode", "both")
    page.select_option("#zoom", "all")
    assert page.errors == []


def test_play_advances_frames_and_pause_stops(page):
    page.focus("#frame")
    page.keyboard.press("Home")
    assert page.input_value("#frame") == "0"
    before = _canvas(page)
    page.click("#play")
    page.wait_for_function("document.getElementById('frame').value !== '0'", timeout=5000)
    assert page.get_attribute("#play", "aria-pressed") == "true"
    page.click("#play")
    assert page.get_attribute("#play", "aria-pressed") == "false"
    stopped = page.input_value("#frame")
    page.wait_for_timeout(300)
    assert page.input_value("#frame") == stopped
    assert _canvas(page) != before
    assert page.errors == []
