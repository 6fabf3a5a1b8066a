"""Reports: prediction numbers, saturation and weight shares, figures, the self-contained HTML,
the comparison report, the ``report`` command, and the HTML report in a real browser (headless
Debian Chromium through Playwright: no console or page error, every figure loads, the slider
redraws the canvas and play advances frames)."""

from __future__ import annotations

import base64
import dataclasses
import json
import re
import shutil
from collections import Counter
from pathlib import Path

import numpy as np
import pytest
import typer
from PIL import Image
from typer.testing import CliRunner

from activebonds.data import Trajectory
from activebonds.errors import InputError
from activebonds.identify import fit
from activebonds.identify.judge.predictions import rms_mm
from activebonds.model import as_standard, load_model, loads_model
from activebonds.report import (
    Figure,
    Section,
    Series,
    Table,
    load_run,
    payload,
    plots,
    predict,
    predict_run,
    projection_axes,
    staged_directory,
    summary_table,
    write_comparison_report,
    write_report,
)
from activebonds.report.predict import near_zero_share, saturation_share
from activebonds.simulation import simulate
from helpers import BROWSER_ARGS, browser_or_skip, figure_size_px, figure_texts

ROOT = Path(__file__).resolve().parents[1]
TRIANGLE = ROOT / "examples" / "triangle.toml"
HORSE_MODEL = ROOT / "examples" / "horse_limb.toml"
HORSE_DATA = (
    ROOT / "src" / "activebonds" / "datasets" / "horse_vhdc" / "Horse1_M1_trot1_kinematics.csv"
)
FIGURES = ("convergence", "trajectories", "parameters", "variants", "weights", "activations")

_RUNS: dict[str, tuple] = {}


def report_app() -> typer.Typer:
    """The ``report`` command on its own (the main app registers the same function)."""
    from activebonds.cli.report_cmd import report

    app = typer.Typer()
    app.command()(report)
    return app


def tiny_run(base: Path):
    """One tiny neural fit of the horse limb (population 20, 30 generations) and its report
    written by the ``report`` command; made once per session, shared with the browser tests
    at the end of this file. Returns (FitResult, report path, the command's result)."""
    if "neural" not in _RUNS:
        run = base / "run"
        result = fit(
            HORSE_MODEL,
            HORSE_DATA,
            out=run,
            markers=("Head", "Withers", "HFL"),
            frames=(0, 10),
            bonds="neural",
            population=20,
            generations=30,
            refine="none",
        )
        cli = CliRunner().invoke(report_app(), [str(run)])
        assert cli.exit_code == 0, cli.output
        _RUNS["neural"] = (result, run / "report.html", cli)
    return _RUNS["neural"]


@pytest.fixture(scope="module")
def neural_run(tmp_path_factory):
    return tiny_run(tmp_path_factory.mktemp("report"))


@pytest.fixture(scope="module")
def triangle():
    model = load_model(TRIANGLE)
    return model, simulate(model, 120, 60.0)


# ----------------------------------------------------------------------------- numbers


def test_one_step_of_the_true_model_has_no_error(triangle):
    model, traj = triangle
    pred = predict(model, traj)
    err = np.abs(pred.one_step[2:] - traj.positions[2:])
    assert np.isnan(pred.one_step[:2]).all()
    assert err.max() < 1e-12
    assert pred.one_step_rms_mm.max() < 1e-9
    assert pred.one_step.dtype == np.float64


def test_free_run_of_the_true_model_reproduces_the_data(triangle):
    model, traj = triangle
    pred = predict(model, traj)
    assert np.abs(pred.free_run - traj.positions).max() < 1e-9
    assert pred.free_run_rms_mm.max() < 1e-6
    assert pred.diverged_at is None
    assert not pred.extended and pred.one_step_rms_mm_beyond is None


def test_missing_markers_are_neither_inputs_nor_counted(triangle):
    model, traj = triangle
    pos = traj.positions.copy()
    pos[0, 2] = np.nan  # frame 0 incomplete: the free run starts from frames 1 and 2
    pos[50:52, 1] = np.nan
    gappy = traj.with_positions(pos)
    pred = predict(model, gappy)
    unknown = np.flatnonzero(np.isnan(pred.one_step).any(axis=(1, 2)))
    assert unknown.tolist() == [0, 1, 2, 51, 52, 53]  # an input frame is incomplete
    assert np.abs(pred.free_run[1:] - traj.positions[1:]).max() < 1e-9
    assert np.isfinite(pred.one_step_rms_mm).all() and pred.one_step_rms_mm.max() < 1e-9
    assert np.isfinite(pred.free_run_rms_mm).all() and pred.free_run_rms_mm.max() < 1e-6
    recorded = payload([("true", pred)])["recorded"]
    assert recorded[50][1] == [None, None] and None not in recorded[49][1]


