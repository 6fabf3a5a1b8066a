"""activebonds' binary bond against an independent simulator: MuJoCo's spatial tendons.

The truth (tests/mujoco_truth.py) is 4 point masses, 6 spring-damper tendons, RK4 at 1e-4 s.
Checked here: MuJoCo's tendon force is the bond law (spring and damper separately); MuJoCo
conserves momentum, conserves energy without damping and dissipates exactly sum c Ldot^2
with it; activebonds, simulating the equivalent model file, converges to MuJoCo's
trajectory as its step shrinks, within error bounds derived from the steps.
"""

import numpy as np
import pytest

mujoco = pytest.importorskip("mujoco")

import mujoco_truth  # noqa: E402
from activebonds import simulate  # noqa: E402
from activebonds.model import loads_model  # noqa: E402

SECONDS = 1.0  # length of the activebonds cross-check
H = 1e-4  # activebonds' step in the cross-check (= MuJoCo's)


@pytest.fixture(scope="module")
def truth():
    return mujoco_truth.tendon_system(n_particles=4, rate=100.0, seconds=2.0, seed=0)


@pytest.fixture(scope="module")
def undamped():
    return mujoco_truth.tendon_system(seconds=2.0, seed=0, damping_scale=0.0)


def bond_forces(x, v, bonds, spring=True, damper=True):
    """DESIGN.md's binary bond, in numpy: f = k (L - l0) + c Ldot, F_i += f u, F_j -= f u."""
    F = np.zeros_like(x)
    for b in bonds:
        i, j = b.particles
        d = x[..., j, :] - x[..., i, :]
        L = np.linalg.norm(d, axis=-1, keepdims=True)
        u = d / L
        Ldot = np.sum((v[..., j, :] - v[..., i, :]) * u, axis=-1, keepdims=True)
        f = spring * b.stiffness * (L - b.rest_length) + damper * b.damping * Ldot
        F[..., i, :] += f * u
        F[..., j, :] -= f * u
    return F


def omega_max(t) -> float:
    """Highest natural frequency (rad/s) of the linearised spring network at frame 0."""
    n = len(t.masses)
    K = np.zeros((3 * n, 3 * n))
    x = t.positions[0]
    for b in t.bonds:
        i, j = b.particles
        u = (x[j] - x[i]) / np.linalg.norm(x[j] - x[i])
        kuu = b.stiffness * np.outer(u, u)
        for p, q, s in ((i, i, 1), (j, j, 1), (i, j, -1), (j, i, -1)):
            K[3 * p : 3 * p + 3, 3 * q : 3 * q + 3] += s * kuu
    w = 1.0 / np.sqrt(np.repeat(t.masses, 3))
    return float(np.sqrt(np.linalg.eigvalsh(w[:, None] * K * w[None, :]).max()))


def activebonds_run(t, h: float, start=None) -> np.ndarray:
    """activebonds (velocity Verlet, step h) on the model file with the true values, sampled
    at the truth's frames over SECONDS. It runs at rate 1/h with one substep: the same
    arithmetic as the truth's rate with 1/(h rate) substeps, but a short compile."""
    model = loads_model(t.model_toml("truth"))
    rate = round(1.0 / h)
    xs = simulate(model, round(SECONDS * rate) + 1, rate, start=start, integrator="verlet")
    return xs.positions[:: round(rate / t.rate)]


def first_order_bound(t, h: float) -> float:
    """A priori bound on activebonds' position error over SECONDS.

    activebonds' Verlet evaluates the step's closing force with the half-step velocity
    (forces.py has velocity-dependent dampers), so each step's velocity is off by
    (h/2) M^-1 D (v_half - v_new) = -(h^2/4) M^-1 D a, D the (linear) damping map: a
    spurious acceleration e = (h/4) M^-1 D a, first order in h. A mode's response to e is
    its integral against sin(w (t-s))/w, whose size is at most (t - s): the error at t is at
    most int_0^t (t - s) |e(s)| ds. (Verlet's own error is O(h^2), far smaller here.)"""
    n = round(SECONDS * t.rate) + 1
    x, v, m = t.positions[:n], t.velocities[:n], t.masses[:, None]
    a = bond_forces(x, v, t.bonds) / m
    e = 0.25 * h * np.linalg.norm(bond_forces(x, a, t.bonds, spring=False) / m, axis=-1).max(-1)
    s = t.times[:n]
    return max(np.trapezoid((s[k] - s[: k + 1]) * e[: k + 1], s[: k + 1]) for k in range(1, n))


