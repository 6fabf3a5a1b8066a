"""One model fitted on several recordings at once (fit MODEL A B ...): costs add up, each
recording keeps its own restarts, times and shooting windows, and the run keeps every copy."""

from __future__ import annotations

import jax
import numpy as np
import pytest

import activebonds
from activebonds.data import Trajectory, write_trajectory
from activebonds.errors import InputError
from activebonds.identify.problem import identification
from activebonds.identify.rundir import RunDir
from activebonds.identify.settings import FitSettings
from activebonds.model import load_model, loads_model
from helpers import EXAMPLES, cli

FAST = dict(bonds="standard", generations=3, population=16, seed=0)


@pytest.fixture(scope="module")
def trials():
    """The triangle's truth started from two different states: two 'trials' of one subject."""
    model = load_model(EXAMPLES / "triangle.toml")
    text = (EXAMPLES / "triangle.toml").read_text()
    kicked = loads_model(text.replace("velocity = [0.0, 0.3, 0.1]", "velocity = [0.2, -0.4, 0.0]"))
    a = activebonds.simulate(model, 40, 60.0)
    b = activebonds.simulate(kicked, 30, 60.0)
    truth = np.array([g.value for g in model.layout.genes])
    return model, a, b, truth


def test_the_cost_of_two_recordings_is_the_sum_of_their_costs(trials):
    model, a, b, _ = trials
    settings = FitSettings(**FAST)
    genome = model.layout.initial() * 0.9
    both, one, two = (  # each compiled once (as the fit runs it), not op by op
        jax.jit(identification(model, data, settings).problem.evaluate)(genome)
        for data in ([a, b], a, b)
    )
    assert float(both[0]) == pytest.approx(float(one[0]) + float(two[0]), rel=1e-12)
    np.testing.assert_allclose(both[1], one[1] + two[1], rtol=1e-12)


@pytest.mark.parametrize("cost", ["restart", "shooting"])
def test_two_recordings_recover_the_truth(trials, cost):
    model, a, b, truth = trials
    result = activebonds.fit(
        model, [a, b], init="lsq", refine="lm", cost=cost, horizon=(8,), **FAST
    )
    nat = model.layout.natural(result.genome)
    assert np.max(np.abs(nat - truth) / truth) < 1e-7
    (stage,) = result.refinement
    assert stage.accepted and stage.end_rms_mm < 1e-8


@pytest.mark.slow  # integration scale: in `pytest -m slow` (every landing)
def test_two_recordings_are_not_joined_by_shooting_continuity(trials):
    """Glued end to end as one recording, the two trials jump; fitted as two they do not."""
    model, a, b, truth = trials
    glued = Trajectory(
        positions=np.concatenate([a.positions, b.positions]),
        mask=np.concatenate([a.mask, b.mask]),
        markers=a.markers,
        rate=a.rate,
    )
    options = dict(init="lsq", refine="lm", cost="shooting", horizon=(8,), **FAST)
    apart = activebonds.fit(model, [a, b], **options)
    joined = activebonds.fit(model, glued, **options)
    assert apart.refinement[0].end_rms_mm < 1e-8
    assert joined.refinement[0].end_rms_mm > 1e-3  # the jump between the trials cannot be fitted


def test_recordings_at_different_rates_are_refused(trials):
    model, a, _, _ = trials
    faster = activebonds.simulate(model, 40, 120.0)
    with pytest.raises(InputError, match="one fit needs one frame rate"):
        identification(model, [a, faster], FitSettings(**FAST))


@pytest.mark.slow  # integration scale: in `pytest -m slow` (every landing)
def test_the_run_keeps_every_recording_and_resume_checks_them(trials, tmp_path):
    _, a, b, _ = trials
    pa, pb = tmp_path / "a.csv", tmp_path / "b.csv"
    write_trajectory(a, pa)
    write_trajectory(b, pb)
    run = tmp_path / "run"
    res = cli(
        "fit", EXAMPLES / "triangle.toml", pa, pb, "--out", run, "--bonds", "standard",
        "--generations", "5", "--population", "16",
    )  # fmt: skip
    assert res.returncode == 0, res.stderr
    assert "fitted on 2 recordings at once" in res.stdout
    windows = RunDir(run).windows()
    assert [w.n_frames for w in windows] == [40, 30]
    meta = RunDir(run).meta()
    assert set(meta["inputs"]) == {"model", "data", "data-2"}
    again = activebonds.resume(run)
    assert len(again.identification.all_data) == 2
    write_trajectory(a, pb)  # the second recording changes
    res = cli("resume", run)
    assert res.returncode == 2 and "the data-2 file" in res.stderr and "changed" in res.stderr
