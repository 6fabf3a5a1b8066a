"""In a notebook, a Trajectory, a Model, a FitResult and a run print as one short line (sizes,
rate, kinds, error, verdict and status, never an array) and show as a small HTML table; a
FitResult carries its baselines and verdict; ``fit(progress=...)`` calls a function with
increasing generation counts, and ``progress=True`` shows a bar (rich's in a terminal or a
log, an HTML ``<progress>`` updated in place in Jupyter)."""

from __future__ import annotations

import dataclasses
import math
import re
import sys
import types

import pytest

from activebonds import fit, load_model, read_trajectory
from activebonds.identify.progress import ProgressBar
from activebonds.identify.rundir import RunDir
from activebonds.report.runs import load_run
from helpers import HORSE_LIMB, HORSE_TROT, ROOT, TRIANGLE

TRIANGLE_CSV = ROOT / "examples" / "triangle.csv"
SHORT = dict(frames=(0, 30), population=8, generations=3, chunk=1, refine="none")


def _short(text: str, limit: int = 300) -> None:
    assert "\n" not in text and len(text) <= limit, text
    assert "array(" not in text and "[[" not in text, text


def test_trajectory_repr():
    text = repr(read_trajectory(HORSE_TROT))
    _short(text)
    assert text.startswith("Trajectory(600 frames x 7 markers [Head, Withers,")
    assert "60 Hz" in text and "0 missing marker-frames" in text


def test_model_repr():
    text = repr(load_model(HORSE_LIMB))
    _short(text)
    assert text == "Model('horse_limb', 3D, 3 particles, bonds: 3 binary, 27 free parameters)"


@pytest.fixture(scope="module")
def fitted(tmp_path_factory):
    """A short fit of the triangle with a run directory, its progress calls recorded."""
    calls = []
    said = []
    run = tmp_path_factory.mktemp("reprs") / "run"
    result = fit(
        TRIANGLE,
        TRIANGLE_CSV,
        out=run,
        progress=lambda g, total, rms: calls.append((g, total, rms)),
        status=said.append,
        **SHORT,
    )
    return result, calls, said


def _cells(page: str) -> dict[str, str]:
    """The (name, value) rows of an HTML table of ours."""
    assert page.startswith("<table") and page.endswith("</table>")
    return dict(re.findall(r"<th[^>]*>(.*?)</th><td[^>]*>(.*?)</td>", page))


def test_fit_result_repr_baselines_and_verdict(fitted):
    result, _, _ = fitted
    text = repr(result)
    _short(text, 400)
    assert text.startswith("FitResult(Model('triangle'")
    assert f"rms {result.rms_mm:.4g} mm" in text and "es 8 x 3" in text
    zero = result.baselines["zero_force_rms_mm"]
    # the triangle's recording has no noise: every model of its springs beats zero force
    assert math.isfinite(zero) and zero > result.rms_mm > 0
    assert f"(zero force {zero:.4g} mm)" in text
    v = result.verdict
    assert v.better and v.zero_force_mm == pytest.approx(zero, rel=1e-6)
    assert f"better than zero force by {v.gain_pct:.3g} %" in text
    # the plain one-step cost: the momentum floor and the exact least squares too
    assert set(result.baselines) == {
        "zero_force_rms_mm",
        "momentum_floor_rms_mm",
        "least_squares_rms_mm",
    }
    assert result.baselines["least_squares_rms_mm"] <= result.rms_mm + 1e-9


def test_html_reprs_are_small_tables():
    traj = read_trajectory(HORSE_TROT)
    cells = _cells(traj._repr_html_())
    assert cells["shape"] == "600 frames × 7 markers × 3D"
    assert cells["markers"] == "Head, Withers, Sacrum, HFL, HFR, HHL, HHR"
    assert cells["rate"] == "60 Hz (dt 0.01667 s)" and cells["missing"].startswith("0 ")
    model = load_model(HORSE_LIMB)
    cells = _cells(model._repr_html_())
    assert cells["bonds"] == "3 binary" and cells["free parameters"] == "27"
    assert cells["particles"].startswith("3: ")
    # user text is escaped, never markup
    odd = traj.select(["Head"]).with_positions(traj.positions[:, :1], markers=("<b>x:100:",))
    assert "&lt;b&gt;x:100:" in odd._repr_html_() and "<b>x" not in odd._repr_html_()


def test_fit_result_and_run_html(fitted):
    result, _, _ = fitted
    cells = _cells(result._repr_html_())
    assert cells["RMS one-step error"] == f"{result.rms_mm:.4g} mm"
    assert cells["zero force (constant velocity)"] == (
        f"{result.baselines['zero_force_rms_mm']:.4g} mm"
    )
    assert cells["verdict, fitted frames, one step"].startswith("better than zero force by")
    assert cells["genes"] == f"{len(result.genome)} free parameters"
    run = RunDir(result.run)
    cells = _cells(run._repr_html_())
    assert cells["status"] == "completed" and cells["generations"] == "3 of 3"
    assert cells["best RMS one-step error"] == f"{result.rms_mm:.4g} mm"
    assert cells["verdict, fitted frames, one step"].startswith("better than zero force by")
    bare = dataclasses.replace(result, records={})  # a failed fit: no baselines ran
    assert bare.baselines == {} and bare.verdict is None and "zero force" not in repr(bare)
    assert "verdict, fitted frames, one step" not in _cells(bare._repr_html_())
    assert _cells(RunDir(result.run.parent)._repr_html_()) == {"status": "not a run directory"}
    record = load_run(result.run)
    _short(repr(record))
    assert repr(record).startswith(f"RunRecord({str(result.run)!r}, completed, 3 of 3")
    assert _cells(record._repr_html_())["best model"].startswith("Model(&#x27;triangle&#x27;")


def test_progress_function_sees_increasing_generations(fitted):
    _, calls, said = fitted
    assert [g for g, _, _ in calls] == [1, 2, 3]
    assert all(total == 3 and math.isfinite(rms) for _, total, rms in calls)
    assert [rms for *_, rms in calls] == sorted((rms for *_, rms in calls), reverse=True)
    assert said[0].startswith("compiling")


def test_progress_true_shows_a_bar(capsys):
    result = fit(TRIANGLE, TRIANGLE_CSV, progress=True, **SHORT)
    err = capsys.readouterr().err
    assert (
        "generation" in err and "3/3" in err and f"{result.history['best_rms_mm'][-1]:.4g}" in err
    )


def test_progress_bar_in_jupyter_updates_one_display(monkeypatch):
    """In Jupyter the bar is one HTML display updated in place (no widget library)."""
    shown = []

    class Handle:
        def update(self, page):
            shown.append(("update", page.data))

    def display(page, display_id=False):
        assert display_id
        shown.append(("display", page.data))
        return Handle()

    fake = types.ModuleType("IPython.display")
    fake.HTML = type("HTML", (), {"__init__": lambda self, data: setattr(self, "data", data)})
    fake.display = display
    monkeypatch.setitem(sys.modules, "IPython", types.ModuleType("IPython"))
    monkeypatch.setitem(sys.modules, "IPython.display", fake)
    bar = ProgressBar()
    bar.jupyter = True
    bar.status("compiling the cost")
    bar(1, 4, 2.5)
    bar(4, 4, 1.25)
    bar.close()
    assert [kind for kind, _ in shown] == ["display", "update", "update", "update"]
    assert 'value="4" max="4"' in shown[-1][1] and "best 1.25 mm" in shown[-1][1]
    assert "compiling the cost" in shown[0][1]
