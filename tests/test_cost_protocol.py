"""Costs and integrators as objects (identify/costs, physics/integrators): no module outside
them branches on their names, and a cost defined here, in the test file, runs through fit,
resume, the uncertainty stage and report without editing the package, recovering the truth."""

from __future__ import annotations

import ast
import json
from pathlib import Path

import jax.numpy as jnp
import numpy as np
import pytest
from jax.flatten_util import ravel_pytree

from activebonds.identify import costs, fit, resume
from activebonds.identify.costs.base import ResidualFunction
from activebonds.identify.costs.restart_cost import RestartCost
from activebonds.identify.costs.windows import join_windows, make_residuals, make_windows, rms_mm
from activebonds.identify.prepare import prepare
from activebonds.identify.settings import FitSettings
from activebonds.identify.solvers import stage as lm
from activebonds.model import load_model
from activebonds.physics import integrators
from activebonds.physics.integrators import Integrator
from activebonds.simulation import simulate
from helpers import EXAMPLES, TRIANGLE
from test_import_graph import SRC, module_files

PACKAGE = SRC / "activebonds"
# the costs and the integrators themselves: where their names belong
OWNERS = ("identify/costs/", "physics/integrators.py", "physics/integrate.py")


def named_branches(path: Path, names: set[str]) -> list[tuple[int, str]]:
    """(line, name) of every comparison in ``path`` against one of ``names`` (``x == "a"``,
    ``x != "a"``, ``x in ("a", "b")``, ``x not in {...}``) and every ``match`` case on one."""
    found = []
    for node in ast.walk(ast.parse(path.read_text(), str(path))):
        sides = []
        if isinstance(node, ast.Compare):
            sides = [node.left, *node.comparators]
        elif isinstance(node, ast.match_case) and isinstance(node.pattern, ast.MatchValue):
            sides = [node.pattern.value]
        for side in sides:
            items = side.elts if isinstance(side, ast.Tuple | ast.List | ast.Set) else [side]
            for item in items:
                if isinstance(item, ast.Constant) and item.value in names:
                    found.append((node.lineno if hasattr(node, "lineno") else 0, item.value))
    return found


def outside_owners() -> list[Path]:
    return [
        p
        for p in module_files().values()
        if not any(p.relative_to(PACKAGE).as_posix().startswith(o) for o in OWNERS)
    ]


def test_the_branch_check_sees_a_comparison_and_a_match_on_a_name(tmp_path):
    path = tmp_path / "m.py"
    path.write_text(
        'def f(s, m):\n    """restart"""\n    if s.cost == "restart":\n        return 1\n'
        '    if m in ("euler", "rk4"):\n        return 2\n    match s:\n'
        '        case "verlet":\n            return 3\n    return "shooting"\n'
    )
    found = named_branches(path, {"restart", "shooting", "euler", "verlet"})
    assert sorted(name for _, name in found) == ["euler", "restart", "verlet"]


@pytest.mark.parametrize("path", outside_owners(), ids=lambda p: p.relative_to(PACKAGE).as_posix())
def test_no_module_outside_the_costs_and_integrators_branches_on_their_names(path):
    names = set(costs.names()) | set(integrators.names())
    assert {"restart", "shooting", "euler", "verlet"} <= names
    found = named_branches(path, names)
    assert not found, f"{path.relative_to(PACKAGE)} branches on a cost or integrator: {found}"


def test_every_module_but_the_owners_is_checked():
    checked = {p.relative_to(PACKAGE).as_posix() for p in outside_owners()}
    assert {"identify/solvers/refine.py", "identify/judge/uncertainty.py"} <= checked
    assert {"auto/candidates/shot.py", "cli/main.py", "simulation.py"} <= checked
    assert {"identify/stages/refinement.py", "identify/settings.py"} <= checked
    assert not any(c.startswith("identify/costs/") for c in checked)


# ----------------------------------------------------------------------------- integrators


def test_the_integrator_value_knows_its_exact_backward_step_and_its_start_lag():
    """One Euler substep starts at the backward difference itself; Verlet at one substep
    starts half a kick on; a constant acceleration puts Euler's N substeps (N+1)/(2N) behind."""
    assert Integrator("euler", 1).exact_backward and not Integrator("euler", 2).exact_backward
    assert not Integrator("verlet", 1).exact_backward and Integrator("verlet", 1).half_kick_start
    assert Integrator("euler", 3).start_lag() == pytest.approx(4 / 6)
    assert Integrator("verlet", 3).start_lag() == 0.5
    with pytest.raises(ValueError, match="unknown integrator 'rk4'; choose one of euler, verlet"):
        integrators.scheme("rk4")
    with pytest.raises(ValueError, match="unknown integrator 'rk4'"):
        FitSettings(integrator="rk4")


# ----------------------------------------------------------------------------- a toy cost


