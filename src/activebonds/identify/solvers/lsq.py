"""Exact least squares for the parameters that enter the one-step prediction linearly.

With one-substep semi-implicit Euler and horizon 1, the prediction of frame t + 1 is
``x_t + dt v_t + dt^2 F(x_t, v_t) / m`` (``v_t`` the backward difference), and the forces of
the *linear families* are linear in a reparametrisation of their parameters. Each bond kind
says how it enters (``kind.linear``, :mod:`activebonds.bonds`), for example:

* binary bonds (the passive part): tension ``k L - (k l0) + c Ldot``, unknowns ``(k, k l0, c)``;
* unary springs and dampers: ``-k x + (k a) - c v``, unknowns ``(k, k a, c)``.

The rest (fixed parameters, the uniform field, fixed flexion springs) is a known offset; the
bounds ``l0 in [lo, hi]`` become the linear constraints ``k lo <= k l0 <= k hi``. So the best
parameters of such a model are a convex, linearly constrained least-squares problem, solved
exactly here (scipy): the optimum the ES should reach, a floor for any model of these
families, and a starting individual for the ES (``--init lsq``).

Masses, which enter as ``m a = F``, are identified in the *equation-error* form (the force
balance at each recorded frame, linear in masses and parameters jointly) when a total mass
or one particle's mass fixes the scale: :func:`equation_error_fit`.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import partial

import jax
import jax.numpy as jnp
import numpy as np
from scipy.linalg import lstsq, qr, solve_triangular
from scipy.optimize import LinearConstraint, lsq_linear, minimize, nnls

from ... import bonds
from ...errors import InputError
from ...model import Gene, Model
from ...model.params import Params
from ...physics.forces import total_force
from ..costs.windows import Windows, start_phases
from .lsq_blocks import blocks


@dataclass(frozen=True)
class LinearProblem:
    """Columns of the linear unknowns (one row per predicted coordinate that counts)."""

    columns: np.ndarray  # [R, K] displacement per unit of each unknown
    offset: np.ndarray  # [R] displacement of the known forces
    target: np.ndarray  # [R] recorded minus force-free prediction
    names: tuple[str, ...]  # unknown k: "gene:i" (a gene itself) or "product:i*j" (gene i x j)
    lower: np.ndarray  # [K] natural units
    upper: np.ndarray
    pairs: tuple[tuple[int, int, float, float], ...]  # (k of K, k of K*x, x_lo, x_hi)
    n_terms: int  # predicted particle positions (the cost's terms)


@dataclass(frozen=True)
class LinearFit:
    """The bounded least-squares optimum over a model's linear genes."""

    values: dict[int, float]  # gene index -> natural value
    genome: np.ndarray  # [G] search space; non-linear genes at the file's values, gains at 0
    cost: float  # summed squared one-step error (m^2), as the ES's cost
    rms_mm: float
    exact: bool  # True: optimum of the convex problem (False: the solver's best point)


def _linear_fields(kind: str) -> frozenset[str]:
    part = bonds.get(kind).linear
    return frozenset() if part is None else part.fields


def nonlinear_genes(model: Model) -> list[int]:
    """The genes outside the linear families (neural terms, masses, flexion springs): where
    there is one, the least-squares optimum is no optimum of the model's own family. Each
    kind says which of its fields are linear (``kind.linear.fields``); a free gravity
    magnitude is linear (m_p n per unit of it), a mass is not."""
    return [g for g, gene in enumerate(model.layout.genes) if not _is_linear(gene)]


def _is_linear(gene: Gene) -> bool:
    if gene.owner == "gravity":
        return True
    return gene.kind is not None and gene.field in _linear_fields(gene.kind)


def _switched_value(gene: Gene, g: int, layout, off: Params) -> float | None:
    """The value its kind's ``switch_off`` gives gene ``g`` (a neuron's gain: 0), or None if
    the kind leaves it as it is."""
    where = np.asarray(layout.index.bonds[gene.kind][gene.field]) == g
    now = np.asarray(layout.base.bonds[gene.kind][gene.field])[where]
    new = np.asarray(off.bonds[gene.kind][gene.field])[where]
    changed = new != now
    return float(new[changed][0]) if changed.any() else None


def _free(index) -> bool:
    return bool((np.asarray(index) >= 0).any())


