"""Levenberg-Marquardt refinement (fit --refine lm): restart and multiple-shooting costs, the
bounds, the curriculum, a divergent stage, interruption and resume."""

from __future__ import annotations

import numpy as np
import pytest
from typer.testing import CliRunner

import activebonds
from activebonds.data import Trajectory
from activebonds.identify.costs.shooting import shooting_windows
from activebonds.identify.rundir import RunDir
from activebonds.identify.solvers import refine as refine_mod
from activebonds.identify.solvers import stage as stage_mod
from activebonds.identify.solvers.refine import Bounded
from activebonds.model import load_model, loads_model
from helpers import EXAMPLES, each_case_both_ways

# The triangle of examples/triangle.toml (its file values are the truth), 60 frames at 60 Hz,
# fitted with standard bonds: 9 genes (stiffness, rest length, damping of 3 bond types).
FAST = dict(bonds="standard", generations=3, population=16, seed=0)


@pytest.fixture(scope="module")
def triangle():
    model = load_model(EXAMPLES / "triangle.toml")
    traj = activebonds.simulate(model, 60, 60.0)
    truth = np.array([g.value for g in model.layout.genes])
    return model, traj, truth


def rel_error(model, genome, truth) -> float:
    return float(np.max(np.abs(model.layout.natural(genome) - truth) / np.abs(truth)))


def test_restart_refinement_recovers_the_truth_from_a_poor_es_result(triangle):
    model, traj, truth = triangle
    result = activebonds.fit(model, traj, refine="lm", **FAST)
    assert rel_error(model, result.es_genome, truth) > 0.1  # three generations: far off
    assert rel_error(model, result.genome, truth) < 1e-8
    (stage,) = result.refinement
    assert stage.accepted and stage.cost == "restart" and stage.horizon == 1
    assert stage.end_rms_mm < 1e-9 < stage.start_rms_mm
    # the result's cost is the fit's own (one-step) cost at the refined genome
    assert result.rms_mm == pytest.approx(stage.end_rms_mm, rel=1e-6, abs=1e-12)


def test_shooting_refinement_recovers_the_truth_and_joins_the_windows(triangle):
    model, traj, truth = triangle
    options = dict(refine="lm", cost="shooting", horizon=(10,), init="lsq")
    result = activebonds.fit(model, traj, **options, **FAST)
    assert rel_error(model, result.genome, truth) < 1e-8
    (stage,) = result.refinement
    assert stage.accepted and stage.continuity_mm < 1e-9


def test_shooting_windows_count_every_frame_once():
    pos = np.random.default_rng(0).normal(size=(23, 2, 3))
    mask = np.ones((23, 2), bool)
    mask[7, 1] = False
    for h in (1, 4, 10, 22, 100):
        w = shooting_windows(pos, mask, 0.01, h)
        assert w.n_terms == mask.sum()
        frames = w.starts[:, None] + np.arange(w.horizon + 1)
        counted = frames[w.weight[..., 0] > 0]
        assert sorted(counted.tolist()) == list(range(23))


def test_the_bounded_transform_keeps_every_gene_inside():
    b = Bounded(np.array([0.0, -1.0]), np.array([1.0, 2.0]))
    u = np.linspace(-50, 50, 1001)[:, None] * np.ones(2)
    g = np.asarray(b.to_genome(u))
    assert (g >= b.lower).all() and (g <= b.lower + b.span).all()
    inner = np.array([0.3, 1.5])
    assert np.allclose(b.to_genome(b.from_genome(inner)), inner, atol=1e-12)


def test_an_optimum_beyond_a_bound_ends_on_the_bound(triangle):
    """The damping of bond A-B (truth 0.5) is bounded to [0.01, 0.25]: the refinement stops
    at the upper bound, never beyond, and the stage is accepted."""
    _, traj, _ = triangle
    text = (EXAMPLES / "triangle.toml").read_text()
    old = "damping = { value = 0.5, min = 0.01, max = 10.0 }"
    assert text.count(old) == 1
    capped = loads_model(text.replace(old, "damping = { value = 0.2, min = 0.01, max = 0.25 }"))
    result = activebonds.fit(capped, traj, refine="lm", **FAST)
    g = [gene.name for gene in capped.layout.genes].index("bond[0].damping")
    upper = capped.layout.upper[g]
    assert result.genome[g] <= upper
    assert result.genome[g] == pytest.approx(upper, rel=1e-6)
    assert result.refinement[0].accepted