# ------------------------------------------------------------------ MuJoCo on its own


def test_mujoco_tendon_force_is_the_bond_law(truth):
    """qfrc_spring = -k (L - springlength) along u, qfrc_damper = -c Ldot along u, at MuJoCo
    states taken from the run (the sites are at the centres of mass: no torques)."""
    model = mujoco.MjModel.from_xml_string(truth.xml)
    data = mujoco.MjData(model)
    n = len(truth.masses)
    for f in (0, 37, 150):
        qpos = data.qpos.reshape(n, 7)
        qpos[:, :3], qpos[:, 3:] = truth.positions[f], [1.0, 0.0, 0.0, 0.0]
        data.qvel[:] = 0.0
        data.qvel.reshape(n, 6)[:, :3] = truth.velocities[f]
        mujoco.mj_forward(model, data)
        x, v = truth.positions[f], truth.velocities[f]
        spring = data.qfrc_spring.reshape(n, 6)
        damper = data.qfrc_damper.reshape(n, 6)
        want_s = bond_forces(x, v, truth.bonds, damper=False)
        want_d = bond_forces(x, v, truth.bonds, spring=False)
        assert np.abs(want_d).max() > 0.01  # the dampers do act in these states
        np.testing.assert_allclose(spring[:, :3], want_s, rtol=1e-10, atol=1e-12)
        np.testing.assert_allclose(damper[:, :3], want_d, rtol=1e-10, atol=1e-12)
        np.testing.assert_allclose(spring[:, 3:], 0.0, atol=1e-12)
        np.testing.assert_allclose(damper[:, 3:], 0.0, atol=1e-12)
        np.testing.assert_allclose(data.qfrc_passive, data.qfrc_spring + data.qfrc_damper)


def test_every_bond_is_excited(truth):
    l0 = np.array([b.rest_length for b in truth.bonds])
    strain = np.abs(truth.lengths() - l0).max(axis=0) / l0
    assert strain.min() > 0.03, strain
    # MuJoCo's own spring energy reads springlength as the rest length.
    np.testing.assert_allclose(truth.mujoco_potential, truth.potential_energy(), rtol=1e-12)


def test_mujoco_conserves_momentum(truth, undamped):
    """No external force, and RK4 keeps linear invariants exactly: p stays at its start,
    0 to rounding (velocities ~0.3 m/s, masses ~1 kg)."""
    for t in (truth, undamped):
        assert np.abs(t.momentum()).max() < 1e-13


def test_mujoco_energy_without_damping_is_conserved(undamped):
    """RK4's energy error over T is about T w (w h)^4 relative (w the highest frequency)."""
    w = omega_max(undamped)
    band = 2.0 * w * (w * undamped.timestep) ** 4  # T = 2 s
    E = undamped.energy()
    assert np.ptp(E) / E[0] < band, (np.ptp(E) / E[0], band)


def test_mujoco_energy_with_damping_dissipates_sum_c_ldot2(truth, undamped):
    """dE/dt = -sum c Ldot^2 <= 0: E never rises (beyond rounding, 1e-12 E(0)), falls a
    lot over 2 s, and E(0) - E(T) equals the integral of sum c Ldot^2 (Simpson's rule on
    the 100 Hz samples, relative error ~ (2 w dt)^4 / 180 with Ldot^2 oscillating at 2 w)."""
    E = truth.energy()
    assert E[0] == pytest.approx(undamped.energy()[0])  # same start
    assert np.diff(E).max() < 1e-12 * E[0]
    assert E[-1] < 0.5 * E[0]
    i, j = np.array([b.particles for b in truth.bonds]).T
    x, v = truth.positions, truth.velocities
    u = (x[:, j] - x[:, i]) / truth.lengths()[..., None]
    ldot = np.sum((v[:, j] - v[:, i]) * u, axis=-1)
    power = ldot**2 @ np.array([b.damping for b in truth.bonds])
    dt = 1.0 / truth.rate
    simpson = dt / 3 * (power[0] + power[-1] + 4 * power[1:-1:2].sum() + 2 * power[2:-1:2].sum())
    tol = (2 * omega_max(truth) * dt) ** 4 / 180
    assert (E[0] - E[-1]) / simpson == pytest.approx(1.0, abs=tol)


