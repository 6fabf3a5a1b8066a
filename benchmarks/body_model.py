"""Large linear models for the exact least squares: a 41-marker spring body and the 7-marker
spring horse, built through the package's own API (no package code imports this file).

* :func:`body_model_toml` - OpenSim's walk (``activebonds datasets human-walk``): each of the
  41 markers a particle of mass 1 (fixed), joined by a spring-damper (binary) bond to each of
  its ``n_bonds_per_marker`` nearest markers at frame 0, pairs deduplicated (138 bonds, 414
  genes at the default 6); every bond its own stiffness, rest length and damping, free within
  bounds.
* :func:`body_case` - ``n_frames`` of the body at the walk's rate (60 Hz) SIMULATED by
  activebonds (:func:`~activebonds.simulation.simulate`, semi-implicit Euler, 10 substeps)
  from the truth (:func:`body_truth`): stiffness spread 50-500 N/m, damping 0.5-5 N s/m, rest
  lengths the frame-0 distances each scaled by a factor in [0.9, 1.1] (so the start is not at
  rest), started at the walk's frame 0 with its finite-difference velocities. The model
  returned starts at deliberately wrong values (as ``tests/mujoco_truth.py``'s ``start``).
* :func:`horse_case` - the bundled horse trot's first ``n_frames`` (all 7 markers), every pair
  joined by a spring-damper (21 bonds, 63 genes).

Everything is deterministic (fixed seeds, no clock).

    python benchmarks/body_model.py      # builds both, runs a 1-generation fit on the body
"""

from __future__ import annotations

import itertools
import math
from functools import cache

import numpy as np

from activebonds.data import Trajectory, read_trajectory
from activebonds.data.bundled import dataset
from activebonds.model import Model, loads_model
from activebonds.simulation import simulate

STIFFNESS_BOUNDS = (1.0, 5000.0)  # N/m
DAMPING_BOUNDS = (0.01, 50.0)  # N s/m
REST_LENGTH_BOUNDS = (0.5, 1.5)  # x the frame-0 distance
REST_LENGTH_START = 1.2  # x the frame-0 distance: the deliberately wrong start
STIFFNESS_RANGE = (50.0, 500.0)  # the truth
DAMPING_RANGE = (0.5, 5.0)
REST_LENGTH_JITTER = 0.1  # truth rest length = frame-0 distance x U(1 -+ this)
SUBSTEPS = 10
SEED = 41


def _num(x: float) -> str:
    return repr(float(x))


def _vec(x) -> str:
    return "[" + ", ".join(_num(v) for v in x) + "]"


@cache
def walk() -> Trajectory:
    """The bundled human walk (41 markers, 151 frames, 60 Hz, metres)."""
    return read_trajectory(dataset("human-walk").path)


def neighbour_pairs(x: np.ndarray, n_bonds_per_marker: int = 6) -> list[tuple[int, int]]:
    """Each point joined to its ``n_bonds_per_marker`` nearest (``x`` [P, D]); (i, j) with
    i < j, deduplicated, sorted."""
    d = np.linalg.norm(x[:, None] - x[None], axis=-1)
    np.fill_diagonal(d, np.inf)
    pairs = set()
    for i in range(len(x)):
        for j in np.argsort(d[i], kind="stable")[:n_bonds_per_marker]:
            pairs.add((min(i, int(j)), max(i, int(j))))
    return sorted(pairs)


def _spread(rng: np.random.Generator, lo: float, hi: float, n: int) -> np.ndarray:
    """n values spread log-evenly over [lo, hi], in random order."""
    return rng.permutation(np.geomspace(lo, hi, n))


def _truth(x0: np.ndarray, pairs) -> dict[str, np.ndarray]:
    rng = np.random.default_rng(SEED)
    n = len(pairs)
    i, j = np.array(pairs).T
    d0 = np.linalg.norm(x0[j] - x0[i], axis=-1)
    return {
        "distance": d0,
        "stiffness": _spread(rng, *STIFFNESS_RANGE, n),
        "damping": _spread(rng, *DAMPING_RANGE, n),
        "rest_length": d0 * rng.uniform(1 - REST_LENGTH_JITTER, 1 + REST_LENGTH_JITTER, n),
    }


