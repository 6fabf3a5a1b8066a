"""``activebonds fill``: which gaps are filled or left, the baselines (linear, cubic spline,
Gløersen & Federolf's PCA) exact where they should be, the model's fill of a simulated
recording (exact without noise, within the noise with it), the hard cases as one line, and
the filled files read back."""

from __future__ import annotations

import csv
import json

import numpy as np
import pytest

from activebonds.data import Trajectory, read_trajectory, write_trajectory
from activebonds.data.fill import (
    apply_fill,
    baseline_uncertainty,
    fill_baseline,
    plan_fill,
    record_csv,
)
from activebonds.errors import InputError
from activebonds.model import load_model
from activebonds.simulation import simulate
from helpers import TRIANGLE, cli_in_process


def _traj(positions, missing=(), markers=None, rate=60.0):
    """A trajectory of positions [F, M, D] with ``missing`` (marker, start, stop) removed."""
    p = np.array(positions, dtype=np.float64)
    mask = np.ones(p.shape[:2], bool)
    for m, a, b in missing:
        mask[a:b, m] = False
    p[~mask] = np.nan
    names = markers or tuple("ABCDEFGH"[: p.shape[1]])
    return Trajectory(p, mask, names, rate)


def _truth(n_frames=120):
    return simulate(load_model(TRIANGLE), n_frames, 60.0)


# ----------------------------------------------------------------------------- the plan


def test_plan_fills_inner_gaps_and_leaves_edges_long_ones_and_outside():
    t = _traj(
        np.zeros((100, 3, 3)),
        missing=[(0, 0, 5), (0, 20, 30), (1, 40, 80), (2, 95, 100), (2, 10, 12)],
    )
    plan = plan_fill(t, ("A", "B", "C"), (0, None), max_gap=20)
    got = {(g.marker, g.start, g.stop): g.reason for g in plan.gaps}
    assert got == {
        ("A", 0, 5): "at the start (filling it would be extrapolation)",
        ("C", 10, 12): None,
        ("A", 20, 30): None,
        ("B", 40, 80): "longer than --max-gap 20",
        ("C", 95, 100): "at the end (filling it would be extrapolation)",
    }
    windowed = plan_fill(t, ("A", "C"), (15, 90))
    got = {(g.marker, g.start): g.reason for g in windowed.gaps}
    assert got == {
        ("A", 0): "outside --frames",
        ("C", 10): "outside --frames",
        ("A", 20): None,
        ("C", 95): "outside --frames",
    }
    assert [(g.start, g.stop) for g in windowed.local()] == [(5, 15)]


def test_plan_refuses_absent_and_never_present_markers_naming_them():
    t = _traj(np.zeros((50, 3, 3)), missing=[(1, 0, 50)])
    with pytest.raises(InputError, match="marker\\(s\\) X, Y are not in the recording"):
        plan_fill(t, ("A", "X", "Y"))
    with pytest.raises(InputError, match="marker\\(s\\) B never present in frames 0:50"):
        plan_fill(t, ("A", "B"))


# ----------------------------------------------------------------------------- baselines


def test_linear_and_spline_are_exact_on_lines_and_cubics():
    f = np.arange(60.0)
    line = np.stack([0.01 * f, -0.02 * f + 1.0, np.full_like(f, 0.5)], -1)
    cubic = np.stack([1e-5 * f**3 - 1e-3 * f**2, 1e-4 * f**2, 0.01 * f], -1)
    t = _traj(np.stack([line, cubic], 1), missing=[(0, 10, 20), (1, 15, 45)])
    plan = plan_fill(t, ("A", "B"))
    lin = fill_baseline("linear", plan.positions, plan.mask, plan.local())
    spl = fill_baseline("spline", plan.positions, plan.mask, plan.local())
    assert np.max(np.abs(lin[10:20, 0] - line[10:20])) < 1e-12
    assert np.max(np.abs(spl[15:45, 1] - cubic[15:45])) < 1e-12
    # the self-test's uncertainty: exact fills, zero error
    sigma = baseline_uncertainty("linear", plan.positions, plan.mask, plan.local()[:1])
    assert sigma[0].shape == (10,) and np.max(sigma[0]) < 1e-12