def test_a_wrong_model_has_errors_and_a_longer_window_is_generalisation(triangle):
    model, traj = triangle
    stiff = model.spec.model_copy(
        update={"bond": [b.model_copy(update={"stiffness": 400.0}) for b in model.spec.bond]}
    )
    wrong = load_model_from_spec(stiff)
    pred = predict(wrong, traj, fit_frames=60)
    assert pred.extended and pred.fit_frames == 60
    assert (pred.one_step_rms_mm > 1e-3).all() and (
        pred.free_run_rms_mm > pred.one_step_rms_mm
    ).all()
    assert pred.one_step_rms_mm_beyond.shape == (3,)


def test_a_diverging_free_run_counts_as_an_infinite_error(triangle):
    model, traj = triangle
    spec = model.spec.model_copy(
        update={"bond": [b.model_copy(update={"stiffness": 1e9}) for b in model.spec.bond]}
    )
    # fitted 0:60, beyond 60:120: each its own free run (as evaluate), long enough to diverge
    pred = predict(load_model_from_spec(spec), traj, fit_frames=60)
    assert pred.diverged_at is not None and 2 < pred.diverged_at < 100
    assert np.isnan(pred.free_run[pred.diverged_at :]).all()
    assert np.isinf(pred.free_run_rms_mm).all() and np.isinf(pred.free_run_rms_mm_beyond).all()
    assert np.isfinite(pred.one_step_rms_mm).all()  # each step starts from the recording
    data = payload([("stiff", pred)])
    json.dumps(data, allow_nan=False)  # NaN became null
    assert data["models"][0]["free_run"][-1][0] == [None, None]


def load_model_from_spec(spec):
    from activebonds.model import build

    return build(spec)


def test_rms_mm_ignores_missing_frames():
    rec = np.zeros((5, 2, 3))
    pred = rec.copy()
    pred[..., 0] += 0.003  # 3 mm off along x
    pred[1, 1] = np.nan
    pred[:, 1, 2] = [0.004, np.nan, 0.004, 0.004, 0.004]
    pred[:, 1, 0] = 0.003
    out = rms_mm(pred, rec)
    assert out[0] == pytest.approx(3.0)
    assert out[1] == pytest.approx(5.0)
    assert np.isnan(rms_mm(np.full_like(rec, np.nan), rec)).all()


def test_saturation_share_on_a_hand_built_case():
    act = np.array([[0.96, 0.5, 0.99], [-0.97, np.nan, 0.1], [0.2, -0.951, 1.0]])
    neural = np.array([True, True, False])
    share, per = saturation_share(act, neural)
    # neural samples known: 0.96, 0.5, -0.97, 0.2, -0.951 -> saturated 0.96, -0.97, -0.951
    assert share == pytest.approx(3 / 5)
    assert per[0] == pytest.approx(2 / 3) and per[1] == pytest.approx(1 / 2)
    assert np.isnan(per[2])
    share, per = saturation_share(act, np.zeros(3, bool))
    assert np.isnan(share) and np.isnan(per).all()


NEURAL_MODEL = """
name = "n3"
dimension = 2
[[particle]]
name = "a"
[[particle]]
name = "b"
[[particle]]
name = "c"
[[bond]]
kind = "binary"
particles = ["a", "b"]
rest_length = 1.0
neural = true
weights = { length = [0.0, 0.1, 5.0], rate = [0.0, -0.19, 0.3], min = -10.0, max = 10.0 }
[[bond]]
kind = "binary"
particles = ["b", "c"]
rest_length = 1.0
neural = true
weights = { length = [0.0, 0.0, -0.005], rate = [0.5, 0.0, 0.0], min = -1.0, max = 1.0 }
[[bond]]
kind = "binary"
particles = ["a", "c"]
rest_length = 1.0
"""