def _switched_off(model: Model) -> Params:
    """Model parameters with every linear unknown's term removed, neural gains at 0."""
    layout, topo = model.layout, model.topology
    base, index = layout.base, layout.index
    values = {
        kind: {f: np.array(a, np.float64, copy=True) for f, a in fields.items()}
        for kind, fields in base.bonds.items()
    }
    if _free(index.mass):
        raise InputError(
            model.name,
            "least squares: free masses do not enter linearly; give every mass a number in "
            "the model file, or fit without --init lsq (the search finds the masses)",
        )
    for name in topo.active():
        kind = bonds.get(name)
        if kind.linear is None:
            if any(_free(a) for a in index.bonds[name].values()):
                raise InputError(
                    model.name, f"least squares: free {kind.what} do not enter linearly"
                )
            continue
        try:
            values[name] = kind.linear.switch_off(
                values[name], index.bonds[name], topo.bonds[name], layout.genes
            )
        except ValueError as err:
            raise InputError(model.name, str(err)) from None
    gravity = np.array(base.gravity, np.float64)
    if layout.gravity_direction is not None:  # a free magnitude: a column of its own
        gravity[:] = 0.0
    return Params(mass=np.array(base.mass, np.float64), gravity=gravity, bonds=values)


class _Unknowns:
    """The columns of the linear unknowns being built, and the known forces."""

    def __init__(self, model: Model, known: np.ndarray, time: np.ndarray, phase=None):
        self.model, self.known = model, known
        self.time = time  # [S] the time of each start (forces that depend on time)
        # [S] an entrained drive's phase at each start, tracked along the record at the
        # model's fixed drive numbers (None without one)
        self.phase = phase
        self.cols: dict[str, np.ndarray] = {}
        self.bounds: dict[str, tuple[float, float]] = {}
        self.pairs: list[tuple[str, str, float, float]] = []

    def _name(self, g: int) -> str:
        name = f"gene:{g}"
        if name not in self.cols:
            genes = self.model.layout.genes
            self.cols[name] = np.zeros(self.known.shape)
            self.bounds[name] = (genes[g].lower, genes[g].upper)
        return name

    def gene(self, g: int) -> np.ndarray:
        """The column of gene ``g`` itself (a force per unit of it, [S, P, D])."""
        return self.cols[self._name(g)]

    def product(self, gk: int, gx: int) -> np.ndarray:
        """The column of the product of genes ``gk`` (a stiffness, >= 0) and ``gx``."""
        name = f"product:{gk}*{gx}"
        if name not in self.cols:
            genes = self.model.layout.genes
            klo, khi = genes[gk].lower, genes[gk].upper
            if klo < 0:
                raise InputError(
                    self.model.name,
                    f"least squares: {genes[gk].name} may be negative (min {klo}); "
                    "the bounds of k x need k >= 0",
                )
            xlo, xhi = genes[gx].lower, genes[gx].upper
            corners = [a * b for a in (klo, khi) for b in (xlo, xhi)]
            self.cols[name] = np.zeros(self.known.shape)
            self.bounds[name] = (min(corners), max(corners))
            self.pairs.append((self._name(gk), name, xlo, xhi))
        return self.cols[name]


@partial(jax.jit, static_argnums=1)
def _known_forces(params: Params, topo, x, v, times):
    """The forces of everything that is not a linear unknown, at every restart state: one
    compiled call (op by op, each of the force's primitives would compile on its own)."""
    return jax.vmap(lambda a, b, t: total_force(params, topo, a, b, t))(x, v, times)


def _start_phases(model: Model, windows: Windows) -> np.ndarray | None:
    """An entrained drive's phase at each start [S], tracked along the record at the model's
    (fixed) frequency, gain and start phase; None without one."""
    with jax.enable_x64(True):  # the signals and the phase in double precision
        tracker = start_phases(model, windows, 1)
        if tracker is None:
            return None
        params = jax.tree_util.tree_map(lambda a: jnp.asarray(a, jnp.float64), model.params)
        return np.asarray(tracker(params)[1], np.float64)