def _low_rank_motion() -> np.ndarray:
    """Six markers [200, 6, 3] moving as a body that translates (any way) and bends in two
    modes."""
    rng = np.random.default_rng(3)
    f = np.arange(200.0)
    modes = rng.normal(size=(2, 6, 3)) * 0.05
    base = rng.normal(size=(6, 3)) * 0.3
    weights = np.stack([np.sin(f / 9.0), np.cos(f / 13.0)], -1)
    drift = np.stack([0.01 * f, np.sin(f / 30.0), 0.002 * f**1.5], -1)
    return base + np.einsum("fk,kmd->fmd", weights, modes) + drift[:, None, :]


def test_pca_reconstructs_a_marker_from_a_low_dimensional_motion():
    """Six markers moving as a body that translates (any way) and bends in two modes: the
    missing marker is the combination of the modes the present ones show (to rounding)."""
    x = _low_rank_motion()
    t = _traj(x, missing=[(2, 50, 110)])
    plan = plan_fill(t, tuple("ABCDEF"))
    pca = fill_baseline("pca", plan.positions, plan.mask, plan.local())
    spl = fill_baseline("spline", plan.positions, plan.mask, plan.local())
    assert np.max(np.abs(pca[50:110, 2] - x[50:110, 2])) < 1e-9
    assert np.max(np.abs(spl[50:110, 2] - x[50:110, 2])) > 1e-3  # a spline cannot know it


def test_pca_refuses_a_window_without_complete_frames():
    t = _traj(np.zeros((20, 2, 3)), missing=[(0, 1, 10), (1, 9, 19)])
    plan = plan_fill(t, ("A", "B"))
    with pytest.raises(InputError, match="--method pca: needs frames where every chosen"):
        fill_baseline("pca", plan.positions, plan.mask, plan.local())


def test_apply_fill_writes_the_gaps_and_lists_every_sample():
    t = _traj(np.ones((30, 2, 3)), missing=[(0, 10, 13), (1, 0, 2)])
    plan = plan_fill(t, ("A", "B"))
    values = plan.positions.copy()
    values[10:13, 0] = 2.0
    filled, records = apply_fill(plan, values, [np.full(3, 1e-3)], "linear")
    assert filled.mask[10:13, 0].all() and not filled.mask[0:2, 1].any()
    assert np.all(filled.positions[10:13, 0] == 2.0)
    rows = list(csv.DictReader(record_csv(records).decode().splitlines()))
    assert [(r["frame"], r["marker"], r["status"]) for r in rows] == [
        ("0", "B", "left"),
        ("1", "B", "left"),
        ("10", "A", "filled"),
        ("11", "A", "filled"),
        ("12", "A", "filled"),
    ]
    assert rows[2]["uncertainty_mm"] == "1" and rows[2]["gap"] == "10:13"


# ----------------------------------------------------------------------------- the model


@pytest.fixture(scope="module")
def triangle():
    """examples/triangle.toml as one object for the true model's fills of this file: the fill
    keeps its compiled programs per model object, so they are traced once, not per test."""
    return load_model(TRIANGLE)


def test_model_fills_a_30_frame_gap_of_its_own_recording_exactly(triangle):
    from activebonds.identify.gaps.fill import model_fill

    model = triangle
    truth = _truth()
    t = _traj(truth.positions, missing=[(1, 40, 70)], markers=model.markers)
    found = model_fill(model, plan_fill(t, model.markers))
    err = np.linalg.norm(found.values[40:70, 1] - truth.positions[40:70, 1], axis=-1)
    assert err.max() < 1e-6
    assert found.uncertainty[0].shape == (30,) and found.uncertainty[0].max() < 1e-6
    assert np.array_equal(found.values[t.mask], t.positions[t.mask])  # the record kept


