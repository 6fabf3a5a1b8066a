"""Ground truth from an independent simulator: point masses joined by MuJoCo spatial tendons.

activebonds' own simulator cannot cheat a test whose data it did not generate. Here MuJoCo
(RK4, a fine step) integrates free point masses joined by spring-damper tendons, and
:class:`MujocoTruth` carries the samples, the true parameters, the equivalent activebonds
model file (:meth:`MujocoTruth.model_toml`) and an activebonds
:class:`~activebonds.data.Trajectory` (:meth:`MujocoTruth.trajectory`).

MuJoCo's tendon law is the activebonds binary bond. A spatial tendon between two sites has
length ``L = |x_j - x_i|`` and velocity ``Ldot = J qvel = (v_j - v_i) . u``; its passive
force along the tendon is ``-k (L - springlength) - c Ldot`` (``mj_passive``: stiffness
times the distance outside the ``springlength`` dead band, whose two ends are equal when one
value is given, plus ``-damping * ten_velocity``), mapped to the joints by ``J^T``. With
``dL/dx_i = -u`` that is ``F_i += f u``, ``F_j -= f u`` with ``f = k (L - l0) + c Ldot``.
RK4 treats the damping explicitly (only the Euler and implicit integrators make it
implicit), and the sites sit at the bodies' centres of mass, so the tendon forces exert no
torque and the free joints' rotations stay at rest.

    truth = tendon_system(n_particles=4, rate=100.0, seconds=2.0, seed=0)
    truth.positions               # [F, P, 3] float64, frame 0 is the initial state
    truth.trajectory()            # activebonds Trajectory of the samples
    truth.model_toml()            # activebonds model: masses fixed, each bond its own type,
                                  # k, c, l0 free with a deliberately wrong start
    truth.model_toml("truth")     # the same with the true values (still free)
    truth.model_toml("truth", free=False)  # every parameter fixed at the truth
"""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass

import mujoco
import numpy as np

# Search bounds of the emitted model file (rest length: relative to the true value).
STIFFNESS_BOUNDS = (1.0, 1000.0)
DAMPING_BOUNDS = (0.001, 10.0)
REST_LENGTH_BOUNDS = (0.5, 1.5)
REST_LENGTH_START = 1.2  # the wrong start of a rest length, relative to the truth

# Ranges of the true parameters (spread over them deterministically from the seed).
STIFFNESS_RANGE = (20.0, 200.0)
DAMPING_RANGE = (0.05, 1.0)
REST_LENGTH_RANGE = (0.3, 0.6)
MASS_RANGE = (0.5, 2.0)
INERTIA = 1e-6  # kg m^2, the point masses' (irrelevant) rotational inertia


@dataclass(frozen=True)
class Bond:
    """One tendon: particle indices (i, j) and its true parameters."""

    particles: tuple[int, int]
    stiffness: float
    damping: float
    rest_length: float


