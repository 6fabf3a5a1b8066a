"""The exact references a fit is judged against: bounded least squares for the linear
families, the momentum floor of internal-force models, and the zero-force baseline.

Each is checked against an independent computation: the truth of simulated data, a general
constrained solver (SciPy's SLSQP on the force vector of one frame), a one-parameter scan, or
the package's own cost and predictions.
"""

from __future__ import annotations

import jax
import numpy as np
import pytest
from scipy.optimize import minimize

from activebonds.data import read_trajectory
from activebonds.errors import InputError
from activebonds.identify import fit
from activebonds.identify.costs.windows import make_cost, make_windows
from activebonds.identify.judge.baselines import (
    model_floor_rms_mm,
    momentum_floor_rms_mm,
    zero_force_rms_mm,
)
from activebonds.identify.judge.predictions import one_step
from activebonds.identify.solvers.lsq import equation_error_fit, least_squares, linear_problem
from activebonds.model import as_standard, load_model, loads_model
from activebonds.simulation import simulate
from helpers import EXAMPLES, HORSE_LIMB, HORSE_TROT, ROOT, both_ways_fresh_in_slow, cli

TETRA = ROOT / "tests" / "models" / "tetra.toml"


@pytest.fixture(scope="module")
def tetra():
    jax.config.update("jax_enable_x64", True)
    model = load_model(TETRA)
    data = simulate(model, 150, 50.0)
    return model, data, make_windows(data.positions, data.mask, data.dt, 1)


@pytest.fixture(scope="module")
def horse():
    jax.config.update("jax_enable_x64", True)
    model = as_standard(load_model(HORSE_LIMB))
    data = read_trajectory(HORSE_TROT).select(["Head", "Withers", "HFL"]).window(0, 10)
    return model, data, make_windows(data.positions, data.mask, data.dt, 1)


def truth_values(model):
    return model.layout.natural(model.layout.initial())


def test_least_squares_recovers_the_truth_exactly(tetra):
    model, _, windows = tetra
    result = least_squares(model, windows)
    assert result.exact
    got = model.layout.natural(result.genome)
    np.testing.assert_allclose(got, truth_values(model), rtol=1e-9)
    assert result.rms_mm < 1e-9


def test_least_squares_cost_is_the_es_cost(horse):
    """The optimum's cost, recomputed by the ES's own cost function, is the same number: the
    two formulations agree. On the paper's horse window it is the audit's 4.2026 mm."""
    model, _, windows = horse
    result = least_squares(model, windows)
    cost = jax.jit(make_cost(model, windows))
    es_cost = float(cost(result.genome)[0])
    assert es_cost == pytest.approx(result.cost, rel=1e-9)
    assert result.rms_mm == pytest.approx(4.2026, abs=5e-5)


def test_least_squares_is_a_minimum_within_the_bounds(horse):
    """No feasible random perturbation of the optimum does better (the ES's search space)."""
    model, _, windows = horse
    result = least_squares(model, windows)
    cost = jax.jit(jax.vmap(lambda g: make_cost(model, windows)(g)[0]))
    lo, hi = model.layout.lower, model.layout.upper
    rng = np.random.default_rng(0)
    for scale in (1e-6, 1e-4, 1e-2):
        trial = result.genome + scale * (hi - lo) * rng.standard_normal((400, len(lo)))
        trial = np.clip(trial, lo, hi)
        assert float(np.min(cost(trial))) >= result.cost * (1 - 1e-12)


def test_active_product_constraint_matches_a_scan(tetra):
    """With the true rest length of bond 0 outside its bounds, the constraint k l0 >= k lo is
    active: the constrained optimum equals the best of a fine scan with l0 pinned at lo."""
    model, data, windows = tetra
    text = TETRA.read_text().replace(
        "rest_length = { value = 0.5, min = 0.25, max = 0.75 }",
        "rest_length = { value = 0.6, min = 0.56, max = 0.75 }",
        1,
    )
    boxed = loads_model(text)
    result = least_squares(boxed, windows)
    l0_gene = [g.name for g in boxed.layout.genes].index("bond[0].rest_length")
    assert boxed.layout.natural(result.genome)[l0_gene] == pytest.approx(0.56, rel=1e-6)
    pinned = loads_model(
        TETRA.read_text().replace(
            "rest_length = { value = 0.5, min = 0.25, max = 0.75 }", "rest_length = 0.56", 1
        )
    )
    reference = least_squares(pinned, windows)
    assert result.cost == pytest.approx(reference.cost, rel=1e-6)
    # and a slightly larger pinned l0 is worse: the bound is where the optimum sits
    worse = loads_model(
        TETRA.read_text().replace(
            "rest_length = { value = 0.5, min = 0.25, max = 0.75 }", "rest_length = 0.57", 1
        )
    )
    assert least_squares(worse, windows).cost > reference.cost


