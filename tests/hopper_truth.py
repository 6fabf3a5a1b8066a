"""Ground truth from an independent fine integrator: a hopper (a body and a foot) on the ground.

Written in NumPy from the laws' definitions (DESIGN.md §2), not by calling activebonds'
physics, so a fit of its samples cannot agree with it by sharing a bug (:func:`forces`; the
generator runs the same operations on Python floats, :func:`integrate`, bit for bit):

* a viscoelastic leg between body (b) and foot (f): with ``u = (x_f - x_b) / L``, ``L`` the
  length and ``Ldot = (v_f - v_b) . u``, the tension ``T = k (L - l0) + c Ldot`` pulls them
  together (``F_b = T u``, ``F_f = -T u``);
* gravity ``m g`` along -z;
* each particle against the plane ``z = h`` (normal +z): penetration ``d = h - z``; while
  ``d > 0`` a normal force ``Fn = max(0, k_g d - c_g v_z)`` and Coulomb friction
  ``-mu Fn vt / sqrt(|vt|^2 + eps^2)`` on the tangential velocity ``vt = (v_x, v_y, 0)``, with
  ``eps = 1e-3`` m/s; nothing otherwise.

Semi-implicit Euler (``v += h F / m; x += h v``) at ``h = 1e-5`` s, 500 steps per frame at
200 Hz: fine enough that the sticking foot's friction drag (``mu Fn / eps``, about 1.2e4 N s/m
on a 0.5 kg foot) is integrated stably, which the model's coarser steps are not.

Thrown forward and sideways with a spin about the foot, the hopper lands on its foot, slides
(kinetic friction), sticks, bounces on the leg and tips over onto its body (both particles
in contact, sliding and sticking) within 2.5 s.

    truth = hopper()                   # HopperTruth: positions [F, 2, 3], the true values
    truth.trajectory()                 # an activebonds Trajectory of the samples
    truth.model_toml()                 # the model to fit: wrong start values, wide bounds
    truth.model_toml("truth")          # the same with the true values
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from functools import lru_cache

import numpy as np

EPS = 1e-3  # m/s, the friction's smoothing speed (the contact law's)
G = 9.81

TRUTH = {
    "body_mass": 2.0,  # kg, fixed in the model (it sets the scale of every force)
    "foot_mass": 0.5,  # kg
    "leg.stiffness": 1500.0,  # N/m
    "leg.rest_length": 0.3,  # m
    "leg.damping": 5.0,  # N s/m
    "ground.height": 0.02,  # m
    "ground.stiffness": 2.0e4,  # N/m
    "ground.damping": 20.0,  # N s/m
    "ground.friction": 0.5,
}

START = {  # the model file's values for the fit: not the truth
    "foot_mass": 1.0,
    "leg.stiffness": 800.0,
    "leg.rest_length": 0.25,
    "leg.damping": 2.0,
    "ground.height": 0.0,
    "ground.stiffness": 1.0e4,
    "ground.damping": 10.0,
    "ground.friction": 0.8,
}

BOUNDS = {
    "foot_mass": (0.1, 2.0),
    "leg.stiffness": (100.0, 10000.0),
    "leg.rest_length": (0.15, 0.45),
    "leg.damping": (0.1, 50.0),
    "ground.height": (-0.05, 0.05),
    "ground.stiffness": (1.0e3, 1.0e5),
    "ground.damping": (1.0, 200.0),
    "ground.friction": (0.0, 2.0),
}

X0 = np.array([[0.0, 0.0, 0.42], [0.03, 0.02, 0.10]])  # body, foot (m)
V0 = np.array([[1.2, 0.3, 0.0], [0.6, 0.0, -0.5]])  # m/s


def forces(x: np.ndarray, v: np.ndarray, p: dict) -> np.ndarray:
    """[2, 3] forces on body and foot (N) at positions x, velocities v [2, 3]."""
    m = np.array([p["body_mass"], p["foot_mass"]])
    f = np.zeros((2, 3))
    f[:, 2] -= m * G
    dx, dv = x[1] - x[0], v[1] - v[0]
    # the dot products summed left to right, as written (``@`` is BLAS's, whose order and
    # fused multiply-adds vary with the build: NumPy 2.4's differed from the float loop's in
    # the last bit)
    length = np.sqrt(dx[0] * dx[0] + dx[1] * dx[1] + dx[2] * dx[2])
    u = dx / length
    along = dv[0] * u[0] + dv[1] * u[1] + dv[2] * u[2]
    tension = p["leg.stiffness"] * (length - p["leg.rest_length"]) + p["leg.damping"] * along
    f[0] += tension * u
    f[1] -= tension * u
    depth = p["ground.height"] - x[:, 2]
    fn = np.maximum(0.0, p["ground.stiffness"] * depth - p["ground.damping"] * v[:, 2])
    fn = np.where(depth > 0.0, fn, 0.0)
    vt = v.copy()
    vt[:, 2] = 0.0
    speed = np.sqrt(np.sum(vt * vt, axis=1) + EPS**2)
    f[:, 2] += fn
    f -= (p["ground.friction"] * fn / speed)[:, None] * vt
    return f


@dataclass(frozen=True, eq=False)
class HopperTruth:
    positions: np.ndarray  # [F, 2, 3] m, frame 0 the initial state
    velocities: np.ndarray  # [F, 2, 3] m/s, the integrator's state at each sample
    rate: float
    step: float  # the integrator's step (s)
    values: dict = field(default_factory=lambda: dict(TRUTH))
    markers: tuple[str, ...] = ("body", "foot")

    def trajectory(self, noise_mm: float = 0.0, seed: int = 0):
        """The samples as an activebonds Trajectory, with Gaussian marker noise of
        ``noise_mm`` (per axis, standard deviation) if given."""
        from activebonds.data import Trajectory

        x = self.positions
        if noise_mm:
            rng = np.random.default_rng(seed)
            x = x + rng.normal(0.0, noise_mm / 1000.0, x.shape)
        return Trajectory(
            positions=x,
            mask=np.ones(x.shape[:2], bool),
            markers=self.markers,
            rate=self.rate,
            source_units="m",
        )

    def in_contact(self) -> np.ndarray:
        """[F, 2] whether each particle is below the plane."""
        return self.positions[..., 2] < self.values["ground.height"]

    def sticking(self, speed: float = 0.01) -> np.ndarray:
        """[F, 2] in contact and sliding slower than ``speed`` (m/s)."""
        vt = np.linalg.norm(self.velocities[..., :2], axis=-1)
        return self.in_contact() & (vt < speed)

    def model_toml(self, values: str = "start") -> str:
        """The activebonds model of the same family: body mass fixed, the rest free within
        :data:`BOUNDS`, from :data:`START` (``"start"``) or the truth (``"truth"``)."""
        src = {"start": START, "truth": self.values}[values]

        def free(key):
            lo, hi = BOUNDS[key]
            return f"{{ value = {src[key]!r}, min = {lo!r}, max = {hi!r} }}"

        contact = "\n".join(
            f"""