def linear_problem(model: Model, windows: Windows) -> LinearProblem:
    """The one-step cost of ``windows`` (horizon 1) as ``|columns @ theta + offset - target|^2``
    over the model's linear unknowns."""
    if windows.horizon != 1:
        raise InputError("--horizon", "least squares needs the one-step cost (horizon 1)")
    layout, topo = model.layout, model.topology
    base, index = layout.base, layout.index
    off_params = _switched_off(model)
    x, v, dt = windows.x0, windows.v0, windows.dt
    n_s, n_p, d = x.shape
    # A switched-off linear kind exerts no force (kind.LinearPart); the known forces are those
    # of the other kinds and of a fixed field, computed only if there are any.
    if all(bonds.get(k).linear is not None for k in topo.active()) and not np.any(
        off_params.gravity
    ):
        known = np.zeros(x.shape, np.float64)
    else:
        with jax.enable_x64(True):  # scoped: the process-wide setting is left as it was
            known = _known_forces(
                off_params, topo, jnp.asarray(x), jnp.asarray(v), jnp.asarray(windows.times)
            )
            known = np.array(known, np.float64)  # [S, P, D], a writable copy

    unknowns = _Unknowns(model, known, windows.times, _start_phases(model, windows))
    for name in topo.active():
        kind = bonds.get(name)
        if kind.linear is not None:
            kind.linear.columns(
                base.bonds[name], index.bonds[name], topo.bonds[name], x, v, unknowns
            )
    if layout.gravity_direction is not None:  # F_p += m_p n g: linear in the magnitude g
        column = unknowns.gene(int(np.asarray(index.gravity)[0]))
        column += np.asarray(base.mass, np.float64)[None, :, None] * layout.gravity_direction
    cols, bounds, pairs = unknowns.cols, unknowns.bounds, unknowns.pairs

    # A gene that multiplies a free stiffness in one bond and a fixed one in another (bonds of
    # one type may mix free and fixed stiffness) enters bilinearly: not this solver's problem.
    partners = {int(n.split("*")[1]) for n in cols if n.startswith("product:")}
    plain = {int(n[5:]) for n in cols if n.startswith("gene:")}
    if partners & plain:
        g = layout.genes[min(partners & plain)]
        raise InputError(
            model.name,
            f"least squares: {g.name} multiplies a free stiffness in one bond and a fixed one "
            "in another (not linear); make the stiffness free or fixed in every bond of the type",
        )
    rows = np.repeat(windows.weight[:, 0] > 0, d, axis=-1).reshape(n_s, n_p, d).ravel()
    scale = dt**2 / np.asarray(base.mass, np.float64)[None, :, None]
    names = tuple(cols)
    columns = np.zeros((int(rows.sum()), len(names)))  # no linear unknown: no column
    for k, n in enumerate(names):  # each unknown's forces freed once it is a column
        columns[:, k] = (cols.pop(n) * scale).ravel()[rows]
    target = (windows.target[:, 0] - (x + dt * v)).ravel()[rows]
    position = {n: k for k, n in enumerate(names)}
    return LinearProblem(
        columns=columns,
        offset=(known * scale).ravel()[rows],
        target=target,
        names=names,
        lower=np.array([bounds[n][0] for n in names]),
        upper=np.array([bounds[n][1] for n in names]),
        pairs=tuple((position[a], position[b], lo, hi) for a, b, lo, hi in pairs),
        n_terms=windows.n_terms,
    )