def test_model_fill_with_half_millimetre_noise_is_within_the_noise(triangle):
    from activebonds.identify.gaps.fill import model_fill

    model = triangle
    truth = _truth()
    noise = np.random.default_rng(0).normal(0.0, 5e-4, truth.positions.shape)
    t = _traj(truth.positions + noise, missing=[(1, 40, 70)], markers=model.markers)
    found = model_fill(model, plan_fill(t, model.markers))
    err = np.linalg.norm(found.values[40:70, 1] - truth.positions[40:70, 1], axis=-1)
    assert np.sqrt(np.mean(err**2)) < 5e-4  # measured 0.09 mm
    # the spline does not get there
    plan = plan_fill(t, model.markers)
    spl = fill_baseline("spline", plan.positions, plan.mask, plan.local())
    assert np.linalg.norm(spl[40:70, 1] - truth.positions[40:70, 1], axis=-1).max() > 2e-3
    # the estimated uncertainty is of the error's order (measured 0.16 mm mean)
    assert 2e-5 < found.uncertainty[0].mean() < 2e-3
    # denoise: every sample the model's, closer to the truth than the record
    smooth = model_fill(model, plan_fill(t, model.markers), denoise=True)
    seen = t.mask
    before = np.sqrt(np.mean(np.square(t.positions[seen] - truth.positions[seen])))
    after = np.sqrt(np.mean(np.square(smooth.values[seen] - truth.positions[seen])))
    assert after < 0.5 * before


def test_the_pca_prior_does_not_pull_the_true_model_off_its_fill(triangle):
    """The true triangle, 0.5 mm noise, a 30-frame gap: the PCA fill of three markers is far
    off (over 50 mm), its cross-validated error says so, and as a prior it weighs almost
    nothing against the true model's fit: the fused fill stays within the noise of the truth
    and of the pure fill (measured 0.47 and 0.39 mm off the truth; the prior's weight 0.0065)."""
    from activebonds.identify.gaps.fill import model_fill

    model = triangle
    truth = _truth()
    noise = np.random.default_rng(0).normal(0.0, 5e-4, truth.positions.shape)
    t = _traj(truth.positions + noise, missing=[(1, 40, 70)], markers=model.markers)
    plan = plan_fill(t, model.markers)
    fused = model_fill(model, plan, prior="pca")
    pca = fill_baseline("pca", plan.positions, plan.mask, plan.local())

    def rms(values):
        err = values[40:70, 1] - truth.positions[40:70, 1]
        return float(np.sqrt(np.mean(np.sum(err**2, axis=-1))))

    assert rms(pca) > 0.05
    (segment,) = fused.segments
    assert 0.0 < segment.prior_weight < 0.05
    assert rms(fused.values) < 5e-4
    assert rms(fused.values - fused.pure + truth.positions) < 5e-4  # fused vs pure
    assert "the PCA fill weighed in as a prior on 1 stretch(es)" in fused.note()
    # without noise the true model's fill stays exact (measured 5e-12 m), and the note does
    # not blame the model for the prior's steady pull on its defects
    exact = _traj(truth.positions, missing=[(1, 40, 70)], markers=model.markers)
    clean = model_fill(model, plan_fill(exact, model.markers), prior="pca")
    assert np.abs(clean.values[40:70, 1] - truth.positions[40:70, 1]).max() < 1e-6
    assert "correlated" not in clean.note()


def test_the_pca_prior_carries_a_wrong_model_where_the_markers_are_correlated():
    """Six markers moving as one body in two modes (the PCA test's motion): PCA reconstructs
    a missing marker exactly, a spring body of every pair (untrained: stiffness 70, rest
    lengths the mean distances) fills a 40-frame gap far off. Its cross-validated error near
    zero, the PCA fill weighs as a recorded sample: the fused fill is within 1 mm of the
    truth, the pure fill far off (measured 0.04 and 264 mm)."""
    from activebonds.identify.gaps.fill import model_fill
    from activebonds.model import loads_model

    x = _low_rank_motion()
    names = tuple("ABCDEF")
    lines = ['name = "six"', "dimension = 3"]
    lines += [f'[[particle]]\nname = "{m}"\nmass = 1.0' for m in names]
    for i in range(6):
        for j in range(i + 1, 6):
            rest = float(np.mean(np.linalg.norm(x[:, i] - x[:, j], axis=-1)))
            lines.append(
                f'[[bond]]\nkind = "binary"\nparticles = ["{names[i]}", "{names[j]}"]\n'
                f"stiffness = 70.0\nrest_length = {rest!r}\ndamping = 0.7"
            )
    model = loads_model("\n".join(lines) + "\n", "<six>")
    t = _traj(x, missing=[(2, 80, 120)], markers=names)
    fused = model_fill(model, plan_fill(t, names), prior="pca")

    def rms(values):
        err = values[80:120, 2] - x[80:120, 2]
        return float(np.sqrt(np.mean(np.sum(err**2, axis=-1))))

    assert rms(fused.pure) > 0.1
    assert rms(fused.values) < 1e-3
    assert fused.segments[0].prior_weight == 1.0