@dataclass(frozen=True, eq=False)
class MujocoTruth:
    """MuJoCo samples every ``1 / rate`` s (frame 0 = the initial state) and the truth.

    Attributes:
        positions: [F, P, 3] float64, metres.
        velocities: [F, P, 3] float64, m/s (MuJoCo's state at each sample, not differences).
        markers: particle (= marker) names.
        rate: sample rate in Hz.
        masses: [P] kg.
        bonds: the tendons with their true stiffness, damping and rest length.
        timestep: MuJoCo's RK4 step in seconds.
        xml: the MJCF model that produced the samples.
        mujoco_potential: [F] MuJoCo's own potential energy (``data.energy[0]``: the tendon
            springs), for checking that it reads ``springlength`` as we do.
    """

    positions: np.ndarray
    velocities: np.ndarray
    markers: tuple[str, ...]
    rate: float
    masses: np.ndarray
    bonds: tuple[Bond, ...]
    timestep: float
    xml: str
    mujoco_potential: np.ndarray

    @property
    def n_frames(self) -> int:
        return int(self.positions.shape[0])

    @property
    def times(self) -> np.ndarray:
        return np.arange(self.n_frames) / self.rate

    def lengths(self) -> np.ndarray:
        """[F, B] bond lengths."""
        i, j = np.array([b.particles for b in self.bonds]).T
        return np.linalg.norm(self.positions[:, j] - self.positions[:, i], axis=-1)

    def momentum(self) -> np.ndarray:
        """[F, 3] total linear momentum."""
        return np.einsum("p,fpd->fd", self.masses, self.velocities)

    def kinetic_energy(self) -> np.ndarray:
        return 0.5 * np.einsum("p,fpd,fpd->f", self.masses, self.velocities, self.velocities)

    def potential_energy(self) -> np.ndarray:
        """[F] sum over bonds of 0.5 k (L - l0)^2."""
        k = np.array([b.stiffness for b in self.bonds])
        l0 = np.array([b.rest_length for b in self.bonds])
        return 0.5 * np.sum(k * (self.lengths() - l0) ** 2, axis=-1)

    def energy(self) -> np.ndarray:
        """[F] mechanical energy: kinetic + spring."""
        return self.kinetic_energy() + self.potential_energy()

    def trajectory(self):
        """The samples as an activebonds Trajectory (every marker seen in every frame)."""
        from activebonds.data import Trajectory

        return Trajectory(
            positions=self.positions,
            mask=np.ones(self.positions.shape[:2], bool),
            markers=self.markers,
            rate=self.rate,
            source_units="m",
        )

    def model_toml(self, values: str = "start", free: bool = True, name: str = "mujoco") -> str:
        """The equivalent activebonds model file.

        Masses are fixed at the truth; particles start at MuJoCo's frame 0 (position and
        velocity, for ``simulate``); each bond has its own ``type`` (``b<i><j>``), so every
        bond's parameters are identified separately. ``values="start"`` writes deliberately
        wrong starting values (the geometric mean of the bounds for stiffness and damping,
        1.2x the true rest length); ``values="truth"`` the true ones. ``free=False`` writes
        plain numbers (fixed parameters) instead of ``{ value, min, max }`` tables: use it
        for a truth with zero damping, which lies outside the damping bounds.
        """
        if values not in ("start", "truth"):
            raise ValueError(f"values must be 'start' or 'truth', got {values!r}")
        lines = [
            f"# {len(self.markers)} point masses joined by MuJoCo spatial tendons "
            f"(tests/mujoco_truth.py); values: {values}.",
            f'name = "{name}"',
            "dimension = 3",
        ]
        for p, marker in enumerate(self.markers):
            lines += [
                "",
                "[[particle]]",
                f'name = "{marker}"',
                f"mass = {_num(self.masses[p])}",
                f"position = {_vec(self.positions[0, p])}",
                f"velocity = {_vec(self.velocities[0, p])}",
            ]
        for b in self.bonds:
            i, j = b.particles
            a, c = self.markers[i], self.markers[j]
            lo_l, hi_l = (r * b.rest_length for r in REST_LENGTH_BOUNDS)
            params = {
                "stiffness": (
                    b.stiffness,
                    math.sqrt(math.prod(STIFFNESS_BOUNDS)),
                    *STIFFNESS_BOUNDS,
                ),
                "rest_length": (b.rest_length, REST_LENGTH_START * b.rest_length, lo_l, hi_l),
                "damping": (b.damping, math.sqrt(math.prod(DAMPING_BOUNDS)), *DAMPING_BOUNDS),
            }
            lines += [
                "",
                "[[bond]]",
                'kind = "binary"',
                f'type = "{bond_type(i, j, len(self.markers))}"',
                f'particles = ["{a}", "{c}"]',
            ]
            for key, (truth, start, lo, hi) in params.items():
                value = truth if values == "truth" else start
                if free:
                    lines.append(
                        f"{key} = {{ value = {_num(value)}, min = {_num(lo)}, max = {_num(hi)} }}"
                    )
                else:
                    lines.append(f"{key} = {_num(value)}")
        return "\n".join(lines) + "\n"


def bond_type(i: int, j: int, n_particles: int) -> str:
    """A tendon's bond type name: "b01" (fewer than 11 particles) or "b3_12"."""
    return f"b{i}{j}" if n_particles <= 10 else f"b{i}_{j}"


def _num(x: float) -> str:
    return repr(float(x))  # shortest round-trip form, a valid TOML float


def _vec(x) -> str:
    return "[" + ", ".join(_num(v) for v in x) + "]"


def _spread(rng: np.random.Generator, lo: float, hi: float, n: int) -> np.ndarray:
    """n values spread log-evenly over [lo, hi] in random order, each jittered by <= 10 %."""
    base = np.geomspace(lo, hi, n) if n > 1 else np.array([math.sqrt(lo * hi)])
    return rng.permutation(base) * np.exp(rng.uniform(-0.1, 0.1, n))


