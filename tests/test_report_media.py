"""The report's media: the MP4 beside the GIF and embedded in the report (without ffmpeg: a
one-line note instead), frames numbered as in the recording for a window that does not start
at frame 0, the animation's legend inside its figure (GIF) and inside the canvas (browser
player), and labelled ticks bracketing the final error on the convergence plot's log axis."""

from __future__ import annotations

import base64
import gc
import json
import re
import warnings
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

from activebonds.data import write_trajectory
from activebonds.identify import fit
from activebonds.model import load_model
from activebonds.report import animation, load_run, plots, predict, write_report
from activebonds.report.html import Section, write_comparison_report
from activebonds.simulation import simulate
from helpers import BROWSER_ARGS, browser_or_skip

ROOT = Path(__file__).resolve().parents[1]
TRIANGLE = ROOT / "examples" / "triangle.toml"
START, STOP = 30, 50  # the fitted window: frames 30..49 of a 90-frame recording
LONG = ("standard bonds, best of 5 seeds (population 500)", "neural bonds, best of 5 seeds")


@pytest.fixture(scope="module")
def run(tmp_path_factory):
    """A tiny fit of the triangle on frames 30:50 of a simulated recording, and its report."""
    base = tmp_path_factory.mktemp("media")
    model = load_model(TRIANGLE)
    data = write_trajectory(simulate(model, 90, 60.0), base / "triangle.csv")
    out = base / "run"
    fit(TRIANGLE, data, out=out, frames=(START, STOP), population=8, generations=4, refine="none")
    return out, write_report(out)


@pytest.fixture(scope="module")
def triangle():
    model = load_model(TRIANGLE)
    return predict(model, simulate(model, 24, 60.0), fit_frames=12)


def _report_data(text: str) -> dict:
    m = re.search(r'<script type="application/json" id="report-data">(.*?)</script>', text, re.S)
    return json.loads(m.group(1))


def _read_mp4(path: Path, monkeypatch) -> tuple[dict, int]:
    """read_frames' metadata and the number of frames it yields."""
    import imageio_ffmpeg

    # no preexec_fn in the forked child of this multithreaded (JAX) process
    monkeypatch.setenv("IMAGEIO_FFMPEG_NO_PREVENT_SIGINT", "1")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", ResourceWarning)  # it leaves its pipes to the GC
        frames = imageio_ffmpeg.read_frames(str(path))
        meta = next(frames)
        n = sum(1 for _ in frames)
        del frames
        gc.collect()
    return meta, n


# ----------------------------------------------------------------------------- MP4


@pytest.mark.slow  # integration scale: in `pytest -m slow` (every landing)
def test_the_mp4_beside_the_gif_has_the_gifs_frames(run, monkeypatch):
    run_dir, report = run
    figs = run_dir / "figures"
    mp4, gif = figs / "animation.mp4", figs / "animation.gif"
    assert mp4.is_file() and gif.is_file()
    head = mp4.read_bytes()[:12]
    assert head[4:8] == b"ftyp", head  # an ISO base media (MP4) file
    meta, n = _read_mp4(mp4, monkeypatch)
    with Image.open(gif) as g:
        assert n == g.n_frames == 2 * (STOP - START)  # the window and as many frames beyond
        assert tuple(meta["size"]) == g.size
    assert meta["codec"].startswith("h264")
    assert meta["fps"] == pytest.approx(12.0)
    text = report.read_text(encoding="utf-8")
    video = re.search(r'<video [^>]*src="data:video/mp4;base64,([^"]+)"', text)
    assert video and base64.b64decode(video.group(1)) == mp4.read_bytes()  # in the report too


# ----------------------------------------------------------------------------- frame numbers