def test_near_zero_weight_share_on_a_hand_built_case():
    model = loads_model(NEURAL_MODEL)
    # bond 0, range 20 (near zero: |w| < 0.2): length[1] 0.1 and rate[1] -0.19 are, 5.0 and
    # 0.3 are not; bond 1, range 2 (|w| < 0.02): length[0] 0, length[2] -0.005 and rate[2] 0
    # are, rate[0] 0.5 is not; a neuron's own entry is unused; bond 2 has no neuron.
    shares = near_zero_share(model)
    assert shares == pytest.approx(5 / 8)
    assert np.isnan(near_zero_share(as_standard(model)))


def test_projection_axes_pick_the_largest_spread():
    t = np.linspace(0, 1, 50)
    pos = np.zeros((50, 2, 3))
    pos[:, 0, 0] = 2 * t  # X travels
    pos[:, 1, 2] = 0.5 * np.sin(6 * t)  # Z oscillates
    pos[:, :, 1] = 0.01 * t[:, None]  # little lateral motion
    assert projection_axes(pos) == (0, 2)
    assert projection_axes(pos[..., :2]) == (0, 1)


# ----------------------------------------------------------------------------- run report


def _html(path: Path) -> str:
    return path.read_text(encoding="utf-8")


def _report_data(text: str) -> dict:
    m = re.search(r'<script type="application/json" id="report-data">(.*?)</script>', text, re.S)
    assert m, "no JSON blob"
    return json.loads(m.group(1))


def test_report_writes_every_figure_and_leaves_no_staging_folder(neural_run):
    result, report, _ = neural_run
    run = result.run
    assert report == run / "report.html" and report.is_file()
    figs = run / "figures"
    for name in FIGURES:
        svg = figs / f"{name}.svg"
        assert svg.read_text(encoding="utf-8").lstrip().startswith("<?xml")
        with Image.open(figs / f"{name}.png") as png:  # the same figure, drawn at the DPI
            assert np.abs(np.subtract(png.size, figure_size_px(svg, plots.DPI))).max() < 1, name
            assert len(png.getcolors(maxcolors=1 << 16) or range(1 << 16)) > 20, name
    with Image.open(figs / "animation.gif") as gif:
        assert gif.n_frames == 20  # fitted window (10) + as many frames beyond
    assert not list(run.glob(".figures*")) and not list(run.glob(".tmp-*"))


def test_report_figures_show_the_runs_numbers(neural_run):
    """The figures' texts read back from their SVGs: the final error, every parameter's
    value, every weight, the saturation share and the labels of the panels."""
    from activebonds.identify.search.operators import VARIANTS
    from activebonds.model.names import parameter_rows
    from activebonds.report.predict import neural_weights
    from activebonds.report.runs import history_rms_mm

    result, _, _ = neural_run
    figs = result.run / "figures"
    record = load_run(result.run)
    text = {name: figure_texts(figs / f"{name}.svg") for name in FIGURES}

    best = history_rms_mm(record.history)["best"]
    final = best[np.isfinite(best) & (best > 0)][-1]
    assert f"{final:.3g} mm" in text["convergence"]

    rows = parameter_rows(record.model)
    values = [t.split("  [")[0] for t in text["parameters"] if "  [" in t]
    assert values == [f"{r.value:.4g}" for r in rows] and len(rows) == record.model.layout.n_genes

    w_len, w_rate, _ = neural_weights(record.model)
    weights = np.concatenate([w_len, w_rate], axis=1)  # every bond is neural: every row shown
    shown = Counter(f"{w:.2g}" for w in weights[np.isfinite(weights)])
    assert shown.total() == 3 * 4 and not shown - Counter(text["weights"])  # each one written

    pred, _ = predict_run(record, frames=20)
    assert f"({100 * pred.saturated_share:.0f} % of samples saturated)" in " ".join(
        text["activations"]
    )
    labels = plots.bond_labels(record.model)
    assert {f"neuron {lab}" for lab in labels} <= set(text["activations"])

    assert {"X (mm)", "Y (mm)", "Z (mm)", *pred.names} <= set(text["trajectories"])
    assert len(pred.names) == 3
    assert {v.label for v in VARIANTS} <= set(text["variants"])


def test_report_embeds_the_animation_and_its_player(neural_run):
    text = _html(neural_run[1])
    data = _report_data(text)
    anim = data["animations"][0]
    assert len(anim["recorded"]) == 20 and anim["fit_frames"] == 10
    assert anim["axes"] == ["X", "Z"]  # the horse's sagittal plane
    assert [m["label"] for m in anim["models"]] == ["run"]
    for ident in ('id="play"', 'id="frame"', 'type="range"', "<canvas", 'id="mode"'):
        assert ident in text