class HorizonWeighted(RestartCost):
    """The restart cost with the prediction j frames ahead weighted 1 / j: a cost defined
    outside the package, its stage composed of the refinement's shared services."""

    name = "horizon-weighted"

    def _weighted(self, residuals, horizon: int):
        w = jnp.asarray(1.0 / np.arange(1, horizon + 1))[None, :, None, None]
        return lambda genome: residuals(genome) * w

    def stage(self, refinement, horizon, genome, max_steps, part="one-step"):
        r = refinement
        windows, residuals = r.restart_residuals(horizon)
        weighted = self._weighted(residuals, horizon)
        u0 = jnp.asarray(r.bounded.from_genome(genome))
        start = lm.sum_squares(weighted(r.to_genome(u0)))
        u, steps, message = lm.solve(
            lambda u: weighted(r.to_genome(u)), u0, max_steps, r.bounded.interior
        )
        result = np.asarray(r.to_genome(u), np.float64)
        end = lm.sum_squares(weighted(jnp.asarray(result)))
        rms = tuple(float(rms_mm(c, windows.n_terms)) for c in (start, end))
        stage = r.judge(horizon, genome, result, (start, end), rms, steps, message)
        stage.cost = self.name
        return stage

    def residual_function(self, ident, settings, horizon, states) -> ResidualFunction:
        model, data = ident.model, ident.all_data
        log = jnp.asarray(model.layout.log)
        windows = join_windows([make_windows(d.positions, d.mask, d.dt, horizon) for d in data])
        weighted = self._weighted(make_residuals(model, windows), horizon)

        def flat(theta):
            return ravel_pytree(weighted(jnp.where(log, jnp.log(theta), theta)))[0]

        observed = int(np.sum(windows.weight)) * model.dimension
        return ResidualFunction(flat, np.zeros(0), 0, observed, 0)

    def describe(self, settings) -> str:
        return "the refinement on the horizon-weighted restart cost"

    def interval_warning(self, horizon, rejected):
        return None


@pytest.fixture(scope="module")
def triangle_recording(tmp_path_factory):
    model = load_model(TRIANGLE)
    path = tmp_path_factory.mktemp("data") / "tri.npz"
    from activebonds.data import write_trajectory

    write_trajectory(simulate(model, 40, 60.0), path)
    return model, path


def test_a_cost_from_outside_the_package_runs_through_fit_resume_uncertainty_and_report(
    triangle_recording, tmp_path
):
    """Registered from here, the horizon-weighted cost is the refinement's: its stage is
    recorded under its name and recovers the triangle's parameters (noise-free, so the
    truth is its optimum at every weighting); resume runs it again; the uncertainty stage
    forms its report on this cost's residuals; the report renders its stage."""
    model, data = triangle_recording
    truth = np.asarray(model.layout.natural(model.layout.initial()))
    run = tmp_path / "run"
    options = dict(bonds="standard", population=16, generations=3, seed=0, horizon=(3,))
    with costs.registered(HorizonWeighted()):
        assert "horizon-weighted" in costs.names()
        result = fit(EXAMPLES / "triangle.toml", data, out=run, cost="horizon-weighted", **options)
        (stage,) = result.refinement
        assert stage.cost == "horizon-weighted" and stage.accepted, stage.message
        assert stage.end_rms_mm < 1e-6 < stage.start_rms_mm
        found = result.model.layout.natural(result.genome)
        np.testing.assert_allclose(found, truth, rtol=1e-6)

        record = json.loads((run / "uncertainty.json").read_text())
        assert record["cost"] == "horizon-weighted" and record["horizon"] == 3
        assert record["sigma_mm"] < 1e-6  # the weighted residuals vanish at the optimum

        again = resume(run, generations=5)  # extended: the refinement runs again
        assert [s.cost for s in again.refinement] == ["horizon-weighted"]
        np.testing.assert_allclose(again.model.layout.natural(again.genome), truth, rtol=1e-6)

        from activebonds.report import write_report

        write_report(run)
        html = (run / "report.html").read_text()
        assert "horizon-weighted" in html
    assert "horizon-weighted" not in costs.names()  # registered in the with block only
    with pytest.raises(ValueError, match="unknown cost 'horizon-weighted'"):
        FitSettings(cost="horizon-weighted")


def test_auto_is_chosen_by_the_library_from_python(triangle_recording):
    """``cost="auto"`` in Python as ``--cost auto`` on the command line: a window of 3
    particles' 6 coordinates and 9 genes is affordable, so the fit shoots over 10 frames."""
    _, data = triangle_recording
    result = fit(
        EXAMPLES / "triangle.toml", data, bonds="standard", population=8, generations=2,
        cost="auto", max_steps=2,
    )  # fmt: skip
    assert result.settings.cost == "shooting" and result.settings.horizon == (10,)
    assert [s.cost for s in result.refinement] in (["shooting"], ["restart"])
    # a horizon asked for is kept, in settings given whole as in options
    asked = FitSettings(bonds="standard", population=8, generations=2, cost="auto", horizon=5)
    given = prepare(EXAMPLES / "triangle.toml", data, asked, horizon_given=True)
    assert given.settings.horizon == (5,) and given.cost_note.startswith("cost: shooting (auto")