def _rest_shape(rng: np.random.Generator, n: int) -> np.ndarray:
    """n points whose pairwise distances all lie in REST_LENGTH_RANGE, well spread in 3D
    (not near-collinear or near-flat), by rejection from a ball."""
    lo, hi = REST_LENGTH_RANGE
    need = min(n - 1, 3)  # the dimensions the shape must span to be rigid
    for _ in range(100_000):
        x = rng.uniform(-1.0, 1.0, (4 * n, 3))
        x = x[np.linalg.norm(x, axis=1) <= 1.0][:n] * (0.5 * hi)
        if len(x) < n:
            continue
        d = np.linalg.norm(x[:, None] - x[None], axis=-1)[np.triu_indices(n, 1)]
        if not np.all((d >= lo) & (d <= hi)):
            continue
        if n == 2 or np.linalg.svd(x - x.mean(0), compute_uv=False)[need - 1] > 0.08:
            return x
    raise ValueError(f"found no rest shape of {n} particles with bonds in {REST_LENGTH_RANGE}")


def _cloud(rng: np.random.Generator, n: int) -> np.ndarray:
    """n points in a ball, no two closer than REST_LENGTH_RANGE's low end (a sparse
    network's rest shape: its bonds join near neighbours)."""
    lo = REST_LENGTH_RANGE[0]
    radius = lo * (n / 0.4) ** (1 / 3) / 2  # a random close packing's density, roughly
    points: list[np.ndarray] = []
    while len(points) < n:
        x = rng.uniform(-radius, radius, 3)
        if np.linalg.norm(x) <= radius and all(np.linalg.norm(x - q) >= lo for q in points):
            points.append(x)
    return np.array(points)


def _mjcf(masses, rest, bonds, timestep: float) -> str:
    bodies = "\n".join(
        f'    <body name="P{p}" pos="{_num(x[0])} {_num(x[1])} {_num(x[2])}">\n'
        f"      <freejoint/>\n"
        f'      <inertial pos="0 0 0" mass="{_num(m)}" diaginertia="{INERTIA} {INERTIA} {INERTIA}"/>\n'
        f'      <site name="s{p}" pos="0 0 0" size="0.01"/>\n'
        f"    </body>"
        for p, (m, x) in enumerate(zip(masses, rest, strict=True))
    )
    tendons = "\n".join(
        f'    <spatial name="b{i}{j}" stiffness="{_num(b.stiffness)}" damping="{_num(b.damping)}" '
        f'springlength="{_num(b.rest_length)}">\n'
        f'      <site site="s{i}"/>\n      <site site="s{j}"/>\n    </spatial>'
        for b in bonds
        for i, j in [b.particles]
    )
    # Gravity 0, no geoms (so no contacts), RK4 with the fine step, and the energy flag
    # so that MuJoCo reports its own spring energy.
    return f"""<mujoco model="tendon_system">
  <compiler angle="radian" inertiafromgeom="false"/>
  <option timestep="{_num(timestep)}" integrator="RK4" gravity="0 0 0">
    <flag energy="enable" contact="disable"/>
  </option>
  <worldbody>
{bodies}
  </worldbody>
  <tendon>
{tendons}
  </tendon>
</mujoco>
"""