def test_equation_error_recovers_masses_with_a_known_total(tetra):
    model, _, windows = tetra
    text = TETRA.read_text()
    for m in ("1.0", "1.5", "2.0", "0.8"):
        text = text.replace(f"mass = {m}\n", "mass = { value = 1.0, min = 0.1, max = 10.0 }\n")
    free = loads_model("total_mass = 5.3\n" + text)  # every mass free: the scale is the total
    assert (np.asarray(free.layout.index.mass) >= 0).all()
    result = equation_error_fit(free, windows, total_mass=5.3)
    np.testing.assert_allclose(result.masses, [1.0, 1.5, 2.0, 0.8], rtol=1e-8)
    names = [g.name for g in free.layout.genes]
    truth = dict(zip([g.name for g in model.layout.genes], truth_values(model), strict=True))
    for g, v in result.values.items():
        assert v == pytest.approx(truth[names[g]], rel=1e-8), names[g]
    assert result.rms_force < 1e-9
    assert equation_error_fit(free, windows).masses == pytest.approx(result.masses)  # the file's
    with pytest.raises(InputError, match="total_mass"):  # every mass free, no scale: refused
        loads_model(text)


def _floor_by_slsqp(resid, x, mass):
    """One frame's floor by a general solver: min |r - d|^2 with sum m d = 0 and
    sum m x cross d = 0 (d = dt^2 a, one 3-vector per particle)."""
    n = len(mass)

    def cons(d):
        d = d.reshape(n, 3)
        return np.concatenate([mass @ d, np.sum(mass[:, None] * np.cross(x, d), axis=0)])

    res = minimize(
        lambda d: np.sum((resid.ravel() - d) ** 2),
        np.zeros(3 * n),
        jac=lambda d: 2 * (d - resid.ravel()),
        constraints=[{"type": "eq", "fun": cons}],
        method="SLSQP",
        options={"ftol": 1e-20, "maxiter": 500},
    )
    return res.fun


def test_momentum_floor_matches_a_general_solver_and_the_audit(horse):
    model, data, windows = horse
    floor = momentum_floor_rms_mm(data.positions, data.mask, data.dt, model.params.mass)
    assert floor == pytest.approx(4.107, abs=5e-4)  # the audit's exact floor
    linear_only = momentum_floor_rms_mm(
        data.positions, data.mask, data.dt, model.params.mass, angular=False
    )
    assert linear_only == pytest.approx(3.0946, abs=5e-4)  # the old, linear-only bound
    resid = windows.target[:, 0] - (windows.x0 + windows.dt * windows.v0)
    mass = np.asarray(model.params.mass, float) * np.array([1.0, 1.0, 1.0])
    total = sum(_floor_by_slsqp(resid[s], windows.x0[s], mass) for s in range(len(resid)))
    assert floor == pytest.approx(np.sqrt(total / windows.n_terms) * 1000, rel=1e-6)
    # the exact optimum of the standard family sits above the floor, as it must
    assert least_squares(model, windows).rms_mm > floor


def test_momentum_floor_is_invariant_to_the_mass_scale(horse):
    """The constraints are homogeneous in the masses: scaling them all changes nothing, and
    at very unequal masses the torque constraints are kept (a general solver agrees). They
    were once dropped there (an absolute rank threshold on torques about the origin)."""
    model, data, windows = horse
    mass = np.asarray(model.params.mass, float)
    base = momentum_floor_rms_mm(data.positions, data.mask, data.dt, mass)
    for scale in (1e-90, 1e-20, 1e20, 1e90):
        got = momentum_floor_rms_mm(data.positions, data.mask, data.dt, mass * scale)
        assert got == pytest.approx(base, rel=1e-9)
    skewed = np.array([1.0, 1e-9, 1e-9])  # one heavy particle
    floor = momentum_floor_rms_mm(data.positions, data.mask, data.dt, skewed)
    linear_only = momentum_floor_rms_mm(data.positions, data.mask, data.dt, skewed, angular=False)
    resid = windows.target[:, 0] - (windows.x0 + windows.dt * windows.v0)
    # the general solver at the same ratios, in a scale it handles (masses 1, 1e-3, 1e-3):
    # at small masses the constraints converge to their limit, which both must follow
    limit = np.array([1.0, 1e-6, 1e-6])
    total = sum(_floor_by_slsqp(resid[s], windows.x0[s], limit) for s in range(len(resid)))
    assert momentum_floor_rms_mm(data.positions, data.mask, data.dt, limit) == pytest.approx(
        np.sqrt(total / windows.n_terms) * 1000, rel=1e-4
    )
    assert floor > linear_only * (1 + 1e-3)  # the torque rows still bind