def test_the_lapack_step_solves_the_block_tridiagonal_system_as_the_jax_one():
    from activebonds.identify.gaps.states import block_tridiagonal_lapack
    from activebonds.identify.solvers.shooting_normal import block_tridiagonal_solve

    rng = np.random.default_rng(1)
    k, n = 7, 5
    a = rng.normal(size=(k * n, k * n))
    full = a @ a.T + k * n * np.eye(k * n)
    band = np.zeros_like(full)
    for i in range(k):  # keep the diagonal and first off-diagonal blocks
        for j in (i - 1, i, i + 1):
            if 0 <= j < k:
                band[i * n : (i + 1) * n, j * n : (j + 1) * n] = full[
                    i * n : (i + 1) * n, j * n : (j + 1) * n
                ]
    diag = np.stack([band[i * n : (i + 1) * n, i * n : (i + 1) * n] for i in range(k)])
    off = np.stack([band[i * n : (i + 1) * n, (i + 1) * n : (i + 2) * n] for i in range(k - 1)])
    rhs = rng.normal(size=(k, n))
    got = block_tridiagonal_lapack(diag, off, rhs)
    assert np.max(np.abs(band @ got.ravel() - rhs.ravel())) < 1e-10
    ref = np.asarray(block_tridiagonal_solve(diag, off, rhs[..., None]))[..., 0]
    assert np.max(np.abs(got - ref)) < 1e-10


def test_the_step_prior_adds_its_exact_gauss_newton_terms():
    """The step prior's J^T J and J^T r, added by hand to the normal equations, are those of
    its residuals by automatic differentiation (to rounding)."""
    import jax
    import jax.numpy as jnp

    from activebonds.identify.gaps.states import step_residuals, with_steps
    from activebonds.identify.solvers.shooting_normal import Normal

    rng = np.random.default_rng(2)
    k, m, d = 6, 3, 3
    n = 2 * m * d
    z = jnp.asarray(rng.normal(size=(k, n)))
    delta = jnp.asarray(rng.normal(size=(k - 1, m, d)))
    w = jnp.asarray(np.abs(rng.normal(size=(k - 1, m))) * (rng.random((k - 1, m)) > 0.3))
    zero = Normal(
        jnp.zeros((k, n, n)),
        jnp.zeros((k - 1, n, n)),
        jnp.zeros((k, n, 1)),
        jnp.zeros((1, 1)),
        jnp.zeros((k, n)),
        jnp.zeros(1),
    )
    got = with_steps(zero, z, delta, w)
    jac = jax.jacfwd(lambda y: step_residuals(y.reshape(k, n), delta, w))(z.ravel())
    jtj = np.asarray(jac.T @ jac)
    grad = np.asarray(jac.T @ step_residuals(z, delta, w))
    for i in range(k):
        assert np.allclose(got.diag[i], jtj[i * n : (i + 1) * n, i * n : (i + 1) * n])
        if i < k - 1:
            assert np.allclose(got.off[i], jtj[i * n : (i + 1) * n, (i + 1) * n : (i + 2) * n])
    assert np.allclose(np.asarray(got.grad_s).ravel(), grad)