def test_report_embeds_every_figure_byte_for_byte(neural_run):
    result, report, _ = neural_run
    text = _html(report)
    for name in FIGURES:
        encoded = base64.b64encode((result.run / "figures" / f"{name}.png").read_bytes()).decode()
        assert f'src="data:image/png;base64,{encoded}"' in text


def test_report_summary_shows_the_fits_numbers(neural_run):
    result, report, _ = neural_run
    text = _html(report)
    assert f"{result.rms_mm:.4g} mm" in text
    assert "neural" in text and "Head" in text and "failed evaluations" in text


def test_report_html_is_self_contained(neural_run):
    text = _html(neural_run[1])
    assert "http://" not in text and "https://" not in text
    assert 'src="http' not in text and 'href="http' not in text
    refs = re.findall(r'(?:src|href)\s*=\s*"([^"]*)"', text)
    assert refs and all(r.startswith(("data:", "#")) for r in refs), refs
    assert "<script src" not in text and 'rel="stylesheet"' not in text
    assert "@import" not in text and "url(" not in text


def test_one_step_predictions_match_the_fit_cost(neural_run):
    result = neural_run[0]
    pred, record = predict_run(result.run)
    assert record.has_best and not pred.extended
    expected = [result.local_rms_mm[n] for n in pred.names]
    np.testing.assert_allclose(pred.one_step_rms_mm, expected, rtol=1e-9)
    longer, _ = predict_run(result.run, frames=20)
    assert longer.n_frames == 20 and longer.fit_frames == 10
    np.testing.assert_allclose(longer.one_step[:10], pred.one_step, rtol=0, atol=1e-15)
    assert 0.0 <= longer.saturated_share <= 1.0
    assert longer.activation.shape == (20, 3)


def test_figures_folder_is_replaced_whole_and_foreign_files_are_guarded(neural_run, tmp_path):
    target = tmp_path / "figures"
    target.mkdir()
    (target / "stale.png").write_bytes(b"old")
    with staged_directory(target) as new:
        (new / "a.png").write_bytes(b"new")
        assert (target / "stale.png").exists()  # untouched until the new folder is complete
    assert sorted(p.name for p in target.iterdir()) == ["a.png"]
    with pytest.raises(RuntimeError), staged_directory(target) as new:
        (new / "b.png").write_bytes(b"half")
        raise RuntimeError("interrupted")
    assert sorted(p.name for p in target.iterdir()) == ["a.png"]
    assert [p.name for p in tmp_path.iterdir()] == ["figures"]  # no leftovers

    run = tmp_path / "copy"
    shutil.copytree(neural_run[0].run, run)
    before = (run / "report.html").read_bytes()
    (run / "figures" / "notes.txt").write_text("mine")
    with pytest.raises(InputError, match="not figures"):
        write_report(run)
    assert (run / "figures" / "notes.txt").read_text() == "mine"
    assert (run / "report.html").read_bytes() == before
    assert not list(run.glob(".figures*"))


def test_a_run_that_failed_at_once_is_still_reported(neural_run, tmp_path):
    run = tmp_path / "failed"
    shutil.copytree(neural_run[0].run, run, ignore=shutil.ignore_patterns("report.html", "figures"))
    (run / "best_model.toml").unlink()
    header = (run / "history.csv").read_text().splitlines()[0]
    (run / "history.csv").write_text(header + "\n")  # as written when every start failed
    record = load_run(run)
    assert not record.has_best and len(record.history["generation"]) == 0
    # the run's bond variant, starting values
    assert record.model.topology.bonds["binary"]["neural"].all()
    pred, _ = predict_run(record, frames=20)
    summary = dict(summary_table(record, pred).rows)
    assert summary["status"] == "completed (no best model)"
    figs = tmp_path / "figs"
    assert plots.convergence([Series("failed", [record.history])], figs / "c")[0].is_file()
    assert plots.variant_success(record.history, figs / "v")[0].is_file()