@pytest.mark.slow  # integration scale: in `pytest -m slow` (every landing)
def test_frames_are_numbered_as_in_the_recording(run):
    run_dir, report = run
    text = report.read_text(encoding="utf-8")
    anim = _report_data(text)["animations"][0]
    n = 2 * (STOP - START)
    assert anim["frame_numbers"] == list(range(START, START + n))
    assert anim["first_frame"] == START and anim["fit_end"] == STOP
    assert anim["times"][0] == pytest.approx(START / 60.0)
    assert f"Frames {START}–{STOP - 1} of the recording were fitted" in text
    assert f"frames {STOP}–{START + n - 1} test generalisation" in text
    assert f"{START}:{STOP}" in text  # the summary's and the free-run table's windows

    record = load_run(run_dir)
    pred = predict(record.model, record.window)
    fig = plots.trajectories_figure(pred, first_frame=START, start_time=record.window.start_time)
    ax = fig.axes[0]
    xs = ax.get_lines()[0].get_xdata()
    assert xs[0] == START and xs[-1] == STOP - 1
    lo, hi = ax.get_xlim()
    assert lo < START and START <= hi <= STOP + 2

    scene = animation.Scene([("run", pred)], first_frame=START, start_time=record.window.start_time)
    assert scene.caption_text(0).startswith(f"frame {START}  t = {START / 60:.3f} s")


def test_the_player_labels_the_recordings_frame_numbers(run):
    sync_playwright, executable = browser_or_skip()
    _, report = run
    with sync_playwright() as p:
        browser = p.chromium.launch(executable_path=executable, args=BROWSER_ARGS)
        try:
            pg = browser.new_page(viewport={"width": 1200, "height": 900})
            errors: list[str] = []
            pg.on("pageerror", lambda e: errors.append(str(e)))
            pg.goto(report.resolve().as_uri(), wait_until="load")
            label = pg.locator("#frame-label")
            assert label.inner_text().startswith(
                f"frame {START} / {START + 2 * (STOP - START) - 1}"
            )
            assert "fitted window" in label.inner_text()
            pg.focus("#frame")
            pg.keyboard.press("End")
            assert label.inner_text().startswith(f"frame {START + 2 * (STOP - START) - 1} ")
            assert "beyond the fit" in label.inner_text()
            assert errors == []
        finally:
            browser.close()


# ----------------------------------------------------------------------------- legends


def test_the_gif_legend_lies_within_the_figure(triangle):
    for preds in ([("run", triangle)], [(label, triangle) for label in LONG * 3]):
        scene = animation.Scene(preds)
        fig = scene.fig
        fig.canvas.draw()
        box = scene.legend.get_window_extent(fig.canvas.get_renderer())
        assert fig.bbox.x0 <= box.x0 and box.x1 <= fig.bbox.x1, (box, fig.bbox)
        assert fig.bbox.y0 <= box.y0 and box.y1 <= fig.bbox.y1, (box, fig.bbox)
        frame = scene.render(0)
        assert frame.shape[0] % 16 == 0 and frame.shape[1] % 16 == 0
        assert frame.shape[1] >= fig.bbox.width - 1  # nothing of the figure cut off


def test_the_player_legend_lies_within_the_canvas(triangle, tmp_path):
    sync_playwright, executable = browser_or_skip()
    preds = [(label, triangle) for label in LONG]
    page = tmp_path / "long.html"
    write_comparison_report(page, "long labels", [Section("a", animation=animation.payload(preds))])
    with sync_playwright() as p:
        browser = p.chromium.launch(executable_path=executable, args=BROWSER_ARGS)
        try:
            pg = browser.new_page(viewport={"width": 1200, "height": 900})
            pg.goto(page.resolve().as_uri(), wait_until="load")
            x, y, w, h = map(float, pg.get_attribute("#canvas", "data-legend").split(","))
            width, height = pg.evaluate(
                "[document.getElementById('canvas').width, document.getElementById('canvas').height]"
            )
            assert 0 <= x and x + w <= width and 0 <= y and y + h <= height, (x, y, w, h)
            # the longest label fits its box (measured as the player measures it)
            widest = pg.evaluate(
                """(labels) => { const c = document.getElementById('canvas').getContext('2d');
                   return Math.max(...labels.map(t => c.measureText(t).width)); }""",
                [f"{label} one-step" for label in LONG],
            )
            assert widest <= w
        finally:
            browser.close()