def test_floor_is_zero_for_internal_forces_and_the_field_for_a_missing_one(tetra):
    model, data, windows = tetra
    assert model_floor_rms_mm(model, data.positions, data.mask, data.dt) < 1e-9
    # the system (equal masses) falling under gravity the model does not know: the centre of
    # mass accelerates by g, which no internal force can produce, and with equal masses every
    # particle's error is dt^2 g, all of it in the constrained direction: floor dt^2 |g|
    text = TETRA.read_text()
    for m in ("1.5", "2.0", "0.8"):
        text = text.replace(f"mass = {m}\n", "mass = 1.0\n")
    falling = loads_model("gravity = [0.0, 0.0, -9.81]\n" + text)
    fell = simulate(falling, 40, 50.0)
    floor = momentum_floor_rms_mm(fell.positions, fell.mask, fell.dt, np.ones(4))
    assert floor == pytest.approx(9.81 * fell.dt**2 * 1000, rel=1e-9)
    # told about the field, the floor is zero again
    assert model_floor_rms_mm(falling, fell.positions, fell.mask, fell.dt) < 1e-9
    # unequal masses: internal forces can share the error unequally; the linear part alone
    # gives |sum m e|^2 / sum m^2 per frame, and the torque constraint can only add to it
    fell = simulate(loads_model("gravity = [0.0, 0.0, -9.81]\n" + TETRA.read_text()), 40, 50.0)
    mass = np.asarray(model.params.mass, float)
    linear = mass.sum() * 9.81 * fell.dt**2 / np.sqrt(np.sum(mass**2) * 4) * 1000
    assert momentum_floor_rms_mm(
        fell.positions, fell.mask, fell.dt, mass, angular=False
    ) == pytest.approx(linear, rel=1e-9)
    assert momentum_floor_rms_mm(fell.positions, fell.mask, fell.dt, mass) >= linear * (1 - 1e-12)


def test_zero_force_baseline_is_the_force_free_prediction(horse):
    model, data, _ = horse
    off = loads_model(
        'name = "free"\ndimension = 3\n'
        + "".join(f'[[particle]]\nname = "{n}"\n' for n in ("Head", "Withers", "HFL"))
    )
    pred = one_step(off, data.positions, data.dt)
    err = np.sum((pred[2:] - data.positions[2:]) ** 2, axis=-1)
    by_model = np.sqrt(err.mean()) * 1000
    assert zero_force_rms_mm(data.positions, data.mask, data.dt) == pytest.approx(
        by_model, rel=1e-12
    )
    assert by_model == pytest.approx(5.6205, abs=5e-4)


def test_init_lsq_puts_the_optimum_in_the_first_population(tetra):
    model, data, _ = tetra
    search = {"population": 20, "generations": 1, "seed": 0, "refine": "none"}  # the start alone
    uniform = fit(model, data, **search)
    lsq = fit(model, data, **search, init="lsq")
    assert lsq.rms_mm < 1e-9 < uniform.rms_mm
    assert linear_problem(model, make_windows(data.positions, data.mask, data.dt, 1)).pairs


@pytest.mark.parametrize(*both_ways_fresh_in_slow())
def test_init_lsq_refuses_a_non_linear_model_in_one_line(tmp_path, run):
    text = TETRA.read_text().replace("mass = 1.0\n", "mass = { value = 1.0, min = 0.5, max = 2 }\n")
    path = tmp_path / "m.toml"
    path.write_text(text)
    data = tmp_path / "d.csv"
    from activebonds.data import write_trajectory

    write_trajectory(simulate(load_model(TETRA), 30, 50.0), data)
    proc = run("fit", path, data, "--init", "lsq", "--out", tmp_path / "run")
    assert proc.returncode == 2, proc.stderr
    assert "--init lsq" in proc.stderr and "mass" in proc.stderr
    assert len(proc.stderr.strip().splitlines()) == 1
    assert not (tmp_path / "run").exists()