[[bond]]
kind = "contact"
type = "ground"
particles = ["{name}"]
normal = [0.0, 0.0, 1.0]
height = {free("ground.height")}
stiffness = {free("ground.stiffness")}
damping = {free("ground.damping")}
friction = {free("ground.friction")}
"""
            for name in self.markers
        )
        b, f = self.positions[0], self.velocities[0]
        return f"""# A hopper (tests/hopper_truth.py); values: {values}.
name = "hopper"
dimension = 3
gravity = [0.0, 0.0, {-G!r}]

[[particle]]
name = "body"
mass = {self.values["body_mass"]!r}
position = {list(map(float, b[0]))}
velocity = {list(map(float, f[0]))}

[[particle]]
name = "foot"
mass = {free("foot_mass")}
position = {list(map(float, b[1]))}
velocity = {list(map(float, f[1]))}

[[bond]]
kind = "binary"
type = "leg"
particles = ["body", "foot"]
stiffness = {free("leg.stiffness")}
rest_length = {free("leg.rest_length")}
damping = {free("leg.damping")}
{contact}"""


def integrate_numpy(x, v, n_frames: int, per_frame: int, step: float, p: dict = TRUTH):
    """Semi-implicit Euler with :func:`forces`: ``n_frames`` samples (positions, velocities
    [n_frames, 2, 3], the first the given state), ``per_frame`` steps apart."""
    m = np.array([p["body_mass"], p["foot_mass"]])[:, None]
    x, v = np.array(x, np.float64), np.array(v, np.float64)
    xs, vs = [x.copy()], [v.copy()]
    for _ in range(n_frames - 1):
        for _ in range(per_frame):
            v = v + step * forces(x, v, p) / m
            x = x + step * v
        xs.append(x.copy())
        vs.append(v.copy())
    return np.array(xs), np.array(vs)


def integrate(x, v, n_frames: int, per_frame: int, step: float, p: dict = TRUTH):
    """:func:`integrate_numpy` written out on Python floats, the same operations in the same
    order (so the same numbers to the bit; tests/test_hopper_recovery.py checks it), about 30
    times faster than NumPy on arrays of two particles."""
    mb, mf = p["body_mass"], p["foot_mass"]
    k, l0, c = p["leg.stiffness"], p["leg.rest_length"], p["leg.damping"]
    h, kg, cg, mu = (
        p["ground.height"],
        p["ground.stiffness"],
        p["ground.damping"],
        p["ground.friction"],
    )
    gb, gf, eps2 = -(mb * G), -(mf * G), EPS**2
    (bx, by, bz), (fx, fy, fz) = (map(float, row) for row in x)
    (ubx, uby, ubz), (ufx, ufy, ufz) = (map(float, row) for row in v)
    sqrt = math.sqrt
    xs = [[[bx, by, bz], [fx, fy, fz]]]
    vs = [[[ubx, uby, ubz], [ufx, ufy, ufz]]]
    for _ in range(n_frames - 1):
        for _ in range(per_frame):
            dx, dy, dz = fx - bx, fy - by, fz - bz
            length = sqrt(dx * dx + dy * dy + dz * dz)
            ux, uy, uz = dx / length, dy / length, dz / length
            t = k * (length - l0) + c * ((ufx - ubx) * ux + (ufy - uby) * uy + (ufz - ubz) * uz)
            fbx, fby, fbz = t * ux, t * uy, gb + t * uz  # leg and gravity
            ffx, ffy, ffz = -(t * ux), -(t * uy), gf - t * uz
            depth = h - bz  # the ground, where a particle is below it
            if depth > 0.0:
                fn = max(0.0, kg * depth - cg * ubz)
                drag = mu * fn / sqrt(ubx * ubx + uby * uby + 0.0 + eps2)
                fbx, fby, fbz = fbx - drag * ubx, fby - drag * uby, fbz + fn
            depth = h - fz
            if depth > 0.0:
                fn = max(0.0, kg * depth - cg * ufz)
                drag = mu * fn / sqrt(ufx * ufx + ufy * ufy + 0.0 + eps2)
                ffx, ffy, ffz = ffx - drag * ufx, ffy - drag * ufy, ffz + fn
            ubx, uby, ubz = ubx + step * fbx / mb, uby + step * fby / mb, ubz + step * fbz / mb
            ufx, ufy, ufz = ufx + step * ffx / mf, ufy + step * ffy / mf, ufz + step * ffz / mf
            bx, by, bz = bx + step * ubx, by + step * uby, bz + step * ubz
            fx, fy, fz = fx + step * ufx, fy + step * ufy, fz + step * ufz
        xs.append([[bx, by, bz], [fx, fy, fz]])
        vs.append([[ubx, uby, ubz], [ufx, ufy, ufz]])
    return np.array(xs), np.array(vs)


@lru_cache(maxsize=4)
def hopper(seconds: float = 2.5, rate: float = 200.0, step: float = 1e-5) -> HopperTruth:
    """Simulate the hopper of :data:`TRUTH` from :data:`X0`, :data:`V0`."""
    per_frame = int(round(1.0 / (rate * step)))
    n_frames = int(round(seconds * rate)) + 1
    xs, vs = integrate(X0, V0, n_frames, per_frame, step)
    return HopperTruth(xs, vs, rate, step)
