"""The "springs" benchmark of Kipf et al. 2018 (Neural Relational Inference, ICML), in NumPy.

A re-implementation of ``SpringSim.sample_trajectory`` (``data/synthetic_sim.py`` of
github.com/ethanfetaya/NRI) with the settings of its ``generate_dataset.py`` (``T = 5000``,
``sample_freq = 100``, ``noise_var = 0``):

* 5 unit-mass particles in 2D; each unordered pair is joined with probability 1/2 by a spring of
  zero rest length (types ``[0, 0.5, 1]`` drawn with ``p = [0.5, 0, 0.5]``, lower triangle
  mirrored, zero diagonal), force ``F_i = -0.1 * sum_j A_ij (x_i - x_j)``, clipped to +-100;
* initial positions ~ N(0, 0.5^2) per coordinate; initial velocities of random direction and norm
  exactly 0.5 per particle;
* elastic walls at +-5: a coordinate past a wall is mirrored back into the box and its velocity
  component made to point inwards;
* fine step ``dt = 0.001``: one kick ``v += dt F(x0)``, then for steps ``i = 1 .. T-1``: drift
  ``x += dt v``, wall rule, save ``x`` if ``i % 100 == 0``, kick ``v += dt F(x)``. The saved
  frames are the positions at steps 100, 200, ..., 4900 (times 0.1 .. 4.9): 49 frames, 0.1 s
  apart; the initial position is not among them (NRI writes it to slot 0, then overwrites it).

Departures: the random draws come from a ``numpy.random.Generator`` (NRI uses the legacy global
``np.random``), so the streams differ; only positions and the 0/1 edge matrix are returned; the
optional observation noise is added outside the dynamics (``dataset``).
"""

from __future__ import annotations

import numpy as np

from ..bonds import binary

FRAME_DT = 0.1  # seconds between saved frames (SAMPLE_FREQ fine steps of STEP)
BOX = 5.0  # walls at +-BOX on each axis
STRENGTH = 0.1  # spring stiffness (NRI's interaction_strength), unit masses

STEP = 0.001  # NRI's _delta_T
SAMPLE_FREQ = 100  # fine steps between saved frames
LOC_STD = 0.5
VEL_NORM = 0.5
MAX_FORCE = 0.1 / STEP  # NRI's _max_F: a per-component clip (never reached by these springs)
SPRING_TYPES = np.array([0.0, 0.5, 1.0])
SPRING_PROB = np.array([0.5, 0.0, 0.5])


def _clamp(loc: np.ndarray, vel: np.ndarray) -> None:
    """NRI's ``_clamp``, in place: mirror coordinates past a wall back in, velocity inwards."""
    farthest = np.abs(loc).max()
    if farthest <= BOX:
        return
    if farthest >= 3 * BOX:
        raise RuntimeError("springs: a particle left the box by more than two box widths")
    over = loc > BOX
    loc[over] = 2 * BOX - loc[over]
    vel[over] = -np.abs(vel[over])
    under = loc < -BOX
    loc[under] = -2 * BOX - loc[under]
    vel[under] = np.abs(vel[under])