@pytest.mark.parametrize("stiffness", [0.7, 1.5])
def test_a_model_with_wrong_stiffnesses_fills_by_its_physics_not_by_a_free_run(stiffness):
    """A model whose stiffnesses are all off by ``stiffness`` explains only part of the
    accelerations: the continuity weight drops below the shooting fit's 100, so the markers
    present steer the trajectory through a 60-frame gap: closer to the truth than the same model
    held to its dynamics (measured 2.9 vs 4.5 mm at 0.7, 2.7 vs 7.2 mm at 1.5) and far closer
    than the spline (18 mm)."""
    from activebonds.identify.gaps.dynamics import one_step_ratio
    from activebonds.identify.gaps.fill import model_fill

    model = load_model(TRIANGLE)
    truth = _truth(240)
    genome = np.asarray(model.layout.initial(), np.float64).copy()
    genome[0::3] += np.log(stiffness)  # the log-stiffness of each bond
    wrong = model.with_genome(genome)
    true_ratio = one_step_ratio(
        model, model.layout.initial(), truth.positions, np.ones((240, 3), bool), truth.dt, 0
    )
    assert true_ratio < 0.15  # what the multi-frame second difference leaves of a true model
    t = _traj(truth.positions, missing=[(1, 100, 160)], markers=model.markers)
    plan = plan_fill(t, model.markers)
    found = model_fill(wrong, plan)
    held = model_fill(wrong, plan, continuity=100.0)
    spline = fill_baseline("spline", plan.positions, plan.mask, plan.local())

    def rms(values):
        err = values[100:160, 1] - truth.positions[100:160, 1]
        return float(np.sqrt(np.mean(np.sum(err**2, axis=-1))))

    assert 0.3 <= found.segments[0].continuity < 10.0
    assert rms(found.values) < 0.7 * rms(held.values)
    assert rms(found.values) < 0.2 * rms(spline)


@pytest.fixture(scope="module")
def gap_of_240(triangle):
    """240 frames of the triangle, B missing in frames 100:160, and the true model's fill of
    it (the same for every wrong model compared with it: made once)."""
    from activebonds.identify.gaps.fill import model_fill

    model = triangle
    truth = _truth(240)
    t = _traj(truth.positions, missing=[(1, 100, 160)], markers=model.markers)
    return truth, t, model_fill(model, plan_fill(t, model.markers))


@pytest.mark.parametrize("stiffness", [0.3, 3.0])
def test_a_wrong_model_reports_an_uncertainty_of_the_order_of_its_error(stiffness, gap_of_240):
    """Every stiffness off by ``stiffness``, a 60-frame gap of a noiseless recording: the fill
    is 11 (x0.3) and 18 mm (x3) off (RMS). The posterior standard error alone said 3.6 and 6.2 mm
    (a third of it): the fit follows the markers present, and the model's error shows as
    continuity defects that repeat frame after frame (tau about 10: a right model's are white).
    Scaled by the residuals around the gap (sqrt(tau), the noise floor), the reported
    uncertainty is of the error's order: measured 1.04 and 0.98 times it."""
    from activebonds.identify.gaps.fill import model_fill

    truth, t, right = gap_of_240
    model = load_model(TRIANGLE)
    genome = np.asarray(model.layout.initial(), np.float64).copy()
    genome[0::3] += np.log(stiffness)
    found = model_fill(model.with_genome(genome), plan_fill(t, model.markers))
    err = np.linalg.norm(found.values[100:160, 1] - truth.positions[100:160, 1], axis=-1)
    real = float(np.sqrt(np.mean(err**2)))
    reported = float(np.sqrt(np.mean(found.uncertainty[0] ** 2)))
    assert real > 5e-3  # the model is wrong by millimetres
    assert 0.7 * real < reported < 3.0 * real
    (segment,) = found.segments
    assert segment.tau > 4.0 and segment.scale >= np.sqrt(segment.tau)
    assert "continuity defects around the gaps are correlated (tau up to" in found.note()
    # the true model of the same gap: exact, and its uncertainty too (the noise floor of a
    # noiseless record: the motion's own fourth difference, under a micrometre)
    assert right.uncertainty[0].max() < 1e-6
    assert right.segments[0].tau < 4.0 and "correlated" not in right.note()


# ----------------------------------------------------------------------------- the command


def _gappy(tmp_path, ext=".trc"):
    truth = _truth()
    t = _traj(
        truth.positions,
        missing=[(1, 40, 70), (0, 0, 5), (2, 80, 115)],
        markers=("A", "B", "C"),
    )
    path = tmp_path / f"gappy{ext}"
    write_trajectory(t, path)
    return path, truth