def test_a_horizon_curriculum_starts_each_stage_from_the_last(triangle):
    model, traj, truth = triangle
    result = activebonds.fit(model, traj, refine="lm", horizon=(1, 5), **FAST)
    first, second = result.refinement
    assert (first.horizon, second.horizon) == (1, 5)
    assert second.start_rms_mm < 1e-8  # it starts at the first stage's (exact) result
    assert rel_error(model, result.genome, truth) < 1e-8


@pytest.mark.slow  # integration scale: in pytest -m slow (every landing)
def test_a_divergent_refinement_keeps_the_es_result_and_resume_works(
    triangle, tmp_path, monkeypatch
):
    model, traj, _ = triangle
    data = tmp_path / "tri.npz"
    activebonds.data.write_trajectory(traj, data)
    model_path = EXAMPLES / "triangle.toml"

    def diverge(residual, y0, max_steps, *_):
        return (
            type(y0)(np.full_like(np.asarray(leaf), np.nan) for leaf in y0)
            if isinstance(y0, tuple)
            else np.full_like(np.asarray(y0), np.nan),
            7,
            "converged",
        )

    monkeypatch.setattr(stage_mod, "solve", diverge)
    run = tmp_path / "run"
    result = activebonds.fit(model_path, data, refine="lm", out=run, **FAST)
    (stage,) = result.refinement
    assert not stage.accepted
    assert stage.message == "the refinement diverged (non-finite cost); kept the previous result"
    np.testing.assert_array_equal(result.genome, result.es_genome)
    best = RunDir(run).best_model()
    np.testing.assert_allclose(
        best.layout.natural(best.layout.initial()),
        model.layout.natural(result.es_genome),
        rtol=1e-12,
    )
    monkeypatch.undo()
    from activebonds.report import write_report

    html = write_report(run).read_text()
    assert "rejected: the refinement diverged (non-finite cost)" in html
    again = activebonds.resume(run)  # the record is complete: nothing is run again
    np.testing.assert_array_equal(again.genome, result.es_genome)
    assert [s.message for s in again.refinement] == [stage.message]


def test_the_cli_says_a_divergent_stage_in_one_line(triangle, tmp_path, monkeypatch):
    _, traj, _ = triangle
    data = tmp_path / "tri.npz"
    activebonds.data.write_trajectory(traj, data)

    def diverge(residual, y0, max_steps, *_):
        return np.full_like(np.asarray(y0), np.nan), 3, "converged"

    monkeypatch.setattr(stage_mod, "solve", diverge)
    from activebonds.cli.main import app

    args = ["fit", str(EXAMPLES / "triangle.toml"), str(data), "--out", str(tmp_path / "r")]
    args += ["--bonds", "standard", "--generations", "3", "--population", "16", "--refine", "lm"]
    res = CliRunner().invoke(app, [*args, "--cost", "restart"], env={"COLUMNS": "300"})
    assert res.exit_code == 0, res.output
    lines = [ln for ln in res.output.splitlines() if ln.startswith("refinement 1/1")]
    assert len(lines) == 1 and lines[0].endswith(
        "the refinement diverged (non-finite cost); kept the previous result"
    )


@pytest.mark.slow  # integration scale: in `pytest -m slow` (every landing)
def test_an_interrupted_refinement_resumes_to_the_same_result(triangle, tmp_path, monkeypatch):
    model, traj, _ = triangle
    data = tmp_path / "tri.npz"
    activebonds.data.write_trajectory(traj, data)
    model_path = EXAMPLES / "triangle.toml"
    options = dict(refine="lm", cost="shooting", horizon=(2, 6), init="lsq", frames=(0, 30))
    options |= FAST
    whole = activebonds.fit(model_path, data, **options)

    calls = []
    original = refine_mod.Refinement.stage

    def interrupt_second(self, horizon, genome, max_steps=refine_mod.MAX_STEPS):
        calls.append(horizon)
        if len(calls) == 2:
            raise KeyboardInterrupt
        return original(self, horizon, genome, max_steps)

    monkeypatch.setattr(refine_mod.Refinement, "stage", interrupt_second)
    run = tmp_path / "run"
    with pytest.raises(KeyboardInterrupt):
        activebonds.fit(model_path, data, out=run, **options)
    assert (
        RunDir(run).status()["status"] == "interrupted"
    )  # Ctrl-C in the refinement: saved, resumable
    assert len(RunDir(run).record("refine")["stages"]) == 1
    monkeypatch.undo()
    resumed = activebonds.resume(run)
    assert [s.horizon for s in resumed.refinement] == [2, 6]
    np.testing.assert_array_equal(resumed.genome, whole.genome)
    assert RunDir(run).status()["status"] == "completed"


