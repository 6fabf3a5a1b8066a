"""The strategy protocol: a second optimiser (pure random search) runs through the same loop,
``fit``, the run directory and ``resume`` as the paper's ES, and keeps every guarantee.

* random search does what it says: its best cost is the minimum over every genome it drew
  (recomputed here from the same random numbers, outside the loop);
* through ``fit`` with a run directory: the history holds the strategy's own columns and the
  cost's display columns, the report reads them;
* killed with SIGKILL after a checkpoint and resumed, it ends byte-identical (history and best
  model) to an uninterrupted run;
* the checkpoint stores the strategy's state pytree by its paths;
* the variant table drives the ES's mutation: masks checked against the table, per variant.
"""

from __future__ import annotations

import json
import os
import signal
import subprocess
import time
from functools import partial

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from activebonds.identify import fit
from activebonds.identify.costs.windows import Display
from activebonds.identify.search import evolve, operators, strategies
from activebonds.identify.search.random_search import RandomSearch
from activebonds.identify.search.strategy import Problem
from helpers import bowl_problem
from reliability_runner import (
    EXAMPLES,
    FIT,
    checkpoint_arrays,
    complete_checkpoints,
    env,
    fit_argv,
    result_bytes,
    runner_argv,
    workspace,
)

pytestmark = pytest.mark.timeout(300)


def _bowl(n_genes: int = 3) -> Problem:
    return bowl_problem(n_genes)


def test_random_search_keeps_the_best_of_every_genome_it_drew():
    problem = _bowl()
    strategy = RandomSearch(problem, population=20, dtype=jnp.float64)
    loop = evolve.Evolution(
        strategy, problem, jnp.float64, total=30, requested=7, display=Display(1)
    )
    init_key, gen_key = evolve.keys(5)
    state = loop.start(init_key)
    rows = []
    for latest, row in loop.run(gen_key, state, 30):
        state = latest
        rows.append(row)
    assert len(rows) == 5  # chunks of 7 generations (the last one partly masked)
    best = np.concatenate([r["best_cost"] for r in rows])
    assert np.all(np.diff(best) <= 0) and best.shape == (30,)
    # every genome drawn, recomputed outside the loop from the same keys
    lo, hi = problem.lower, problem.upper
    drawn = [lo + (hi - lo) * np.asarray(jax.random.uniform(init_key, (20, 3), jnp.float64))]
    for g in range(30):
        u = jax.random.uniform(jax.random.fold_in(gen_key, g), (20, 3), jnp.float32)
        drawn.append(lo + (hi - lo) * np.asarray(u, np.float64))
    target = np.linspace(0.2, 0.8, 3)
    costs = [((d - target) ** 2).sum(axis=1) for d in drawn]
    expected = np.minimum.accumulate([c.min() for c in costs])[1:]
    np.testing.assert_allclose(best, expected, rtol=1e-12)
    genome, cost, _ = strategy.best(state.strategy)
    assert float(cost) == pytest.approx(expected[-1], rel=1e-12)
    assert float(((np.asarray(genome) - target) ** 2).sum()) == pytest.approx(float(cost))


@pytest.mark.slow  # integration scale: in `pytest -m slow` (every landing)
def test_random_search_through_fit_writes_its_own_history(tmp_path):
    data = tmp_path / "triangle.csv"
    from activebonds.data import write_trajectory
    from activebonds.model import load_model
    from activebonds.report import write_report
    from activebonds.simulation import simulate

    write_trajectory(simulate(load_model(EXAMPLES / "triangle.toml"), 30, 60.0), data)
    run = tmp_path / "run"
    res = fit(
        EXAMPLES / "triangle.toml", data, out=run, optimizer="random", population=30,
        generations=40, seed=2, refine="none",
    )  # fmt: skip
    meta = json.loads((run / "run.json").read_text())
    assert meta["strategy"] == "random"
    header = (run / "history.csv").read_text().splitlines()[0].split(",")
    assert header == meta["history"]["columns"]
    assert header[:8] == [
        "generation", "best_cost", "median_cost", "worst_cost",
        "best_rms_mm", "median_rms_mm", "worst_rms_mm", "failed",
    ]  # fmt: skip
    assert not any(h.startswith("trials_") for h in header)
    # the stored display is the cost's own: RMS mm over the run's prediction terms
    n_terms = res.identification.windows.n_terms
    assert meta["history"]["display"] == Display(n_terms).record()
    np.testing.assert_allclose(
        res.history["median_rms_mm"],
        np.sqrt(res.history["median_cost"] / n_terms) * 1000.0,
        rtol=1e-12,
    )
    # the ES on the same problem and budget does better than blind search
    es_res = fit(
        EXAMPLES / "triangle.toml", data, population=30, generations=40, seed=2, refine="none"
    )
    assert es_res.rms_mm < res.rms_mm
    report = write_report(run)
    assert report.is_file() and "random search (random)" in report.read_text(encoding="utf-8")