@pytest.mark.parametrize("ext", [".c3d", ".trc"])
def test_filled_file_reads_back_without_the_filled_gaps(tmp_path, ext):
    src, truth = _gappy(tmp_path, ext)
    out = tmp_path / f"filled{ext}"
    res = cli_in_process("fill", TRIANGLE, src, "--out", out, "--max-gap", "30")
    assert res.returncode == 0, res.stderr
    assert "1 gap(s) filled by model (30 samples)" in res.stdout
    assert "left 1 gap(s) at the start (extrapolation: not filled): A 0:5" in res.stdout
    back = read_trajectory(out)
    rows = list(csv.DictReader((tmp_path / "filled.gaps.csv").read_text().splitlines()))
    left = {(int(r["frame"]), r["marker"]) for r in rows if r["status"] == "left"}
    filled = {(int(r["frame"]), r["marker"]) for r in rows if r["status"] == "filled"}
    missing = {(int(f), back.markers[m]) for f, m in zip(*np.nonzero(~back.mask), strict=True)}
    assert missing == left and not (missing & filled)
    assert len(filled) == 30 and len(left) == 5 + 35
    assert all(r["reason"] == "longer than --max-gap 30" for r in rows if r["marker"] == "C")
    err = np.abs(back.positions[40:70, 1] - truth.positions[40:70, 1]).max()
    assert err < (1e-6 if ext == ".trc" else 1e-6 + 1e-4)  # C3D holds float32 millimetres
    info = cli_in_process("info", out, "--json")
    assert json.loads(info.stdout)["gaps"] == {"A": 5, "B": 0, "C": 35}


@pytest.mark.parametrize("ext", [".mat", ".c3d"])
def test_fill_without_out_keeps_the_recordings_format_beside_it(tmp_path, ext):
    """No --out: the filled file is the recording's name with _filled, in its own format
    (a Qualisys .mat stays a .mat), the filled samples the model's."""
    src, truth = _gappy(tmp_path, ext)
    res = cli_in_process("fill", TRIANGLE, src, "--max-gap", "30")
    assert res.returncode == 0, res.stderr
    out = tmp_path / f"gappy_filled{ext}"
    back = read_trajectory(out)
    assert back.markers == ("A", "B", "C") and back.mask[40:70, 1].all()
    err = np.abs(back.positions[40:70, 1] - truth.positions[40:70, 1]).max()
    assert err < 1e-6 + 1e-4  # (C3D: float32 millimetres)
    assert (tmp_path / "gappy_filled.gaps.csv").exists()


@pytest.mark.parametrize(
    ("args", "line"),
    [
        (
            ["--markers", "A,X,Y"],
            "the model's marker(s) X, Y are not in the recording",
        ),
        (["--method", "cubic"], "--method: expected model, spline, linear, pca, got 'cubic'"),
        (["--method", "spline", "--denoise"], "--denoise: needs --method model, not spline"),
        (["--frames", "10:4"], "--frames: 10:4 is not a window of 120 frames"),
        (["--max-gap", "0"], "--max-gap: expected a positive number of frames, got 0"),
        (["--continuity", "0"], "--continuity: expected a positive weight, got 0.0"),
        (["--prior", "ica"], "--prior: expected pca, got 'ica'"),
        (["--method", "spline", "--prior", "pca"], "--prior: needs --method model, not spline"),
    ],
)
def test_hard_cases_are_one_line_and_write_nothing(tmp_path, args, line):
    src, _ = _gappy(tmp_path)
    out = tmp_path / "filled.trc"
    res = cli_in_process("fill", TRIANGLE, src, "--out", out, *args)
    assert res.returncode == 2
    assert res.stderr.count("\n") == 1 and line in res.stderr, res.stderr
    assert sorted(p.name for p in tmp_path.iterdir()) == ["gappy.trc"]


def test_fill_takes_a_step_limit_and_says_when_a_stretch_stops_there(tmp_path):
    """--max-steps bounds the Levenberg-Marquardt steps of each fitted stretch; a stretch that
    stops at it is counted as not converged, and the line names the option."""
    from activebonds.cli.fill_cmd import MAX_STEPS
    from activebonds.identify.gaps import fill

    assert MAX_STEPS == fill.MAX_STEPS
    src, _ = _gappy(tmp_path)
    res = cli_in_process("fill", TRIANGLE, src, "--out", tmp_path / "f.trc", "--max-steps", "1")
    assert res.returncode == 0, res.stderr
    assert (
        "1 not converged (stopped at the step limit (1) before converging); raise the limit "
        "with --max-steps" in res.stdout
    )
    bad = cli_in_process("fill", TRIANGLE, src, "--out", tmp_path / "g.trc", "--max-steps", "0")
    assert bad.returncode == 2 and "--max-steps" in bad.stderr