def compress(a: np.ndarray, rhs: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``(r, c)`` with ``|r t - c|^2 = |a t - rhs|^2`` for every ``t``, at most K + 1 rows: the
    triangular factor of the QR decomposition of ``[a | rhs]`` (its last row holds the part of
    ``rhs`` no combination of the columns reaches). One O(R K^2) factorisation; every solve
    after it works on the small system, and a subset of the unknowns on a subset of its
    columns (the columns of ``a`` are ``Q r``)."""
    if a.shape[0] <= a.shape[1] + 1:
        return a, rhs
    augmented = np.empty((a.shape[0], a.shape[1] + 1), order="F")
    augmented[:, :-1], augmented[:, -1] = a, rhs
    factor = qr(augmented, mode="r", overwrite_a=True, check_finite=False)[0][: a.shape[1] + 1]
    return factor[:, :-1], factor[:, -1]


def _lstsq(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """The (minimum-norm) least-squares solution: by back substitution when ``a`` is a
    well-conditioned triangular factor (as :func:`compress` gives), else by a rank-revealing
    QR (LAPACK gelsy)."""
    n = a.shape[1]
    # rows below the square: zero in a compressed factor, not in a subset of its columns
    if a.shape[0] >= n and not np.tril(a[:n], -1).any() and not a[n:].any():
        diag = np.abs(np.diag(a))
        if n and diag.min() > 1e-10 * diag.max():
            return solve_triangular(a[:n], b[:n], check_finite=False)
    return lstsq(a, b, lapack_driver="gelsy", check_finite=False)[0]


def solve(problem: LinearProblem, bounded: bool = True) -> tuple[np.ndarray, bool]:
    """The least-squares unknowns (natural units) and whether the optimum is exact; block by
    block where the problem falls apart (:func:`~.lsq_blocks.blocks`: the same optimum),
    each block as :func:`_solve_block` solves it."""
    parts = blocks(problem.columns, problem.pairs)
    if len(parts) == 1:
        return _solve_block(problem, bounded)
    theta, exact = np.zeros(problem.columns.shape[1]), True
    place = np.full(len(theta), -1)
    for rows, unknowns in parts:
        place[unknowns] = np.arange(len(unknowns))
        pairs = tuple((place[k], place[p], lo, hi) for k, p, lo, hi in problem.pairs
                      if place[k] >= 0)  # fmt: skip
        sub = LinearProblem(
            columns=problem.columns[np.ix_(rows, unknowns)],
            offset=problem.offset[rows],
            target=problem.target[rows],
            names=tuple(problem.names[k] for k in unknowns),
            lower=problem.lower[unknowns],
            upper=problem.upper[unknowns],
            pairs=pairs,
            n_terms=problem.n_terms,
        )
        theta[unknowns], ok = _solve_block(sub, bounded)
        exact = exact and ok
        place[unknowns] = -1
    return theta, exact


def _solve_block(problem: LinearProblem, bounded: bool = True) -> tuple[np.ndarray, bool]:
    """The least-squares unknowns (natural units) and whether the optimum is exact.

    The system is compressed first (:func:`compress`, the same cost in K + 1 rows), its
    columns scaled to unit norm. The unconstrained optimum is kept if it is feasible.
    Otherwise, with products, the linearly constrained problem (bounds and ``k lo <= k x <=
    k hi``) is solved as a least distance problem (Lawson & Hanson, ch. 23: one NNLS on the
    constraints, exact when the system has full rank); without products, or where the system
    is rank-deficient, the box problem (product bounds relaxed to their corners) is solved
    by BVLS, then, if its solution breaks a product constraint, the constrained problem by
    SLSQP from there. That point then fixes the active set (unknowns at a bound, products at
    ``k lo`` or ``k hi``), on which the equality-constrained problem is solved directly: the
    optimum to machine precision, kept if feasible and no worse."""
    a = problem.columns
    rhs = problem.target - problem.offset
    if a.shape[1] == 0:
        return np.zeros(0), True
    if a.shape[0] == 0:  # unknowns no prediction sees: any value in the bounds
        return np.clip(0.0, problem.lower, problem.upper), True
    norm = np.linalg.norm(a, axis=0)
    norm = np.where(norm > 0, norm, 1.0)
    a_s, c = compress(a / norm, rhs)  # scaled columns, compressed
    free = _lstsq(a_s, c)
    if not bounded:
        return free / norm, True
    lo, hi = problem.lower * norm, problem.upper * norm
    inside = bool(np.all((free >= lo) & (free <= hi)))
    theta = free / norm
    if not inside or _violation(problem, theta) > 1e-12:
        z = _least_distance(problem, a_s, c, norm) if problem.pairs else None
        if z is not None:
            theta = _feasible(problem, z / norm)
        else:
            if not inside:  # BVLS returns the unconstrained optimum when it is inside
                box = lsq_linear(a_s, c, bounds=(lo, hi), method="bvls", tol=1e-14, lsmr_tol=None)
                theta = box.x / norm
            if _violation(problem, theta) > 1e-12:
                theta = _slsqp(problem, a_s, c, norm, theta)
    polished = _polish(problem, a_s * norm, c, theta)  # the compressed system, natural units
    # on noiseless data both costs are rounding (|residual| ~ 1e-15 |rhs|): within that, the
    # polished point, the optimum of its active set, is kept
    cost = lambda t: float(np.sum((a @ t - rhs) ** 2))  # noqa: E731
    rounding = (1e-13 * np.linalg.norm(rhs)) ** 2
    if polished is not None and cost(polished) <= cost(theta) * (1 + 1e-12) + rounding:
        return polished, True
    return theta, False


def _feasible(problem: LinearProblem, t: np.ndarray) -> np.ndarray:
    """``t`` moved onto its bounds and product constraints where rounding left it outside
    (the least distance solution holds its active constraints to ~1e-13, not exactly)."""
    t = np.clip(t, problem.lower, problem.upper)
    for k, p, xlo, xhi in problem.pairs:
        t[p] = min(max(t[p], t[k] * xlo), t[k] * xhi)
    return t


def _violation(problem: LinearProblem, t: np.ndarray) -> float:
    """Largest relative breach of a product constraint ``k lo <= p <= k hi``."""
    worst = 0.0
    for k, p, xlo, xhi in problem.pairs:
        scale = max(abs(t[k]) * max(xhi - xlo, abs(xhi), abs(xlo)), 1e-300)
        worst = max(worst, (t[k] * xlo - t[p]) / scale, (t[p] - t[k] * xhi) / scale)
    return worst


def _constraints(problem: LinearProblem, norm: np.ndarray, einv: np.ndarray):
    """``(g einv, h)`` for the constraints ``g z >= h`` on the scaled unknowns ``z = theta *
    norm``: the finite bounds (a product's only where it has no pair: ``k lo <= p <= k hi``
    with ``k >= 0`` in its bounds implies them) and, for each product, ``p - k lo >= 0`` and
    ``k hi - p >= 0``. The rows of ``g`` hold one or two entries, so ``g einv`` is built from
    rows of ``einv`` directly."""
    lo, hi = problem.lower * norm, problem.upper * norm
    paired = np.zeros(len(norm), bool)
    paired[[p for _, p, _, _ in problem.pairs]] = True
    low = np.isfinite(lo) & ~paired
    high = np.isfinite(hi) & ~paired
    rows = [einv[low], -einv[high]]
    h = [lo[low], -hi[high]]
    if problem.pairs:
        k, p, xlo, xhi = (np.array(v) for v in zip(*problem.pairs, strict=True))
        kk, pp = einv[k] / norm[k, None], einv[p] / norm[p, None]
        rows += [pp - xlo[:, None] * kk, xhi[:, None] * kk - pp]
        h.append(np.zeros(2 * len(k)))
    return np.concatenate(rows), np.concatenate(h)


def _least_distance(problem, a_s, rhs, norm):
    """The linearly constrained optimum in the scaled unknowns, or None where the system is
    rank-deficient (or the solve fails): min |e z - f| subject to g z >= h, ``e`` the square
    upper triangular factor (Lawson & Hanson, Solving Least Squares Problems, ch. 23). With
    ``y = e z - f`` it is min |y| subject to ``g e^-1 y >= h - g e^-1 f``, whose solution is
    the normalised residual of one NNLS problem on the constraints."""
    n = len(norm)
    if a_s.shape[0] < n or np.tril(a_s[:n], -1).any():
        return None
    e, f = a_s[:n], rhs[:n]  # the rows after n do not depend on z
    diag = np.abs(np.diag(e))
    if diag.min() <= 1e-10 * diag.max():
        return None
    einv = solve_triangular(e, np.eye(n), check_finite=False)
    ginv, h = _constraints(problem, norm, einv)
    b = h - ginv @ f
    design = np.vstack([ginv.T, b[None, :]])  # [n + 1, constraints]
    target = np.zeros(n + 1)
    target[n] = 1.0
    try:
        u, _ = nnls(design, target, maxiter=50 * design.shape[1])
    except RuntimeError:  # too many iterations
        return None
    resid = design @ u - target
    if not np.isfinite(resid).all() or abs(resid[n]) < 1e-12:
        return None  # infeasible (cannot happen for consistent bounds) or a failed solve
    y = -resid[:n] / resid[n]
    return einv @ (y + f)


def _slsqp(problem, a_s, rhs, norm, theta):
    lo, hi = problem.lower * norm, problem.upper * norm
    rows = []
    for k, p, xlo, xhi in problem.pairs:
        r1, r2 = np.zeros(len(norm)), np.zeros(len(norm))
        r1[p], r1[k] = 1.0 / norm[p], -xlo / norm[k]
        r2[p], r2[k] = -1.0 / norm[p], xhi / norm[k]
        rows += [r1, r2]
    h, g = a_s.T @ a_s, a_s.T @ rhs
    res = minimize(
        lambda z: 0.5 * z @ h @ z - g @ z,
        np.clip(theta * norm, lo, hi),
        jac=lambda z: h @ z - g,
        method="SLSQP",
        bounds=list(zip(lo, hi, strict=True)),
        constraints=[LinearConstraint(np.asarray(rows), 0.0, np.inf)],
        options={"ftol": 1e-16, "maxiter": 1000},
    )
    return res.x / norm


def _polish(problem: LinearProblem, a, rhs, theta, tol: float = 1e-7):
    """The equality-constrained optimum on ``theta``'s active set, or None if infeasible."""
    n = len(theta)
    lo, hi = problem.lower, problem.upper
    span = np.maximum(hi - lo, 1e-300)
    fixed = np.full(n, np.nan)
    fixed[np.abs(theta - lo) <= tol * span] = lo[np.abs(theta - lo) <= tol * span]
    fixed[np.abs(theta - hi) <= tol * span] = hi[np.abs(theta - hi) <= tol * span]
    ratio = {}  # product unknown -> (its k unknown, pinned x)
    for k, p, xlo, xhi in problem.pairs:
        x = theta[p] / theta[k] if theta[k] != 0 else np.nan
        for bound in (xlo, xhi):
            if np.isfinite(x) and abs(x - bound) <= tol * max(xhi - xlo, 1e-300):
                ratio[p] = (k, bound)
    # theta = base + t_map @ psi over the free unknowns psi
    free = [i for i in range(n) if np.isnan(fixed[i]) and i not in ratio]
    t_map = np.zeros((n, len(free)))
    base = np.where(np.isnan(fixed), 0.0, fixed)
    for col, i in enumerate(free):
        t_map[i, col] = 1.0
    for p, (k, x) in ratio.items():
        base[p] = x * base[k] if not np.isnan(fixed[k]) else 0.0
        t_map[p] = x * t_map[k]
    out = base.copy()
    if free:
        m = a @ t_map
        scale = np.linalg.norm(m, axis=0)
        scale = np.where(scale > 0, scale, 1.0)
        psi = _lstsq(m / scale, rhs - a @ base)
        out = base + t_map @ (psi / scale)
    feasible = np.all(out >= lo - 1e-12 * span) and np.all(out <= hi + 1e-12 * span)
    return out if feasible and _violation(problem, out) <= 1e-12 else None


def least_squares(model: Model, windows: Windows, bounded: bool = True) -> LinearFit:
    """The exact (bounded) least-squares optimum of ``model``'s linear genes on ``windows``
    (one-substep Euler, horizon 1), neural gains at 0, other genes at the file's values."""
    problem = linear_problem(model, windows)
    theta, exact = solve(problem, bounded)
    layout = model.layout
    values = _gene_values(problem, theta, layout)
    natural = layout.natural(layout.initial())
    for g, gene in enumerate(layout.genes):
        if g in values:
            natural[g] = min(max(values[g], gene.lower), gene.upper)
    off = _switched_off(model)  # the non-linear terms as the kinds switch them off
    for g in nonlinear_genes(model):
        gene = layout.genes[g]
        switched = None if gene.kind is None else _switched_value(gene, g, layout, off)
        if switched is not None:  # e.g. the neurons off: their gains at 0
            natural[g] = switched
    genome = np.where(layout.log, np.log(np.maximum(natural, 1e-300)), natural)
    resid = problem.columns @ theta + problem.offset - problem.target
    cost = float(resid @ resid)
    rms = float(np.sqrt(cost / max(problem.n_terms, 1)) * 1000.0)
    return LinearFit(values=values, genome=genome, cost=cost, rms_mm=rms, exact=exact)


@dataclass(frozen=True)
class EquationErrorFit:
    masses: np.ndarray  # [P] kg
    values: dict[int, float]  # linear gene index -> natural value (unbounded)
    rms_force: float  # RMS force-balance residual (N)


def equation_error_fit(
    model: Model, windows: Windows, total_mass: float | None = None
) -> EquationErrorFit:
    """Masses and linear parameters from the force balance ``m_p a_p = F_p`` at each frame,
    with ``a_p = (x_{t+1} - 2 x_t + x_{t-1}) / dt^2`` (exact for one-substep Euler): linear and
    homogeneous in (masses, parameters), so the scale comes from the fixed masses or from
    ``total_mass`` (sum of all masses). Unbounded; every term of the balance counts alike."""
    layout = model.layout
    free_mass = np.asarray(layout.index.mass) >= 0
    if not free_mass.any():
        raise InputError(model.name, "equation_error_fit: no free mass")
    if layout.gravity_direction is not None:
        raise InputError(
            model.name, "equation_error_fit: a free gravity with free masses is not linear"
        )
    if total_mass is None:
        total_mass = model.spec.total_mass
    if free_mass.all() and total_mass is None:
        raise InputError(model.name, "every mass is free: give the total mass")
    from ...model.model import build

    particles = [p.model_copy(update={"mass": 1.0}) for p in model.spec.particle]
    unit = build(model.spec.model_copy(update={"particle": particles}), disable=model.disabled)
    problem = linear_problem(unit, windows)  # masses 1: columns and offset are forces * dt^2
    dt = windows.dt
    n_s, n_p, d = windows.x0.shape
    rows = np.repeat(windows.weight[:, 0] > 0, d, axis=-1).reshape(n_s, n_p, d).ravel()
    # the field acts as m g, so it joins the mass columns: m_p (a_p - g) = F_internal
    gravity = np.asarray(layout.base.gravity, np.float64)
    field = dt**2 * np.broadcast_to(gravity, (n_s, n_p, d)).ravel()[rows]
    internal_known = problem.offset - field
    particle = np.broadcast_to(np.arange(n_p)[None, :, None], (n_s, n_p, d)).ravel()[rows]
    mass_cols = np.stack(
        [np.where(particle == p, problem.target - field, 0.0) for p in range(n_p)], axis=1
    )
    masses = np.asarray(layout.base.mass, np.float64).copy()
    # mass_cols @ m - columns @ theta = internal_known
    rhs = internal_known - mass_cols[:, ~free_mass] @ masses[~free_mass]
    a = np.concatenate([mass_cols[:, free_mass], -problem.columns], axis=1)
    n_free = int(free_mass.sum())
    if total_mass is not None:
        # the free masses sum to the total less the fixed ones: eliminate the last free mass
        rest = float(total_mass) - masses[~free_mass].sum()
        last = a[:, n_free - 1].copy()
        reduced = np.delete(a, n_free - 1, axis=1)
        reduced[:, : n_free - 1] -= last[:, None]
        sol, *_ = np.linalg.lstsq(reduced, rhs - last * rest, rcond=None)
        sol = np.insert(sol, n_free - 1, rest - sol[: n_free - 1].sum())
    else:
        sol, *_ = np.linalg.lstsq(a, rhs, rcond=None)
    masses[free_mass] = sol[:n_free]
    theta = sol[n_free:]
    resid = (a @ sol - rhs) / dt**2
    by_name = {g.name: i for i, g in enumerate(layout.genes)}
    unit_values = _gene_values(problem, theta, unit.layout)
    values = {by_name[unit.layout.genes[g].name]: v for g, v in unit_values.items()}
    return EquationErrorFit(
        masses=masses, values=values, rms_force=float(np.sqrt(np.mean(resid**2)))
    )


def _gene_values(problem: LinearProblem, theta: np.ndarray, layout) -> dict[int, float]:
    """Gene index -> natural value from the unknowns (``k l0`` divided back by ``k``)."""
    values: dict[int, float] = {}
    for n, t in zip(problem.names, theta, strict=True):
        if n.startswith("gene:"):
            values[int(n[5:])] = float(t)
    for n, t in zip(problem.names, theta, strict=True):
        if n.startswith("product:"):
            gk, gx = (int(s) for s in n[8:].split("*"))
            k = values[gk]
            values[gx] = float(t / k) if k != 0 else float(layout.genes[gx].value)
    return values