@pytest.mark.slow  # integration scale: in `pytest -m slow` (every landing)
def test_a_killed_random_search_resumes_byte_identical(tmp_path, tmp_path_factory):
    ws = workspace(tmp_path_factory)
    extra = ["--optimizer", "random"]
    ref = tmp_path / "ref"
    proc = subprocess.run(
        fit_argv(ws, "triangle", ref) + extra,
        env=env(ws["cache"]), capture_output=True, text=True, timeout=300, check=False,
    )  # fmt: skip
    assert proc.returncode == 0, proc.stderr
    arrays = checkpoint_arrays(ref / "checkpoints" / f"gen-{FIT['generations']:09d}.npz")
    # the state pytree by its paths: the loop's counters and the strategy's fields
    names = {k for k in arrays if k.startswith("state_")}
    assert names == {
        "state_generation", "state_failed_total", "state_genes", "state_cost", "state_local",
    }  # fmt: skip

    run = tmp_path / "killed"
    log = tmp_path / "log.txt"
    with open(log, "w") as fh:
        p = subprocess.Popen(
            fit_argv(ws, "triangle", run, throttle=0.05) + extra,
            stdout=fh, stderr=subprocess.STDOUT, env=env(ws["cache"]),
        )  # fmt: skip
        deadline = time.monotonic() + 120
        while time.monotonic() < deadline and p.poll() is None:
            done = [int(x.split()[1]) for x in log.read_text().split("\n") if x.startswith("gen")]
            if done and done[-1] >= 2 * FIT["checkpoint_every"]:
                break
            time.sleep(0.02)
        os.kill(p.pid, signal.SIGKILL)
        p.wait()
    assert p.returncode == -signal.SIGKILL, log.read_text()
    saved = complete_checkpoints(run)
    assert saved and max(saved) < FIT["generations"], saved
    proc = subprocess.run(
        runner_argv("resume", run), env=env(ws["cache"]), capture_output=True, text=True,
        timeout=300, check=False,
    )  # fmt: skip
    assert proc.returncode == 0, proc.stderr
    assert result_bytes(run) == result_bytes(ref)


@pytest.mark.parametrize("index", range(operators.N_VARIANTS))
def test_the_variant_table_drives_the_mutation(index):
    """Each variant moves exactly the genes its table row names, adapts mutabilities exactly
    when its row says so, and takes a Cauchy step exactly when its row says so."""
    v = operators.VARIANTS[index]
    n, g = 6, 5
    key = jax.random.PRNGKey(index)
    nz = operators.draw(key, n, 0, g, (2, 1), jnp.float64)
    genes = jnp.full((n, g), 0.5)
    sigma = jnp.full((n, g), 0.01)
    gene_group = jnp.array([0, 0, 1, 1, 1], jnp.int32)
    group_prob = jnp.tile(jnp.array([0.0, 1.0]), (n, 1))  # variant "group": always group 1
    bounds = operators.Bounds(jnp.zeros(g), jnp.ones(g))
    variant = jnp.full((n,), index)
    new, new_sigma = operators.mutate(
        nz, genes, sigma, variant, group_prob, gene_group, bounds, 1e-9
    )
    moved = np.asarray(new != genes)
    expected = {
        "all": np.ones((n, g), bool),
        "group": np.broadcast_to(np.asarray(gene_group) == 1, (n, g)),
        "one": None,
    }[v.genes]
    if v.genes == "one":
        assert np.all(moved.sum(axis=1) == 1)
    else:
        np.testing.assert_array_equal(moved, expected)
    assert bool(np.any(new_sigma != sigma)) == v.adapts
    step = (np.asarray(new) - 0.5)[moved] / np.asarray(new_sigma)[moved]
    rows = np.nonzero(moved)[0]
    expected_step = (
        np.asarray(nz.cauchy)[rows] if v.step == "cauchy" else np.asarray(nz.step)[moved]
    )
    inside = np.abs(np.asarray(new)[moved] - 0.5) < 0.5 - 1e-12  # not reflected
    np.testing.assert_allclose(step[inside], expected_step[inside], rtol=1e-9)