def test_baselines_command_prints_the_references(horse):
    import json

    model, data, windows = horse
    proc = cli(
        "baselines", HORSE_LIMB, HORSE_TROT, "--markers", "Head,Withers,HFL",
        "--frames", "0:10", "--bonds", "standard", "--json",
    )  # fmt: skip
    assert proc.returncode == 0, proc.stderr
    got = json.loads(proc.stdout)
    assert got["frames"] == [0, 10]
    assert got["zero_force_rms_mm"] == pytest.approx(
        zero_force_rms_mm(data.positions, data.mask, data.dt)
    )
    assert got["momentum_floor_mm"] == pytest.approx(4.1066, abs=1e-3)
    assert got["least_squares_rms_mm"] == pytest.approx(least_squares(model, windows).rms_mm)


@pytest.mark.parametrize(*both_ways_fresh_in_slow())
def test_baselines_command_refuses_a_missing_recording_in_one_line(run):
    bad = run("baselines", HORSE_LIMB, "missing.csv")
    assert bad.returncode == 2 and len(bad.stderr.strip().splitlines()) == 1


def test_fixed_stiffness_and_damping_are_known_offsets(tetra):
    """Bonds with fixed stiffness (rest length free) and fixed damping: the fixed terms are a
    known offset, the rest is still recovered exactly."""
    model, _, windows = tetra
    text = TETRA.read_text()
    text = text.replace("stiffness = { value = 40.0, min = 1.0, max = 1000.0 }", "stiffness = 40.0")
    text = text.replace("damping = { value = 0.8, min = 0.01, max = 10.0 }", "damping = 0.8")
    partly = loads_model(text)
    result = least_squares(partly, windows)
    truth = dict(zip([g.name for g in model.layout.genes], truth_values(model), strict=True))
    got = partly.layout.natural(result.genome)
    for gene, value in zip(partly.layout.genes, got, strict=True):
        assert value == pytest.approx(truth[gene.name], rel=1e-9), gene.name
    assert result.exact and result.rms_mm < 1e-9


def test_a_type_mixing_free_and_fixed_stiffness_is_refused(tetra):
    """Two bonds of one type share their rest length; with the stiffness free in one and fixed
    in the other the rest length enters bilinearly: refused, not solved wrongly."""
    model, _, windows = tetra
    text = TETRA.read_text().replace(
        'particles = ["A", "B"]\n', 'particles = ["A", "B"]\ntype = "t"\n', 1
    )
    text = text.replace(
        'particles = ["A", "C"]\nstiffness = { value = 25.0, min = 1.0, max = 1000.0 }',
        'particles = ["A", "C"]\ntype = "t"\nstiffness = 40.0',
    )
    mixed = loads_model(text)
    with pytest.raises(InputError, match="not linear"):
        least_squares(mixed, windows)


def test_no_floor_is_claimed_for_free_masses(tetra):
    model, data, _ = tetra
    text = TETRA.read_text().replace(
        "mass = 1.5\n", "mass = { value = 1.0, min = 0.1, max = 10 }\n"
    )
    assert model_floor_rms_mm(loads_model(text), data.positions, data.mask, data.dt) is None


@pytest.mark.parametrize(
    "path",
    [TETRA, HORSE_LIMB, EXAMPLES / "horse_trot_drive.toml", EXAMPLES / "horse_trot_ground.toml"],
    ids=lambda p: p.stem,
)
def test_a_switched_off_linear_kind_exerts_no_force(path):
    """The contract the least squares relies on to skip computing known forces: once its
    linear terms are switched off, a kind with a linear part (binary bonds, neural or not,
    driven or not; unary springs with fixed or moving anchors) exerts no force at any state
    or time, whatever its fixed parameters."""
    from activebonds import bonds
    from activebonds.identify.solvers.lsq import _switched_off

    model = load_model(path)
    try:
        off = _switched_off(model)
    except InputError:  # free genes outside the linear families: checked on the rest
        off = None
    topo = model.topology
    rng = np.random.default_rng(0)
    linear = [k for k in topo.active() if bonds.get(k).linear is not None]
    assert linear
    for name in linear:
        kind = bonds.get(name)
        values = {f: np.array(a, np.float64) for f, a in model.layout.base.bonds[name].items()}
        if off is None:  # switch this kind off on its own
            values = kind.linear.switch_off(
                values, model.layout.index.bonds[name], topo.bonds[name], model.layout.genes
            )
        else:
            values = off.bonds[name]
        for _ in range(5):
            x = rng.normal(size=(topo.n_particles, model.dimension))
            v = rng.normal(size=x.shape)
            f = kind.forces(values, topo.bonds[name], x, v, float(rng.uniform(0, 10)))
            np.testing.assert_array_equal(np.asarray(f), 0.0, err_msg=f"{path.stem}: {name}")