@pytest.mark.parametrize(
    *each_case_both_ways(
        "options, message",
        [
            (
                ["--horizon", "1,5", "--refine", "none"],
                "a horizon curriculum (several horizons) is run by the refinement",
            ),
            (
                ["--cost", "shooting", "--refine", "none"],
                "the shooting cost is the refinement's; add --refine lm",
            ),
            (["--horizon", "0"], "horizons must be integers >= 1"),
            (["--horizon", "1,x"], "expected integers separated by commas"),
            (["--refine", "newton"], "--refine"),
        ],
    )
)
def test_bad_refinement_options_are_one_line(tmp_path, triangle, run, options, message):
    data = tmp_path / "tri.npz"
    activebonds.data.write_trajectory(triangle[1], data)
    res = run("fit", EXAMPLES / "triangle.toml", data, "--out", tmp_path / "r", *options)
    assert res.returncode == 2
    assert message in res.stderr and len(res.stderr.strip().splitlines()) == 1
    assert not (tmp_path / "r").exists()


@pytest.mark.slow  # integration scale: in `pytest -m slow` (every landing)
def test_noise_does_not_bias_the_shooting_fit_as_it_biases_the_one_step_fit(triangle):
    """0.5 mm of marker noise on the triangle: the exact one-step optimum's dampings are far
    off (the noisy restart states), multiple shooting's are close."""
    model, traj, truth = triangle
    rng = np.random.default_rng(3)
    pos = traj.positions + rng.normal(0, 0.0005, traj.positions.shape)
    noisy = Trajectory(positions=pos, mask=traj.mask, markers=traj.markers, rate=traj.rate)
    one_step = activebonds.fit(model, noisy, init="lsq", refine="none", **FAST)
    shot = activebonds.fit(
        model, noisy, init="lsq", refine="lm", cost="shooting", horizon=(20,), **FAST
    )
    damping = [i for i, g in enumerate(model.layout.genes) if g.name.endswith("damping")]

    def err(genome):
        return np.abs(model.layout.natural(genome) - truth)[damping] / truth[damping]

    assert np.median(err(shot.genome)) < 0.5 * np.median(err(one_step.genome))


@pytest.mark.slow  # integration scale: in `pytest -m slow` (every landing)
def test_a_shooting_fit_from_the_exact_start_searches_on_the_one_step_cost(triangle):
    """With --init lsq and --cost shooting the search evolves on the one-step Euler cost
    (whatever --substeps the shooting uses), whose optimum the least squares is: the search's
    best is that optimum exactly, its RMS the least squares' own, and the shooting at 4 Verlet
    substeps then recovers the truth, the fit saying which cost each stage used."""
    from activebonds.identify.costs.windows import make_windows
    from activebonds.identify.solvers.lsq import least_squares

    model, _, truth = triangle
    traj = activebonds.simulate(model, 60, 60.0, substeps=4, integrator="verlet")
    settings = dict(init="lsq", cost="shooting", horizon=(10,), refine="lm", substeps=4)
    result = activebonds.fit(model, traj, integrator="verlet", **settings, **FAST)
    exact = least_squares(
        result.identification.model, make_windows(traj.positions, traj.mask, traj.dt, 1)
    )
    np.testing.assert_allclose(result.es_genome, exact.genome, rtol=1e-12, atol=1e-12)
    baselines = result.records["baselines"]
    assert result.history["best_rms_mm"][0] == pytest.approx(
        baselines["least_squares_rms_mm"], rel=1e-9
    )
    assert rel_error(model, result.genome, truth) < 1e-6
    line = result.records["refine"]["costs"]
    assert "one-step cost (1 Euler substep" in line and "multiple shooting (4 verlet" in line


def test_a_model_whose_predictions_cannot_be_computed_is_not_said_to_lose():
    """Dampings no two Verlet substeps at 60 Hz can carry (h c / m of 4): the start velocity's
    fixed point diverges, and the check against constant velocity says so instead of printing
    "nan vs X mm"."""
    from activebonds.identify.problem import identification
    from activebonds.identify.settings import FitSettings
    from activebonds.simulation import simulate

    text = (EXAMPLES / "triangle.toml").read_text().replace("max = 10.0", "max = 1000.0")
    model = loads_model(text, "triangle")
    recording = simulate(load_model(EXAMPLES / "triangle.toml"), 60, 60.0)
    settings = FitSettings(cost="shooting", substeps=2, integrator="verlet", horizon=(10,))
    ident = identification(model, recording, settings)
    layout = ident.model.layout
    genome = np.array(layout.initial(), np.float64)
    damping = [i for i, g in enumerate(layout.genes) if g.name.endswith("damping")]
    genome[damping] = np.where(layout.log[damping], np.log(500.0), 500.0)
    why = refine_mod.Refinement(ident, settings).versus_constant_velocity(genome, (1,))
    assert why == (
        "its 1-frame predictions cannot be computed at these parameters (a start velocity or a "
        "prediction diverged: more --substeps may hold them)"
    )