def tendon_system(
    n_particles: int = 4,
    rate: float = 100.0,
    seconds: float = 2.0,
    seed: int = 0,
    timestep: float = 1e-4,
    damping_scale: float = 1.0,
    trial: int = 0,
    excitation: float = 1.0,
    neighbours: int | None = None,
) -> MujocoTruth:
    """Free point masses, every pair joined by a spring-damper tendon (2: one bond, 3: a
    triangle, 4: a tetrahedron; more: the complete graph), simulated by MuJoCo.
    ``neighbours``: instead, each mass joined to its that many nearest in the rest shape (a
    sparse network, each pair once).

    Deterministic from ``seed``: masses spread over [0.5, 2] kg, stiffnesses over [20, 200]
    N/m, dampings over [0.05, 1] N s/m (times ``damping_scale``; 0 for an undamped system);
    the rest shape is a random rigid shape with bonds of 0.3-0.6 m, each bond at rest there.
    The start perturbs every position by ~10 % of the mean bond length and gives velocities
    of ~0.3 m/s, the total momentum removed (the centre of mass stays at the origin).
    Samples every ``1 / rate`` s for ``seconds`` s (frame 0 included); ``1 / rate`` must be a
    whole number of MuJoCo steps. ``trial`` > 0 draws another start of the same system (the
    same parameters: a further recording of one subject); ``excitation`` scales the start's
    perturbation and velocities.
    """
    if n_particles < 2:
        raise ValueError("need at least 2 particles")
    per_frame = 1.0 / (rate * timestep)
    steps = round(per_frame)
    if steps < 1 or abs(per_frame - steps) > 1e-9 * per_frame:
        raise ValueError(f"1/rate = {1 / rate} s is not a whole number of {timestep} s steps")
    rng = np.random.default_rng(seed)
    pairs = list(itertools.combinations(range(n_particles), 2))
    masses = _spread(rng, *MASS_RANGE, n_particles)
    rest = _rest_shape(rng, n_particles) if neighbours is None else _cloud(rng, n_particles)
    if neighbours is not None:
        gaps = np.linalg.norm(rest[:, None] - rest[None], axis=-1) + np.diag(
            np.full(n_particles, np.inf)
        )
        near = {
            tuple(sorted((i, int(j))))
            for i in range(n_particles)
            for j in np.argsort(gaps[i])[:neighbours]
        }
        pairs = sorted(near)
    rest = rest - masses @ rest / masses.sum()
    stiffness = _spread(rng, *STIFFNESS_RANGE, len(pairs))
    damping = _spread(rng, *DAMPING_RANGE, len(pairs)) * damping_scale
    bonds = tuple(
        Bond(
            particles=(i, j),
            stiffness=float(k),
            damping=float(c),
            rest_length=float(np.linalg.norm(rest[j] - rest[i])),
        )
        for (i, j), k, c in zip(pairs, stiffness, damping, strict=True)
    )
    scale = np.mean([b.rest_length for b in bonds])
    if trial:
        rng = np.random.default_rng((seed, trial))
    amp = 0.1 * excitation * scale / math.sqrt(3)
    x0 = rest + rng.normal(0.0, amp, rest.shape)
    x0 -= masses @ x0 / masses.sum()
    v0 = rng.normal(0.0, 0.3 * excitation / math.sqrt(3), rest.shape)
    v0 -= masses @ v0 / masses.sum()

    xml = _mjcf(masses, rest, bonds, timestep)
    model = mujoco.MjModel.from_xml_string(xml)
    data = mujoco.MjData(model)
    # MuJoCo must read the tendons as we wrote them: one spring length (both ends of the
    # dead band), no joint damping or armature, point sites at the centres of mass.
    assert np.allclose(model.tendon_lengthspring[:, 0], model.tendon_lengthspring[:, 1])
    assert np.allclose(model.tendon_lengthspring[:, 0], [b.rest_length for b in bonds])
    assert not model.dof_damping.any() and not model.dof_armature.any()
    assert not model.jnt_stiffness.any()
    assert np.allclose(model.body_mass[1:], masses)
    assert not model.body_ipos.any() and not model.site_pos.any()

    qpos = data.qpos.reshape(n_particles, 7)
    qvel = data.qvel.reshape(n_particles, 6)
    qpos[:, :3] = x0
    qpos[:, 3:] = [1.0, 0.0, 0.0, 0.0]
    qvel[:, :3] = v0  # a free joint's linear velocity, world frame
    qvel[:, 3:] = 0.0

    n_frames = int(round(seconds * rate)) + 1
    xs = np.empty((n_frames, n_particles, 3))
    vs = np.empty_like(xs)
    potential = np.empty(n_frames)
    for f in range(n_frames):
        if f:
            for _ in range(steps):
                mujoco.mj_step(model, data)
        mujoco.mj_forward(model, data)  # energy of the current state
        xs[f] = qpos[:, :3]
        vs[f] = qvel[:, :3]
        potential[f] = data.energy[0]
    return MujocoTruth(
        positions=xs,
        velocities=vs,
        markers=tuple(f"P{p}" for p in range(n_particles)),
        rate=float(rate),
        masses=masses,
        bonds=bonds,
        timestep=float(timestep),
        xml=xml,
        mujoco_potential=potential,
    )