def simulate(
    rng: np.random.Generator, n_balls: int = 5, n_frames: int = 49
) -> tuple[np.ndarray, np.ndarray]:
    """One NRI springs trajectory: positions ``[n_frames, n_balls, 2]`` and the edge matrix.

    The edge matrix ``[n_balls, n_balls]`` (int, 0/1) is symmetric with a zero diagonal. The
    fine simulation runs ``(n_frames + 1) * SAMPLE_FREQ`` steps, as NRI's ``T`` (49 frames for
    ``T = 5000``). No noise.
    """
    n = n_balls
    edges = rng.choice(SPRING_TYPES, size=(n, n), p=SPRING_PROB)
    edges = np.tril(edges) + np.tril(edges, -1).T
    np.fill_diagonal(edges, 0.0)
    # F = -k (D - A) x with D the degree matrix: -k sum_j A_ij (x_i - x_j)
    laplacian = np.diag(edges.sum(axis=1)) - edges
    coupling = -STRENGTH * laplacian

    def force(x: np.ndarray) -> np.ndarray:
        f = coupling @ x
        return np.clip(f, -MAX_FORCE, MAX_FORCE) if np.abs(f).max() > MAX_FORCE else f

    # drawn as NRI's [2, n] arrays, kept as [n, 2]
    loc = (rng.standard_normal((2, n)) * LOC_STD).T.copy()
    vel = rng.standard_normal((2, n)).T.copy()
    vel *= VEL_NORM / np.linalg.norm(vel, axis=1, keepdims=True)
    _clamp(loc, vel)

    steps = (n_frames + 1) * SAMPLE_FREQ
    out = np.empty((n_frames, n, 2))
    frame = 0
    vel += STEP * force(loc)
    for i in range(1, steps):
        loc += STEP * vel
        _clamp(loc, vel)
        if i % SAMPLE_FREQ == 0:
            out[frame] = loc
            frame += 1
        vel += STEP * force(loc)
    return out, edges.astype(int)


def dataset(n: int, seed: int, noise: float = 0.0) -> list[tuple[np.ndarray, np.ndarray]]:
    """``n`` trajectories ``(positions, edges)`` from ``np.random.default_rng(seed)``.

    ``noise`` is the standard deviation of Gaussian observation noise added to every position
    coordinate (simulation units). It is drawn from the same generator after all ``n``
    simulations, so a seed gives the same clean trajectories and graphs at every noise level.
    """
    rng = np.random.default_rng(seed)
    runs = [simulate(rng) for _ in range(n)]
    if noise > 0:
        runs = [(x + noise * rng.standard_normal(x.shape), a) for x, a in runs]
    return runs


def near_wall(positions: np.ndarray) -> np.ndarray:
    """``[F, N]`` bool: True where a particle is within ``reach`` of a wall at that frame.

    ``reach`` is the largest displacement of any particle along any axis between two consecutive
    frames of this trajectory. A bounce between frames ``t`` and ``t + 1`` happens at the wall,
    and the particle covers at most about ``reach`` per frame along an axis, so at least one of
    the two frames is within ``reach`` of that wall: every frame triple around a bounce contains
    a flagged frame. A one-step prediction across a bounce (the central second difference at such
    a triple) measures the wall's impulse, not a spring force, so those particle-frames are
    masked out of the fit.
    """
    x = np.asarray(positions, dtype=float)
    if x.shape[0] < 2:
        return np.zeros(x.shape[:2], dtype=bool)
    reach = float(np.max(np.abs(np.diff(x, axis=0))))
    return np.any(np.abs(x) > BOX - reach, axis=-1)


def candidate_model_toml(n_balls: int = 5) -> str:
    """An activebonds model file for the structure search on a springs trajectory.

    Particles ``p0 ..`` of fixed unit mass; one optional zero-rest-length, undamped binary
    spring per unordered pair, each its own type ``k{i}_{j}`` (its own stiffness gene).
    """
    lines = [
        f"# NRI springs (Kipf et al. 2018): {n_balls} unit masses, one optional spring per pair.",
        'name = "springs"',
        "dimension = 2",
    ]
    for i in range(n_balls):
        lines += ["", "[[particle]]", f'name = "p{i}"', "mass = 1.0"]
    for i in range(n_balls):
        for j in range(i + 1, n_balls):
            lines += [
                "",
                "[[bond]]",
                f'kind = "{binary.KIND.name}"',
                f'particles = ["p{i}", "p{j}"]',
                f'type = "k{i}_{j}"',
                "optional = true",
                "stiffness = { value = 0.05, min = 0.0, max = 1.0 }",
                "rest_length = 0.0",
                "damping = 0.0",
            ]
    return "\n".join(lines) + "\n"