# ----------------------------------------------------------------------------- log ticks


def _labelled_ticks(fig) -> list[float]:
    fig.canvas.draw()
    ax = fig.axes[0]
    lo, hi = ax.get_ylim()
    return [
        t.get_position()[1]
        for t in ax.get_yticklabels(minor=False) + ax.get_yticklabels(minor=True)
        if t.get_text() and lo <= t.get_position()[1] <= hi
    ]


@pytest.mark.parametrize(
    "best",
    [
        np.geomspace(0.12, 9.37e-4, 200),  # the triangle's course: ends just under a decade
        np.geomspace(50.0, 2.0e-13, 300),  # many decades, final far below them
        np.geomspace(3.1, 2.4, 50),  # less than a decade
        np.geomspace(1.0, 1e-3, 40),  # ends on a power of ten
    ],
)
def test_log_ticks_bracket_the_final_error(best):
    history = {"best_rms_mm": best, "median_rms_mm": best * 1.5}
    fig = plots.convergence_figure(
        [plots.Series("run", [history])], references=[("zero force", 0.06)]
    )
    final = float(best[-1])
    assert plots.final_values(fig) == [pytest.approx(final)]
    ticks = _labelled_ticks(fig)
    assert any(final / 10 <= t <= final * (1 + 1e-9) for t in ticks), (final, ticks)
    assert any(final * (1 - 1e-9) <= t <= final * 10 for t in ticks), (final, ticks)
    texts = [t.get_text() for t in fig.axes[0].texts]
    assert f"{final:.3g} mm" in texts  # the final value written beside the last point


def test_log_ticks_bracket_each_series_final_error():
    rng = np.random.default_rng(0)
    series = [
        plots.Series(
            label,
            [
                {
                    "best_rms_mm": end * np.geomspace(1e3, 1, 60) * rng.uniform(1, 1.1, 60),
                    "median_rms_mm": end * np.geomspace(2e3, 2, 60),
                }
                for _ in range(3)
            ],
        )  # fmt: skip
        for label, end in (("standard", 4.2e-2), ("neural", 3.3e-5))
    ]
    fig = plots.convergence_figure(series)
    ticks = _labelled_ticks(fig)
    finals = plots.final_values(fig)
    assert len(finals) == 2
    for final in finals:
        assert any(final / 10 <= t <= final for t in ticks), (final, ticks)
        assert any(final <= t <= final * 10 for t in ticks), (final, ticks)


# ----------------------------------------------------------------------------- no ffmpeg
# (last: it rewrites the run's report, replacing a figures folder that holds the MP4)


def test_without_ffmpeg_the_report_is_written_with_a_one_line_note(run, monkeypatch):
    run_dir, report = run
    figs = run_dir / "figures"
    assert (figs / "animation.mp4").is_file()

    def no_ffmpeg():
        raise RuntimeError("No ffmpeg exe could be found.\nInstall ffmpeg on your system.")

    def quick_save(fig, stem):  # the static figures are not what this test is about
        paths = [Path(stem).with_suffix(".png"), Path(stem).with_suffix(".svg")]
        Image.new("RGB", (4, 4), "white").save(paths[0])
        paths[1].write_text("<svg xmlns='http://www.w3.org/2000/svg'/>")
        return paths

    monkeypatch.setattr(animation, "_ffmpeg", no_ffmpeg)
    monkeypatch.setattr(plots, "save", quick_save)
    assert write_report(run_dir) == report
    assert (figs / "animation.gif").is_file() and not (figs / "animation.mp4").exists()
    assert not list(figs.glob(".*"))  # no partial file left
    text = report.read_text(encoding="utf-8")
    notes = re.findall(r'<p class="note">(No MP4[^<]*)</p>', text)
    assert notes == [
        "No MP4 of the animation: ffmpeg is unavailable (No ffmpeg exe could be found.)."
    ]
    assert "animation.mp4" not in text and "<video" not in text
