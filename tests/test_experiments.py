"""The reproduce commands at a tiny scale, and the momentum floor of the fit error."""

from __future__ import annotations

import csv
import json
from collections import Counter

import numpy as np
import pytest
from PIL import Image
from typer.testing import CliRunner

from activebonds.cli.main import app
from activebonds.data import Trajectory
from activebonds.experiments.paper import EXPERIMENTS
from activebonds.identify.judge.baselines import momentum_floor_rms_mm
from activebonds.model import load_model
from activebonds.report import plots
from activebonds.report.predict import neural_weights
from activebonds.simulation import simulate
from helpers import EXAMPLES, figure_size_px, figure_texts


def test_floor_is_zero_on_data_made_by_internal_forces():
    truth = load_model(EXAMPLES / "triangle.toml")  # unequal masses, internal forces only
    data = simulate(truth, n_frames=40, rate=60.0)
    assert momentum_floor_rms_mm(data.positions, data.mask, data.dt, truth.params.mass) < 1e-9


def test_floor_of_a_uniformly_accelerated_system_is_its_acceleration_step():
    # Three particles falling with a = 9.81 m/s^2 (no internal force can explain it): every
    # one-step error of an internal-force model is at least dt^2 a on average.
    rate, a = 50.0, 9.81
    t = np.arange(20) / rate
    x = np.zeros((20, 3, 3))
    x[:, :, 2] = -0.5 * a * t[:, None] ** 2 + np.array([0.0, 1.0, 2.0])
    traj = Trajectory(positions=x, mask=np.ones((20, 3), bool), markers=("a", "b", "c"), rate=rate)
    expected = a / rate**2 * 1000.0
    floor = momentum_floor_rms_mm(traj.positions, traj.mask, traj.dt, [1.0, 1.0, 1.0])
    assert floor == pytest.approx(expected, rel=1e-9)
    # Unequal masses: the constraint sum m_p e_p = M g is met best by e_p proportional to m_p,
    # leaving sum e_p^2 = M^2 g^2 / sum m_p^2 (Lagrange), less than P g^2.
    m = np.array([1.0, 2.0, 5.0])
    unequal = expected * np.sqrt(m.sum() ** 2 / (3 * np.sum(m**2)))
    linear = momentum_floor_rms_mm(traj.positions, traj.mask, traj.dt, m, angular=False)
    assert linear == pytest.approx(unequal, rel=1e-9)
    # the particles are on one vertical line, so the torque constraint adds nothing here
    floor = momentum_floor_rms_mm(traj.positions, traj.mask, traj.dt, m)
    assert floor == pytest.approx(unequal, rel=1e-9)


@pytest.mark.slow  # integration scale: in `pytest -m slow` (every landing)
@pytest.mark.parametrize("name", ["synthetic", "horse"])
def test_reproduce_tiny_writes_both_series_curves_and_figures(name, tmp_path):
    out = tmp_path / "out"
    args = ["reproduce", name, "--scale", "tiny", "--seeds", "2", "--out", str(out)]
    res = CliRunner().invoke(app, args, env={"COLUMNS": "200", "NO_COLOR": "1"})
    assert res.exit_code == 0, (res.output, res.exception)
    config = EXPERIMENTS[name].scales["tiny"][0]
    folder = out / name / config.name
    with open(folder / "curves.csv") as fh:
        rows = list(csv.DictReader(fh))
    assert {r["series"] for r in rows} == {"standard", "neural"}
    assert len(rows) == 2 * config.generations
    finals = {}
    for series in ("standard", "neural"):
        best = [float(r["best_rms_mm_median"]) for r in rows if r["series"] == series]
        assert np.all(np.diff(best) <= 1e-12)  # elitism, seed by seed and so in the median
        assert np.isfinite(best[-1])
        finals[series] = best[-1]
    summary = json.loads((out / name / "summary.json").read_text())
    result = summary["configs"][config.name]["series"]
    assert np.isfinite(result["neural"]["fit_rms_mm_median"])
    assert result["standard"]["seeds"] == [0, 1]
    assert 0.0 <= result["neural"]["saturated_share_median"] <= 1.0
    # the figures, read back: each series' final median error is written on the convergence
    # plot, every weight of the best neural model on the heatmap, every frame in the GIF
    figs = folder / "figures"
    for fig in ("convergence.png", "convergence.svg", "neural_weights.png", "animation.gif"):
        assert (figs / fig).stat().st_size > 1000
    for stem in ("convergence", "neural_weights"):
        with Image.open(figs / f"{stem}.png") as png:
            size = figure_size_px(figs / f"{stem}.svg", plots.DPI)
            assert np.abs(np.subtract(png.size, size)).max() < 1, stem
    conv = figure_texts(figs / "convergence.svg")
    for series, final in finals.items():
        assert f"{final:.3g} mm" in conv, (series, final, conv)
        assert any(t.startswith(f"{series}: best (median of 2") for t in conv), conv
    w_len, w_rate, _ = neural_weights(load_model(folder / "best_neural.toml"))
    weights = np.concatenate([w_len, w_rate], axis=1)
    shown = Counter(f"{w:.2g}" for w in weights[np.isfinite(weights)])
    assert shown.total() > 0 and not shown - Counter(figure_texts(figs / "neural_weights.svg"))
    test_frames = result["standard"]["test_frames"]
    with Image.open(figs / "animation.gif") as gif:
        assert gif.n_frames == test_frames[1]  # the recording up to the end of the test frames
    html = (out / "report.html").read_text()
    assert "standard" in html and "neural" in html and "http://" not in html
    assert "zero force" in html
    base = summary["baselines"]
    if name == "horse":  # the audit's figures: floor 4.107, optimum 4.2026, zero force 6.51
        assert base["momentum_floor_mm"] == pytest.approx(4.1066, abs=1e-3)
        assert base["lsq_standard_fit_rms_mm"] == pytest.approx(4.2026, abs=1e-3)
        assert base["zero_force_test_rms_mm"] == pytest.approx(6.5096, abs=1e-3)
        assert base["test_frames"] == [10, 53]
    else:  # data made by a standard model: both reach zero
        assert base["momentum_floor_mm"] < 1e-9
        assert base["lsq_standard_fit_rms_mm"] < 1e-9