def body_model_toml(
    traj: Trajectory | None = None,
    n_bonds_per_marker: int = 6,
    values: str = "start",
    optional: bool = False,
    rest_bounds: tuple[float, float] = REST_LENGTH_BOUNDS,
) -> str:
    """The 41-marker spring body of ``traj`` (default: the bundled walk) as a model file.

    ``values="start"``: stiffness and damping at the geometric mean of their bounds, rest
    lengths 1.2x the frame-0 distance; ``"truth"``: the values :func:`body_case` simulates.
    Particles start at frame 0 with the finite-difference velocity ``(x1 - x0) rate``.
    ``optional=True`` marks every bond a candidate (``activebonds structure``);
    ``rest_bounds`` the rest lengths' bounds relative to the frame-0 distance (narrower than
    the truth's +-10 %, e.g. (0.97, 1.03), some rest lengths are held at a bound: the
    product constraints ``k lo <= k l0 <= k hi`` of the exact least squares become active)."""
    if values not in ("start", "truth"):
        raise ValueError(f"values must be 'start' or 'truth', got {values!r}")
    traj = traj or walk()
    x0, x1 = traj.positions[0], traj.positions[1]
    v0 = (x1 - x0) * traj.rate
    pairs = neighbour_pairs(x0, n_bonds_per_marker)
    truth = _truth(x0, pairs)
    names = traj.markers
    lines = [
        f"# {len(names)} markers, each bonded to its {n_bonds_per_marker} nearest at frame 0 "
        f"({len(pairs)} spring-dampers; benchmarks/body_model.py); values: {values}.",
        'name = "body"',
        "dimension = 3",
    ]
    for p, m in enumerate(names):
        lines += [
            "",
            "[[particle]]",
            f'name = "{m}"',
            "mass = 1.0",
            f"position = {_vec(x0[p])}",
            f"velocity = {_vec(v0[p])}",
        ]
    geo = {k: math.sqrt(a * b) for k, (a, b) in (("k", STIFFNESS_BOUNDS), ("c", DAMPING_BOUNDS))}
    for b, (i, j) in enumerate(pairs):
        d0 = truth["distance"][b]
        if values == "truth":
            k, c, rest = (truth[f][b] for f in ("stiffness", "damping", "rest_length"))
        else:
            k, c, rest = geo["k"], geo["c"], min(REST_LENGTH_START, rest_bounds[1]) * d0
        lo, hi = (r * d0 for r in rest_bounds)
        lines += [
            "",
            "[[bond]]",
            'kind = "binary"',
            f'particles = ["{names[i]}", "{names[j]}"]',
            *(["optional = true"] if optional else []),
            f"stiffness = {{ value = {_num(k)}, min = {_num(STIFFNESS_BOUNDS[0])}, "
            f"max = {_num(STIFFNESS_BOUNDS[1])} }}",
            f"rest_length = {{ value = {_num(rest)}, min = {_num(lo)}, max = {_num(hi)} }}",
            f"damping = {{ value = {_num(c)}, min = {_num(DAMPING_BOUNDS[0])}, "
            f"max = {_num(DAMPING_BOUNDS[1])} }}",
        ]
    return "\n".join(lines) + "\n"


@cache
def _truth_model() -> Model:
    return loads_model(body_model_toml(values="truth"), "<body truth>")


def body_truth() -> np.ndarray:
    """The true natural values [G] of the body model's genes (the order of
    ``model.layout.genes``; the same for every ``n_frames``)."""
    layout = _truth_model().layout
    return np.asarray(layout.natural(layout.initial()), np.float64)


@cache
def _body_recording(n_frames: int) -> Trajectory:
    return simulate(_truth_model(), n_frames, walk().rate, substeps=SUBSTEPS)


def body_case(n_frames: int = 151, optional: bool = False) -> tuple[Model, Trajectory]:
    """The body model at its wrong start and ``n_frames`` frames simulated from the truth
    (:func:`body_truth`) at the walk's rate, 10 substeps."""
    model = loads_model(body_model_toml(optional=optional), "<body>")
    return model, _body_recording(n_frames)


def horse_toml(traj: Trajectory) -> str:
    """The 7 markers of ``traj``, every pair joined by a spring-damper (mass 1 each, fixed);
    rest lengths start at the recording's mean distance, bounds +-50 %."""
    names = traj.markers
    lines = [
        f"# {len(names)} markers, every pair a spring-damper (benchmarks/body_model.py)",
        'name = "horse_springs"',
        "dimension = 3",
    ]
    for m in names:
        lines += ["", "[[particle]]", f'name = "{m}"', "mass = 1.0"]
    for a, b in itertools.combinations(range(len(names)), 2):
        ok = traj.mask[:, a] & traj.mask[:, b]
        d = traj.positions[ok, b] - traj.positions[ok, a]
        rest = float(np.mean(np.linalg.norm(d, axis=-1)))
        lines += [
            "",
            "[[bond]]",
            'kind = "binary"',
            f'particles = ["{names[a]}", "{names[b]}"]',
            "stiffness = { value = 70.0, min = 1.0, max = 5000.0 }",
            f"rest_length = {{ value = {_num(rest)}, min = {_num(0.5 * rest)}, "
            f"max = {_num(1.5 * rest)} }}",
            "damping = { value = 0.7, min = 0.01, max = 50.0 }",
        ]
    return "\n".join(lines) + "\n"


def horse_case(n_frames: int = 600) -> tuple[Model, Trajectory]:
    """The 21-spring horse on the bundled trot's first ``n_frames`` frames (7 markers)."""
    trot = read_trajectory(dataset("horse-trot").path)
    traj = trot.window(0, n_frames)
    return loads_model(horse_toml(traj), "<horse springs>"), traj


def main() -> None:
    import time

    import activebonds

    for n in (151, 300, 600):
        t = time.perf_counter()
        model, traj = body_case(n)
        print(
            f"body {n}: {traj.positions.shape}, {model.topology.count('binary')} bonds, "
            f"{model.layout.n_genes} genes, {time.perf_counter() - t:.1f} s"
        )
    model, traj = horse_case()
    print(
        f"horse: {traj.positions.shape}, {model.topology.count('binary')} bonds, "
        f"{model.layout.n_genes} genes"
    )
    model, traj = body_case(151)
    t = time.perf_counter()
    res = activebonds.fit(model, traj, init="lsq", generations=1, refine="none")
    print(
        f"fit init=lsq generations=1 refine=none: {time.perf_counter() - t:.1f} s, RMS {res.rms_mm:.4f} mm"
    )
    truth = body_truth()
    got = model.layout.natural(res.genome)
    print(f"largest relative error to the truth: {np.max(np.abs(got / truth - 1)):.3g}")


if __name__ == "__main__":
    main()