def test_a_marker_never_present_is_refused_by_name(tmp_path):
    truth = _truth(60)
    t = _traj(truth.positions, missing=[(2, 0, 60)], markers=("A", "B", "C"))
    src = tmp_path / "never.csv"
    write_trajectory(t, src)
    res = cli_in_process("fill", TRIANGLE, src, "--out", tmp_path / "f.csv", "--method", "linear")
    assert res.returncode == 2
    assert "marker(s) C never present in frames 0:60: nothing to fill from" in res.stderr
    assert sorted(p.name for p in tmp_path.iterdir()) == ["never.csv"]


# ----------------------------------------------------------------------------- the report


def test_fill_figure_draws_one_panel_per_filled_gap_with_the_spline_beside():
    from activebonds.report.fill import fill_figure

    truth = _truth()
    t = _traj(
        truth.positions, missing=[(1, 40, 70), (2, 80, 95), (0, 0, 5)], markers=("A", "B", "C")
    )
    plan = plan_fill(t, ("A", "B", "C"))
    values = fill_baseline("linear", plan.positions, plan.mask, plan.local())
    fig = fill_figure(plan, values, "linear")
    shown = [ax for ax in fig.axes if ax.get_visible()]
    assert [ax.get_title() for ax in shown] == ["B, frames 40:70", "C, frames 80:95"]
    for ax in shown:
        # per coordinate: the recording, the run's fill, the spline's fill
        assert len(ax.get_lines()) == 3 * 3
    filled = shown[0].get_lines()[1].get_ydata()  # x of B, the run's fill, frames 39..70
    assert np.allclose(filled, values[39:71, 1, 0] * 1000.0)
    assert fill_figure(plan_fill(_traj(truth.positions), ("A", "B", "C")), values, "model") is None


def test_fill_report_is_one_self_contained_page(tmp_path):
    src, _ = _gappy(tmp_path)
    page = tmp_path / "fill.html"
    out = tmp_path / "filled.trc"
    res = cli_in_process(
        "fill", TRIANGLE, src, "--out", out, "--method", "linear", "--report", page
    )
    assert res.returncode == 0, res.stderr
    assert f"wrote {page}" in res.stdout
    text = page.read_text()
    assert text.count("data:image/png;base64,") == 1
    assert 'src="http' not in text and 'href="http' not in text
    assert "<td>B</td><td>40:70</td><td>30</td><td>filled</td>" in text
    assert "left: at the start" in text
    bad = cli_in_process(
        "fill", TRIANGLE, src, "--out", tmp_path / "f2.trc", "--report", tmp_path / "r.png"
    )
    assert bad.returncode == 2 and "--report: expected an .html page" in bad.stderr
    assert not (tmp_path / "f2.trc").exists()