def test_a_shooting_line_says_the_warm_start_and_why_the_markers_rms_rose():
    from activebonds.identify.stages.refinement import STAGE

    stage = {
        "cost": "shooting", "horizon": 10, "steps": 150, "warm_steps": 50, "seconds": 12.0,
        "start_rms_mm": 21.36, "end_rms_mm": 56.7, "continuity_mm": 0.19,
        "start_objective": 0.5, "end_objective": 0.02, "message": "converged",
    }  # fmt: skip
    (line,) = STAGE.lines({"stages": [stage]})
    assert "21.36 -> 56.7 mm in 150 steps (50 of them its warm start" in line
    assert "fell from 0.5 to 0.02 m^2" in line
    fell = {**stage, "end_rms_mm": 1.0, "warm_steps": 0}  # the markers' RMS fell: not said
    (line,) = STAGE.lines({"stages": [fell]})
    assert "in 150 steps, 12 s" in line and "m^2" not in line
    old = {k: v for k, v in stage.items() if "objective" not in k and k != "warm_steps"}
    (line,) = STAGE.lines({"stages": [old]})  # a record written before: as it was
    assert "in 150 steps, 12 s, windows join within 0.19 mm; converged" in line


@pytest.mark.slow  # a shooting stage of its own (45 s)
def test_a_stage_says_its_steps_and_the_lowest_cost_is_its_end(triangle):
    from activebonds.identify.problem import identification
    from activebonds.identify.settings import FitSettings

    model, traj, truth = triangle
    settings = FitSettings(horizon=(10,), cost="shooting", refine="lm", bonds="standard")
    ident = identification(model, traj, settings)
    refinement = refine_mod.Refinement(ident, settings)
    said = []
    refinement.on_step = lambda *a: said.append(a)
    layout = ident.model.layout
    start = layout.initial()  # the truth, moved 5 % off: both parts take steps
    start[layout.log] += np.log(1.05)
    start[~layout.log] *= 1.05
    stage = refinement.stage(10, start)
    assert stage.accepted
    parts = [a[0] for a in said]
    assert parts[0] == "warm start" and parts[-1] == "shooting"
    assert parts == sorted(parts, key=("warm start", "shooting").index)  # warm start first
    for part, most in (("warm start", refine_mod.WARM_STEPS), ("shooting", refine_mod.MAX_STEPS)):
        steps = [a[1] for a in said if a[0] == part]
        assert steps == list(range(1, len(steps) + 1))  # every evaluation, counted from 1
        assert {a[2] for a in said if a[0] == part} == {most}
    assert len(said) == stage.steps  # the warm start's and the shooting's evaluations
    shot = min(a[3] for a in said if a[0] == "shooting")
    assert shot == pytest.approx(stage.end_objective, rel=1e-9)  # the cost |r|^2, m^2


@pytest.mark.slow  # three fits (12 s)
def test_a_stop_asked_during_a_stage_ends_the_fit_before_the_next_and_resume_completes(
    triangle, tmp_path
):
    import json

    from activebonds import runtime
    from activebonds.identify import resume

    model, traj, truth = triangle
    run = tmp_path / "run"
    # the user's Ctrl-C arrives once the refinement has ended (its record written): the
    # stages after it (baselines, uncertainty) cannot stop midway, so the fit stops before them
    runtime.on_stop_request(lambda: (run / "refine.json").exists())
    try:
        with pytest.raises(KeyboardInterrupt):
            activebonds.fit(model, traj, out=run, refine="lm", **FAST)
    finally:
        runtime.on_stop_request(None)
    assert json.loads((run / "status.json").read_text())["status"] == "interrupted"
    assert (run / "refine.json").exists() and not (run / "baselines.json").exists()
    resumed = resume(run)
    assert json.loads((run / "status.json").read_text())["status"] == "completed"
    assert (run / "baselines.json").exists()
    whole = activebonds.fit(model, traj, out=tmp_path / "whole", refine="lm", **FAST)
    np.testing.assert_allclose(resumed.genome, whole.genome, rtol=0, atol=0)
    assert rel_error(model, resumed.genome, truth) < 1e-8