def test_mujoco_converged(truth):
    """MuJoCo's RK4 error at 1e-4 s is negligible next to activebonds' (RK4 is 4th order:
    the error at h is ~ 1/15 of the difference between h and 2h)."""
    coarse = mujoco_truth.tendon_system(seconds=SECONDS, seed=0, timestep=2 * truth.timestep)
    n = coarse.n_frames
    assert np.abs(coarse.positions - truth.positions[:n]).max() / 15 < 1e-11


# ------------------------------------------------------------------ activebonds vs MuJoCo


def test_activebonds_converges_to_mujoco(truth):
    """Same law, same start (the model file carries MuJoCo's frame-0 state): activebonds'
    Verlet error must be first order, C h with C fixed (halving h halves it; a different
    law would leave a floor), within the a priori bound; the Richardson extrapolation
    2 x(h) - x(2h) cancels C h and leaves Verlet's own phase error, 2 A w^3 T h^2 / 24
    (A the largest bond stretch), and MuJoCo's ~1e-12.

    Measured (seed 0): max error over 1 s 5.25e-6 m at h = 1e-4 (1.06e-5 at 2e-4; bound
    1.1e-4); Richardson 2.3e-7 (bound 4.5e-6). Over seeds 0-3 with 3 or 4
    particles: errors 1.1e-6 to 5.6e-6 m, ratios 2.00 to 2.08."""
    n = round(SECONDS * truth.rate) + 1
    want = truth.positions[:n]
    fine, coarse = activebonds_run(truth, H), activebonds_run(truth, 2 * H)
    err_fine = np.abs(fine - want).max()
    err_coarse = np.abs(coarse - want).max()
    assert err_fine < first_order_bound(truth, H), (err_fine, first_order_bound(truth, H))
    assert err_coarse / err_fine == pytest.approx(2.0, rel=0.1)
    l0 = np.array([b.rest_length for b in truth.bonds])
    stretch = np.abs(truth.lengths()[:n] - l0).max()
    w = omega_max(truth)
    richardson = np.abs(2 * fine - coarse - want).max()
    assert richardson < 2 * stretch * w**3 * SECONDS * (2 * H) ** 2 / 24


def test_activebonds_from_two_recorded_frames(truth):
    """The fitting path: activebonds starts from MuJoCo's first two frames (at 1/h), its
    start velocity inferred from them, and stays within the same bound."""
    h = H
    two = mujoco_truth.tendon_system(rate=1.0 / h, seconds=h, seed=0).trajectory()
    assert two.n_frames == 2
    np.testing.assert_array_equal(two.positions[0], truth.positions[0])
    got = activebonds_run(truth, h, start=two)
    err = np.abs(got - truth.positions[: len(got)]).max()
    assert err < first_order_bound(truth, h), err


def test_model_file_start_values(truth):
    """The fitting file: masses fixed at the truth, a type per bond, k/c/l0 free with wrong
    starts inside generous bounds."""
    model = loads_model(truth.model_toml())
    spec = model.spec
    assert [p.mass for p in spec.particle] == pytest.approx(list(truth.masses))
    assert len({b.type for b in spec.bond}) == len(truth.bonds)
    for b, tb in zip(spec.bond, truth.bonds, strict=True):
        assert b.rest_length.value == pytest.approx(1.2 * tb.rest_length)
        assert b.stiffness.value == pytest.approx(np.sqrt(1000.0))
        assert b.damping.value == pytest.approx(0.1)
    x0, v0 = model.initial_state()
    np.testing.assert_array_equal(x0, truth.positions[0])
    np.testing.assert_array_equal(v0, truth.velocities[0])
    traj = truth.trajectory()
    assert traj.markers == model.markers and traj.n_frames == truth.n_frames
    assert model.layout.n_genes == 3 * len(truth.bonds)
    fixed = loads_model(truth.model_toml("truth", free=False))
    assert fixed.layout.n_genes == 0