@pytest.mark.parametrize(
    "setup, message",
    [
        (lambda p: None, "no such run directory"),
        (lambda p: p.mkdir(), "not a run directory"),
        (lambda p: (p.mkdir(), (p / "run.json").write_text("{")), "unreadable run.json"),
    ],
)
def test_invalid_run_directories_are_one_line_errors(tmp_path, setup, message):
    run = tmp_path / "bad"
    setup(run)
    with pytest.raises(InputError, match=message) as err:
        write_report(run)
    assert "\n" not in err.value.line()


def test_report_command(neural_run, tmp_path):
    result, report, cli = neural_run
    assert cli.stdout.strip() == str(report)  # prints the path of the report it wrote
    # and says on stderr what it is doing meanwhile (a spinner in a terminal)
    assert cli.stderr.strip() == "writing the report (predictions, figures, animation) ..."
    runner = CliRunner()
    res = runner.invoke(report_app(), [str(tmp_path / "missing")])
    assert res.exit_code == 2
    lines = [ln for ln in res.output.splitlines() if ln.strip()]
    assert len(lines) == 1 and lines[0].startswith("error:") and "missing" in lines[0]
    res = runner.invoke(report_app(), [str(result.run), "--out", str(tmp_path / "r.txt")])
    assert res.exit_code == 2 and "must end in .html" in res.output


# ----------------------------------------------------------------------------- comparison


def test_comparison_report(neural_run, tmp_path):
    record = load_run(neural_run[0].run)
    pred, _ = predict_run(record, frames=20)
    window = Trajectory(
        positions=pred.recorded,
        mask=np.isfinite(pred.recorded).all(-1),
        markers=pred.markers,
        rate=1 / pred.dt,
    )
    # a second model along the same recording (same topology: its predictions compile once)
    other = record.model.with_genome(0.97 * record.model.layout.initial())
    std = predict(other, window, fit_frames=10)
    h = record.history
    shifted = {k: (v * 1.5 if k.endswith(("cost", "rms_mm")) else v) for k, v in h.items()}
    out = tmp_path / "cmp" / "report.html"
    out.parent.mkdir()
    with staged_directory(out.parent / "figures") as figs:
        conv = plots.convergence(
            [Series("standard", [h, shifted, h]), Series("neural", [shifted, h])],
            figs / "convergence",
        )
        heat = plots.weight_heatmap(record.model, figs / "weights")
        table = Table(
            ["series", "seeds", "best RMS (mm)"], [["standard", 3, 1.5], ["neural", 2, 1.25]]
        )
        sections = [
            Section("Convergence", figures=[Figure(conv[0], "median and IQR")], tables=[table]),
            Section("Best models", animation=payload([("standard", std), ("neural", pred)])),
            Section("Neural weights", figures=[heat[0]]),
        ]
        path = write_comparison_report(out, "Standard vs neural", sections, subtitle="test")
    assert path == out and (out.parent / "figures" / "convergence.svg").is_file()
    text = _html(out)
    anim = _report_data(text)["animations"][0]
    assert [m["label"] for m in anim["models"]] == ["standard", "neural"]
    assert len(anim["recorded"]) == 20
    assert anim["models"][0]["free_run"] != anim["models"][1]["free_run"]
    assert text.count('<img src="data:image/png;base64,') == 2
    assert "Standard vs neural" in text and "https://" not in text
    with pytest.raises(ValueError, match="different recordings"):
        payload([("a", pred), ("b", dataclasses.replace(pred, recorded=pred.recorded + 0.01))])


def test_report_shows_the_fit_beside_its_baselines(neural_run):
    """The zero-force predictor and the momentum floor on the same frames, with their
    numbers recomputed independently here (the fit window is the horse's frames 0-9)."""
    from activebonds.identify.judge.baselines import momentum_floor_rms_mm, zero_force_rms_mm
    from activebonds.identify.stages import baselines

    result, report, _ = neural_run
    pred, record = predict_run(result.run, frames=20)
    rows = {r[0]: r[1:] for r in baselines.table(record.records["baselines"], pred).rows}
    w = record.window
    assert rows["zero force (constant velocity)"][0] == pytest.approx(
        zero_force_rms_mm(w.positions, w.mask, w.dt), rel=1e-12
    )
    assert rows["zero force (constant velocity)"][0] == pytest.approx(5.6205, abs=1e-3)
    floor = momentum_floor_rms_mm(w.positions, w.mask, w.dt, record.model.params.mass)
    assert rows["momentum floor (internal forces)"][0] == pytest.approx(floor, rel=1e-12)
    assert rows["this model"][0] == pytest.approx(result.rms_mm, rel=1e-9)
    assert rows["this model"][0] >= floor  # no internal-force model beats the floor
    # neural terms are not linear: no least-squares optimum claimed for this family
    assert not any(k.startswith("exact least squares") for k in rows)
    text = _html(report)
    assert "zero force (constant velocity)" in text and "momentum floor" in text