def test_an_entrained_drive_fills_with_its_phase_tracked_along_the_record():
    """The entrained triangle (its drive's phase pulled by C's height) simulated at one Euler
    substep: a 30-frame gap of A is its own trajectory again, the phase at every window start
    tracked along the record from the start phase; a gap in C, the signal itself, too: the
    phase is tracked along the model's own fill of C, refitted until it stops moving."""
    from activebonds.identify.gaps.dynamics import fill_phases
    from activebonds.identify.gaps.fill import model_fill
    from activebonds.model import loads_model
    from activebonds.physics import phase
    from test_entrained_drive import entrained

    model = loads_model(entrained())
    truth = simulate(model, 150, 60.0)
    t = _traj(truth.positions, missing=[(0, 50, 80)], markers=model.markers)
    found = model_fill(model, plan_fill(t, model.markers))
    err = np.linalg.norm(found.values[50:80, 0] - truth.positions[50:80, 0], axis=-1)
    assert err.max() < 1e-6
    # the phases the fill starts its windows from: tracked along C's recorded height
    plan = plan_fill(t, model.markers)
    psi = fill_phases(model, model.layout.initial(), plan.positions, plan.mask, t.dt)
    s = phase.signal(model.topology, np.asarray(truth.positions), np)
    assert (
        np.abs(psi - np.asarray(phase.track(model.params, model.topology, s, t.dt))).max() < 1e-12
    )
    # a gap in the signal's marker: the phase runs free through it
    t = _traj(truth.positions, missing=[(2, 50, 80)], markers=model.markers)
    plan = plan_fill(t, model.markers)
    found = model_fill(model, plan)
    err = np.linalg.norm(found.values[50:80, 2] - truth.positions[50:80, 2], axis=-1)
    assert err.max() < 1e-6  # measured 1.2e-12 m: the phase tracked along the fill is the truth's
    # a window that starts later (--frames 40:150) runs the phase on from the recording's
    # first frame, where the model's time starts
    t = _traj(truth.positions, missing=[(0, 70, 100)], markers=model.markers)
    found = model_fill(model, plan_fill(t, model.markers, frames=(40, 150)))
    err = np.linalg.norm(found.values[30:60, 0] - truth.positions[70:100, 0], axis=-1)
    assert err.max() < 1e-6


# ----------------------------------------------------------------------------- in Python


def test_fill_file_writes_what_the_command_writes(tmp_path):
    """``fill_file`` (the library's ``activebonds fill``): the same filled file, the same
    record and the same lines as the command, byte for byte."""
    from activebonds import FillSettings, fill_file

    src, _ = _gappy(tmp_path)
    res = cli_in_process("fill", TRIANGLE, src, "--out", tmp_path / "cli.trc", "--max-gap", "30")
    assert res.returncode == 0, res.stderr
    done = fill_file(TRIANGLE, src, tmp_path / "py.trc", FillSettings(max_gap=30))
    named = (tmp_path / "py.trc").read_bytes().replace(b"py.trc", b"cli.trc")  # TRC's header
    assert named == (tmp_path / "cli.trc").read_bytes()
    assert (tmp_path / "py.gaps.csv").read_bytes() == (tmp_path / "cli.gaps.csv").read_bytes()
    assert done.record == tmp_path / "py.gaps.csv"
    assert len(done.plan.to_fill) == 1 and len(done.plan.left) == 2
    printed = res.stdout.replace(str(tmp_path / "cli"), str(tmp_path / "py")).splitlines()
    assert done.lines() == printed


@pytest.mark.parametrize(
    ("options", "line"),
    [
        ({"method": "cubic"}, "--method: expected model, spline, linear, pca, got 'cubic'"),
        ({"method": "spline", "denoise": True}, "--denoise: needs --method model, not spline"),
        ({"frames": "10:4"}, "--frames: 10:4 is not a window of 120 frames"),
        ({"max_gap": 0}, "--max-gap: expected a positive number of frames, got 0"),
        ({"continuity": 0.0}, "--continuity: expected a positive weight, got 0.0"),
        ({"prior": "ica"}, "--prior: expected pca, got 'ica'"),
        ({"method": "spline", "prior": "pca"}, "--prior: needs --method model, not spline"),
        ({"integrator": "rk4"}, "--integrator: expected euler or verlet, got 'rk4'"),
    ],
)
def test_fill_file_refuses_what_the_command_refuses_in_the_same_line(tmp_path, options, line):
    from pydantic import ValidationError

    from activebonds import FillSettings, fill_file
    from activebonds.errors import option_error

    src, _ = _gappy(tmp_path)
    args = [a for k, v in options.items() for a in (f"--{k.replace('_', '-')}", str(v))]
    args = ["--denoise" if a == "--denoise" else a for a in args if a != "True"]
    res = cli_in_process("fill", TRIANGLE, src, "--out", tmp_path / "cli.trc", *args)
    assert res.returncode == 2 and res.stderr.strip() == f"error: {line}", res.stderr
    with pytest.raises((InputError, ValidationError)) as caught:
        fill_file(TRIANGLE, src, tmp_path / "py.trc", FillSettings(**options))
    error = caught.value
    said = error.line() if isinstance(error, InputError) else option_error(error).line()
    assert said == line
    assert sorted(p.name for p in tmp_path.iterdir()) == ["gappy.trc"]