def test_every_optimizer_name_builds_a_strategy_with_its_columns():
    problem = _bowl()
    from activebonds.identify.settings import FitSettings

    for name in strategies.names():
        s = strategies.make(name, problem, FitSettings(population=8), jnp.float64)
        assert s.name == name
        assert set(s.cost_columns) <= {c.name for c in s.columns}
        state = jax.jit(partial(evolve.start, s, problem, jnp.float64))(jax.random.PRNGKey(0))
        assert np.isfinite(float(s.best(state.strategy)[1]))


def _as_format_1(run) -> None:
    """Rewrite a run as activebonds 0.2 wrote it (format 1): no strategy, history columns or
    display in run.json, no optimizer setting, variants numbered, only the best cost in mm."""
    names = {f"{f}_{v.name}": f"{f}_v{i + 1}" for i, v in enumerate(operators.VARIANTS)
             for f in ("trials", "successes")}  # fmt: skip
    dropped = ("median_rms_mm", "worst_rms_mm")
    meta = json.loads((run / "run.json").read_text())
    for key in ("strategy", "history"):
        meta.pop(key)
    meta["format"] = 1
    meta["settings"].pop("optimizer")
    for key in ("cost", "refine", "smooth"):  # settings added after format 1
        meta["settings"].pop(key, None)
    meta["settings"]["horizon"] = meta["settings"]["horizon"][0]  # an int in format 1
    (run / "run.json").write_text(json.dumps(meta, indent=2, sort_keys=True) + "\n")
    status = json.loads((run / "status.json").read_text())
    status["job"].pop("optimizer")
    (run / "status.json").write_text(json.dumps(status) + "\n")
    lines = (run / "history.csv").read_text().splitlines()
    header = lines[0].split(",")
    keep = [i for i, h in enumerate(header) if h not in dropped]
    rows = [",".join(names.get(header[i], header[i]) for i in keep)]
    rows += [",".join(line.split(",")[i] for i in keep) for line in lines[1:]]
    (run / "history.csv").write_text("\n".join(rows) + "\n")
    for path in (run / "checkpoints").glob("gen-*.npz"):
        arrays = checkpoint_arrays(path)
        old = {}
        for k, v in arrays.items():
            if k.removeprefix("history_") in dropped:
                continue
            old["history_" + names[k[8:]] if k[8:] in names else k] = v
        np.savez(path, **old)


@pytest.mark.slow  # integration scale: in `pytest -m slow` (every landing)
def test_a_format_1_run_is_reported_and_resumed_as_if_new(tmp_path):
    """Runs written by activebonds 0.2 (format 1) are read through the migration: the report
    shows the same curves, and a resume continues them to the same result as one fit."""
    from activebonds.data import write_trajectory
    from activebonds.identify import resume
    from activebonds.model import load_model
    from activebonds.report.runs import history_rms_mm, load_run
    from activebonds.simulation import simulate

    data = tmp_path / "triangle.csv"
    write_trajectory(simulate(load_model(EXAMPLES / "triangle.toml"), 30, 60.0), data)
    opts = {"population": 20, "seed": 4, "chunk": 25, "checkpoint_every": 25, "refine": "none"}
    model = EXAMPLES / "triangle.toml"
    whole = fit(model, data, out=tmp_path / "whole", generations=100, **opts)
    run = tmp_path / "old"
    fit(model, data, out=run, generations=50, **opts)
    before = load_run(run).history
    _as_format_1(run)
    record = load_run(run)
    assert record.meta["format"] == 2 and record.meta["strategy"] == "es"
    for key, values in history_rms_mm(record.history).items():
        np.testing.assert_allclose(values, history_rms_mm(before)[key], rtol=1e-12)
    assert list(record.history) == list(before)
    resumed = resume(run, generations=100)
    assert resumed.status == "completed"
    assert json.loads((run / "run.json").read_text())["format"] == 2
    for key, values in whole.history.items():
        np.testing.assert_array_equal(resumed.history[key], values, err_msg=key)
    assert (run / "best_model.toml").read_bytes() == (
        tmp_path / "whole" / "best_model.toml"
    ).read_bytes()