@pytest.mark.slow  # integration scale: in pytest -m slow (every landing)
def test_the_report_and_evaluate_give_the_same_free_run_and_the_wall_time_is_the_runs(
    tmp_path,
):
    """A small fit of frames 0:60 of a 120-frame recording (the triangle's bonds 30 % too
    stiff and fixed, so the free run drifts), its report over 120 frames, and ``evaluate`` of its
    best model on 0:60 and on 60:120: the same free-run RMS per particle, to rounding. The
    frames beyond the fit get a free run of their own, as ``evaluate --frames 60:120`` starts
    one (the report continued the fitted window's run there: a different number). The
    report's wall time is the run's over its sessions: the fit's whole call (compilation,
    refinement, stages: not only the search), then a resumed session's added."""
    import time

    from activebonds import runtime
    from activebonds.data import read_trajectory, write_trajectory
    from activebonds.identify import resume
    from activebonds.report.evaluate import evaluate

    write_trajectory(simulate(load_model(TRIANGLE), 120, 60.0), tmp_path / "rec.csv")
    truth = read_trajectory(tmp_path / "rec.csv")
    stiff = re.sub(  # every stiffness fixed 30 % too high: the free run drifts
        r"stiffness = \{ value = ([\d.]+)[^}]*\}",
        lambda m: f"stiffness = {1.3 * float(m.group(1))!r}",
        TRIANGLE.read_text(),
    )
    run = tmp_path / "run"
    # a Ctrl-C in the refinement's third step (the first poll: the driver's, before the stage)
    flag = iter([False] * 3 + [True] * 1000)
    runtime.on_stop_request(lambda: next(flag))
    started = time.time()
    try:
        with pytest.raises(KeyboardInterrupt):
            fit(
                loads_model(stiff),
                tmp_path / "rec.csv",
                out=run,
                frames=(0, 60),
                population=8,
                generations=3,
                cost="restart",
                horizon=(1,),
            )
    finally:
        runtime.on_stop_request(None)
    first = time.time() - started
    first_wall = json.loads((run / "status.json").read_text())["wall_seconds"]
    assert first - 1.0 < first_wall <= first  # the whole call, not the search alone
    started = time.time()
    resume(run)
    second = time.time() - started
    wall = json.loads((run / "status.json").read_text())["wall_seconds"]
    assert first_wall + second - 1.0 < wall <= first_wall + second
    record = load_run(run)
    rows = dict(summary_table(record, predict_run(record)[0]).rows)
    assert rows["wall time (the run's, every session)"] == f"{wall:.4g} s"

    pred, _ = predict_run(record, 120)
    best = load_model(run / "best_model.toml")
    fitted = evaluate(best, truth, frames=(0, 60))
    beyond = evaluate(best, truth, frames=(60, 120))
    assert pred.extended and pred.fit_frames == 60
    np.testing.assert_allclose(
        pred.free_run_rms_mm, [p.free_run_rms_mm for p in fitted.particles], rtol=1e-12
    )
    np.testing.assert_allclose(
        pred.free_run_rms_mm_beyond, [p.free_run_rms_mm for p in beyond.particles], rtol=1e-12
    )
    assert (pred.free_run_rms_mm_beyond > 1.0).all()  # millimetres: a real number to compare
    # and the overall figure of the report's free-run table is evaluate's
    table = html_free_run_rows(record)
    assert table[0][3] == pytest.approx(fitted.model.free_run_rms_mm, rel=1e-12)


def html_free_run_rows(record):
    from activebonds.report.html import free_run_table

    return free_run_table(record).rows


# ----------------------------------------------------------------------------- in a browser


@pytest.fixture(scope="module")
def page(neural_run):
    """The tiny run's report open in headless Chromium (the run this file's tests share)."""
    sync_playwright, executable = browser_or_skip()
    report = neural_run[1]
    with sync_playwright() as p:
        browser = p.chromium.launch(executable_path=executable, args=BROWSER_ARGS)
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
