"""Structure identification: which optional bonds a recording needs.

Bonds marked ``optional = true`` are candidates. For models the exact least squares solves
(:mod:`.lsq`: standard bonds, unary anchors, the uniform field), the structure is chosen by
sparse regression on that exact path: **backward elimination under the Bayesian information
criterion**. Start with every candidate present; at each step, remove the candidate whose
removal gives the lowest BIC, as long as that BIC is lower than the current one; stop when
every removal raises it. With Gaussian residuals,

    BIC = n ln(RSS / n) + k ln n

(n residual coordinates, RSS the exact least-squares optimum's sum of squares, k the free
linear unknowns), with RSS floored at ``n (RESOLUTION r0)^2``, r0 the RMS residual of the
zero-force predictor (the signal the forces explain). The floor is the model's resolution: a
one-step model is a discretisation, and on noiseless data the exact sampled dynamics of
linear springs between frames is a matrix function of the true stiffness matrix, dense in
every pair (O(h^2 w^2 / 12) of the true stiffnesses on pairs with no spring), so without a
floor every candidate would "explain" a residual at machine precision and be kept. Terms
that improve the fit by less than 0.1 % of the signal are below what the model resolves.

Why this rather than SINDy's sequential thresholding (Brunton, Proctor & Kutz 2016): the
threshold on a coefficient depends on the units and the excitation of each
bond (a stiff bond that barely stretches and a soft one that stretches a lot carry the same
evidence at very different coefficients), while the BIC compares fits in one currency, the
likelihood, and each step's solve is exact, so the path is the sparse regression's own path
with a scale-free stopping rule.

Every decision carries its evidence at the final structure: the BIC difference and the
relative cost increase of removing a present bond (``delta_bic > 0`` supports it), or of
adding back an absent one (``delta_bic < 0`` supports its absence). Neural bonds need the
evolutionary route, which is not built: the model file refuses ``optional`` on them.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, field, replace

import numpy as np
from scipy.linalg import cho_factor, cho_solve
from threadpoolctl import threadpool_limits

from ... import bonds
from ...errors import InputError
from ...model import Model, build
from ...model.schema import ModelSpec
from ...model.values import Param
from ..costs.windows import Windows
from ..solvers.lsq import LinearProblem, compress, least_squares, linear_problem, solve

TINY = 1e-300  # keeps a relative change finite when an RSS is exactly 0
RESOLUTION = 1e-3  # the one-step model's accuracy, a share of the zero-force residual's RMS


@dataclass(frozen=True)
class Decision:
    """One optional bond: present or not, and the evidence at the final structure."""

    bond: int  # index in the model file's bond list
    label: str  # "binary A-B (type neck)"
    present: bool
    delta_bic: float  # BIC without the bond minus BIC with it (> 0: the data want it)
    cost_change: float  # relative change of the optimum's RSS from with to without the bond


@dataclass
class Structure:
    """The identified structure: the model file (every candidate kept, ``present`` set, the
    linear parameters at their least-squares optimum) and the evidence."""

    spec: ModelSpec
    decisions: list[Decision]
    rms_mm: float  # one-step RMS of the identified model on the fitted frames
    full_rms_mm: float  # ... with every candidate present
    zero_force_rms_mm: float  # ... of the zero-force (constant-velocity) predictor
    bic: float
    removed: list[int] = field(default_factory=list)  # bond indices, in the order removed

    def record(self) -> dict:
        return {
            "criterion": "BIC, backward elimination on the exact least squares",
            "rms_mm": self.rms_mm,
            "full_rms_mm": self.full_rms_mm,
            "zero_force_rms_mm": self.zero_force_rms_mm,
            "bic": self.bic,
            "removed": self.removed,
            "decisions": [asdict(d) for d in self.decisions],
        }


def candidates(spec: ModelSpec) -> list[int]:
    """Indices of the optional bonds of a model file."""
    return [i for i, b in enumerate(spec.bond) if b.optional]


def with_presence(spec: ModelSpec, present: dict[int, bool]) -> ModelSpec:
    """The spec with the given optional bonds present or absent."""
    out = [
        b.model_copy(update={"present": present[i]}) if i in present else b
        for i, b in enumerate(spec.bond)
    ]
    return spec.model_copy(update={"bond": out})


def label(spec: ModelSpec, i: int) -> str:
    b = spec.bond[i]
    kind = f"{b.kind} {'-'.join(b.particles)}"
    return f"{kind} (type {b.type})" if b.type else kind


class _Scorer:
    """Exact least squares and BIC of one structure, cached by its set of present bonds.

    Where every candidate's linear genes are its own (no type shared with another bond) and
    it adds no known force (:class:`_Subsets`), one linear problem with every candidate
    present is compressed once and each structure is solved on a subset of its columns;
    otherwise each structure's model is built and solved on its own."""

    def __init__(self, model: Model, windows: Windows, pool: list[int]):
        self.spec = model.spec
        self.disabled = model.disabled
        self.windows = windows
        self.pool = pool
        self.n = int(np.sum(windows.weight)) * model.dimension  # residual coordinates
        free = windows.x0 + windows.dt * windows.v0  # the zero-force prediction
        r0 = windows.weight[:, 0, :, None] * (windows.target[:, 0] - free)
        self.zero_force = float(np.sum(r0**2))  # RSS of the zero-force predictor
        self.floor = self.zero_force * RESOLUTION**2
        self.cache: dict[frozenset, tuple[float, float]] = {}
        self.fits: dict[frozenset, tuple[float, Model, np.ndarray]] = {}
        self._subsets: _Subsets | None | bool = False  # built on first use (False: not yet)

    @property
    def subsets(self) -> _Subsets | None:
        """The compressed problem of every candidate (:class:`_Subsets`), or None."""
        if self._subsets is False:
            self._subsets = _Subsets.of(self, self.pool)
        return self._subsets

    @subsets.setter
    def subsets(self, value: _Subsets | None) -> None:  # None: every structure on its own
        self._subsets = value

    def model(self, present: frozenset) -> Model:
        spec = with_presence(self.spec, {i: i in present for i in self.pool})
        return build(spec, disable=self.disabled)

    def fitted(self, present: frozenset) -> tuple[float, Model, np.ndarray]:
        """(RSS, model, genome) of the structure, its model built and solved on its own."""
        if present not in self.fits:
            model = self.model(present)
            fit = least_squares(model, self.windows)
            self.fits[present] = (fit.cost, model, fit.genome)
            self.cache.setdefault(present, self._score(fit.cost, len(fit.values)))
        return self.fits[present]

    def _score(self, cost: float, k: int) -> tuple[float, float]:
        rss = max(cost, self.floor, TINY)
        return cost, self.n * math.log(rss / self.n) + k * math.log(self.n)

    def __call__(self, present: frozenset) -> tuple[float, float]:
        """(RSS, BIC) with exactly the candidates in ``present``."""
        if present not in self.cache:
            if self.subsets is not None:
                self.cache[present] = self._score(*self.subsets.solve(present))
            else:
                self.fitted(present)
        return self.cache[present]


class _Subsets:
    """The exact least squares of any set of candidates from one compressed problem: the
    problem with every candidate present, its columns scaled and compressed once
    (:func:`~.lsq.compress`); a structure drops the columns of its absent candidates. Valid
    when each candidate's unknowns are its own (its genes set no other bond) and the
    candidates add no known force (the offset with none of them equals the offset with all,
    and so do the other columns): then the problem of a structure is exactly a subset of the
    columns of the full one."""

    def __init__(self, problem: LinearProblem, owner: list[int | None]):
        self.problem, self.owner = problem, owner
        norm = np.linalg.norm(problem.columns, axis=0)
        self.norm = np.where(norm > 0, norm, 1.0)
        self.r, self.c = compress(problem.columns / self.norm, problem.target - problem.offset)
        self.genes = [_genes(n) for n in problem.names]
        self.optima: dict[frozenset, tuple[list[int], np.ndarray]] = {}

    @classmethod
    def of(cls, scorer: _Scorer, pool: list[int]) -> _Subsets | None:
        full = scorer.model(frozenset(pool))
        owned: dict[int, int] = {}  # gene -> its candidate
        for g, gene in enumerate(full.layout.genes):
            mine = [b for b in gene.bonds if b in pool]
            if mine and len(gene.bonds) > 1:
                return None  # a type shared with another bond: its columns mix bonds
            if mine:
                owned[g] = mine[0]
        problem = linear_problem(full, scorer.windows)
        owner = []
        for name in problem.names:
            ids = {owned.get(g) for g in _genes(name)}
            if len(ids) > 1:
                return None
            owner.append(ids.pop())
        none = linear_problem(scorer.model(frozenset()), scorer.windows)
        base = [k for k, o in enumerate(owner) if o is None]
        same = (
            [_gene_key(n, full) for n in (problem.names[k] for k in base)]
            == [_gene_key(n, scorer.model(frozenset())) for n in none.names]
            and np.array_equal(none.offset, problem.offset)
            and np.array_equal(none.columns, problem.columns[:, base])
        )
        return cls(problem, owner) if same else None

    def lower_bounds(self, present: frozenset, scorer: _Scorer) -> dict[int, float] | None:
        """For each candidate in ``present``, a lower bound of the BIC of ``present`` without
        it, every one from the present structure's bounded optimum t and one Cholesky
        factorisation of its normal matrix G. The cost f(t + d) = f(t) + g.d + d^T G d
        (g = 2 A^T (A t - c)); removing a candidate sets its unknowns J to 0, d_J = -t_J;
        at a bounded optimum g.d >= 0 over the other candidates' feasible moves (each
        candidate's constraints are its own), and the quadratic over the other unknowns, free,
        is at least ``t_J^T (G^-1)_JJ^-1 t_J`` (the Schur complement). So the RSS without it
        is at least ``f(t) - g_J.t_J + t_J^T (G^-1)_JJ^-1 t_J``: the exact change where the
        removal moves no other unknown onto a bound. None where the normal matrix is too
        ill-conditioned for that arithmetic."""
        if present not in self.optima:
            self.solve(present)
        keep, theta = self.optima[present]
        if not keep:
            return None
        a = self.r[:, keep]
        try:
            factor = cho_factor(a.T @ a, check_finite=False)
        except np.linalg.LinAlgError:
            return None
        diagonal = np.abs(np.diag(factor[0]))
        if not np.all(np.isfinite(diagonal)) or diagonal.min() < 1e-6 * diagonal.max():
            return None  # condition number above 1e12: the downdates lose their digits
        inverse = cho_solve(factor, np.eye(len(keep)), check_finite=False)
        resid = a @ theta - self.c
        rss, gradient = float(resid @ resid), 2.0 * (a.T @ resid)
        columns: dict[int, list[int]] = {}
        for j, k in enumerate(keep):
            columns.setdefault(self.owner[k], []).append(j)
        genes = {o: set().union(*(self.genes[keep[j]] for j in js)) for o, js in columns.items()}
        total = sum(len(g) for g in genes.values())  # each candidate's genes are its own
        bounds = {}
        for i in present:
            mine = columns.get(i, [])
            t = theta[mine]
            raised = float(t @ np.linalg.solve(inverse[np.ix_(mine, mine)], t)) if mine else 0.0
            low = rss - float(gradient[mine] @ t) + max(raised, 0.0)
            bounds[i] = scorer._score(max(low, 0.0), total - len(genes.get(i, ())))[1]
        return bounds

    def solve(self, present: frozenset) -> tuple[float, int]:
        """(RSS, free linear genes) of the structure with the candidates ``present``."""
        keep = [k for k, o in enumerate(self.owner) if o is None or o in present]
        where = {k: i for i, k in enumerate(keep)}
        p = self.problem
        sub = LinearProblem(
            columns=self.r[:, keep] * self.norm[keep],
            offset=np.zeros(len(self.c)),
            target=self.c,
            names=tuple(p.names[k] for k in keep),
            lower=p.lower[keep],
            upper=p.upper[keep],
            pairs=tuple((where[k], where[q], lo, hi) for k, q, lo, hi in p.pairs if k in where),
            n_terms=p.n_terms,
        )
        theta, _ = solve(sub)
        self.optima[present] = (keep, theta * self.norm[keep])  # scaled, as ``r``'s columns
        resid = sub.columns @ theta - sub.target
        genes = set().union(*(self.genes[k] for k in keep)) if keep else set()
        return float(resid @ resid), len(genes)


def best_removal(score: _Scorer, present: frozenset, ceiling: float) -> tuple[int | None, float]:
    """(the candidate whose removal from ``present`` gives the lowest BIC, that BIC): backward
    elimination's step, the first such candidate in index order on a tie; (None, inf) where
    no removal can give a BIC below ``ceiling`` (the current one).

    Where :meth:`_Subsets.lower_bounds` gives every removal a lower bound of its BIC (the
    unconstrained least squares of the structure without it, from one factorisation: the
    bounded optimum costs at least as much), the removals are solved exactly in the order of
    their bounds, until the best solved is below every bound left: the same choice as
    solving every removal (branch and bound), by one or two bounded solves a step where the
    bounds are seldom active. Otherwise every removal is solved."""
    order = sorted(present)
    bounds = score.subsets.lower_bounds(present, score) if score.subsets is not None else None
    if bounds is None:
        trials = {i: score(present - {i})[1] for i in order}
        best = min(trials, key=trials.get)
        return best, trials[best]
    best, best_bic = None, math.inf
    for i in sorted(order, key=lambda i: (bounds[i], i)):
        if bounds[i] > min(best_bic, ceiling) + _slack(min(best_bic, ceiling)):
            break
        trial = score(present - {i})[1]
        if trial < best_bic or (trial == best_bic and i < best):
            best, best_bic = i, trial
    return best, best_bic


def _slack(bic: float) -> float:
    """How far a lower bound may exceed the BIC it bounds by rounding (the bound and the exact
    solve reach the same optimum by different arithmetic where no bound is active)."""
    return 1e-9 * abs(bic) + 1e-9


def _genes(name: str) -> tuple[int, ...]:
    """The genes of an unknown: "gene:g" or "product:gk*gx"."""
    kind, rest = name.split(":")
    return tuple(int(g) for g in rest.split("*"))


def _gene_key(name: str, model: Model) -> str:
    """An unknown by its genes' names (gene indices differ between structures)."""
    kind = name.split(":")[0]
    return kind + ":" + "*".join(model.layout.genes[g].name for g in _genes(name))


def _held(bond) -> bool:
    """A bond of a kind the exact least squares does not solve, with a known reach."""
    kind = bonds.get(bond.kind)
    return kind.linear is None and kind.reach is not None and not bond.absent


def _fixed(value):
    if isinstance(value, Param):
        return value.model_copy(update={"fixed": True})
    if isinstance(value, list):
        return [_fixed(v) for v in value]
    return value


def held_out_of_reach(model: Model, windows: Windows) -> tuple[Model, Windows]:
    """The model with the parameters of the bonds the least squares does not solve but whose
    reach is known (contacts: :attr:`~activebonds.bonds.BondKind.reach`) held at their file
    values, and the windows without the predictions of their particles from the states where
    they may act for any value in their bounds: there they exert no force, so the held values
    never enter and the structure is decided on the rest (a hoof in swing, not in stance)."""
    held = [i for i, b in enumerate(model.spec.bond) if _held(b)]
    if not held:
        return model, windows
    names = {n: k for k, n in enumerate(model.particle_names)}
    weight = np.array(windows.weight, copy=True)
    new_bonds = list(model.spec.bond)
    for i in held:
        b = new_bonds[i]
        keys = bonds.get(b.kind).keys
        new_bonds[i] = b.model_copy(update={k: _fixed(getattr(b, k)) for k in keys})
        for name in b.particles:
            k = names[name]
            acts = np.asarray(bonds.get(b.kind).reach(b, windows.x0[:, k]), bool)
            weight[acts, :, k] = 0.0
    spec = model.spec.model_copy(update={"bond": new_bonds})
    return build(spec, disable=model.disabled), replace(windows, weight=weight)


def exact_optimum(model: Model, windows: Windows) -> tuple[ModelSpec, float]:
    """(the model file with its linear parameters at their exact least-squares optimum on
    ``windows``, its one-step RMS in mm there): every bond as it is (an absent candidate stays
    absent, a present one present); the bonds the least squares does not solve but whose reach
    is known (contacts) held at their file values and their particles' predictions left out
    where they may act (:func:`held_out_of_reach`). The start of a fit that adds contacts and
    gravity to a decided structure."""
    original = model.spec
    held_model, held_windows = held_out_of_reach(model, windows)
    fit = least_squares(held_model, held_windows)
    spec = held_model.with_genome(fit.genome).spec
    held = [i for i, b in enumerate(original.bond) if _held(b)]
    spec = spec.model_copy(
        update={"bond": [original.bond[i] if i in held else b for i, b in enumerate(spec.bond)]}
    )
    return spec, fit.rms_mm


def identify_structure(model: Model, windows: Windows, eliminate: bool = True) -> Structure:
    """:func:`_identify`; the elimination with one BLAS thread: its solves are of a few
    hundred unknowns each, where threads cost more than they give, and on a loaded machine
    (threads waiting for a core) a hundred times more (``benchmarks/structure.py``). Without
    elimination, one solve of every candidate (the BLAS library's own threads)."""
    if not eliminate:
        return _identify(model, windows, eliminate)
    with threadpool_limits(limits=1, user_api="blas"):
        return _identify(model, windows, eliminate)


def _identify(model: Model, windows: Windows, eliminate: bool = True) -> Structure:
    """Backward elimination of the optional bonds of ``model`` under the BIC, each structure
    solved by exact least squares on ``windows`` (horizon 1). InputError when the model has
    no optional bond or is outside the families the exact least squares solves.

    ``eliminate=False``: no elimination and no decisions (each costs a solve per candidate):
    every candidate present, the linear parameters at their exact least-squares optimum (for
    candidates too many to decide, ``activebonds auto``)."""
    pool = candidates(model.spec)
    if not pool:
        raise InputError(model.name, "no bond is optional (add optional = true to candidates)")
    if model.layout.mass_rest is not None or any(model.spec.free_masses()):
        raise InputError(
            model.name,
            "structure identification needs fixed masses (it solves the linear parameters "
            "exactly); fix the masses or identify them first",
        )
    original = model.spec
    model, windows = held_out_of_reach(model, windows)
    score = _Scorer(model, windows, pool)
    present = frozenset(pool)
    if not eliminate:  # one solve: the model on its own, no compressed problem of subsets
        score.fitted(present)
    rss_full, bic = score(present)
    removed: list[int] = []
    while present and eliminate:
        best, best_bic = best_removal(score, present, bic)
        if best is None or not best_bic < bic:
            break
        present, bic = present - {best}, best_bic
        removed.append(best)
    rss, bic = score(present)
    _, final, genome = score.fitted(present)
    decisions = []
    for i in pool if eliminate else ():
        other = present - {i} if i in present else present | {i}
        rss_o, bic_o = score(other)
        with_rss, without_rss = (rss, rss_o) if i in present else (rss_o, rss)
        with_bic, without_bic = (bic, bic_o) if i in present else (bic_o, bic)
        decisions.append(
            Decision(
                bond=i,
                label=label(model.spec, i),
                present=i in present,
                delta_bic=float(without_bic - with_bic),
                cost_change=float((without_rss - with_rss) / max(with_rss, TINY)),
            )
        )
    spec = final.with_genome(genome).spec
    held = [i for i, b in enumerate(original.bond) if _held(b)]
    spec = spec.model_copy(
        update={"bond": [original.bond[i] if i in held else b for i, b in enumerate(spec.bond)]}
    )
    n_terms = max(int(np.sum(windows.weight)), 1)
    return Structure(
        spec=spec,
        decisions=decisions,
        rms_mm=float(np.sqrt(rss / n_terms) * 1000.0),
        full_rms_mm=float(np.sqrt(rss_full / n_terms) * 1000.0),
        zero_force_rms_mm=float(np.sqrt(score.zero_force / n_terms) * 1000.0),
        bic=float(bic),
        removed=removed,
    )


def structure_of(
    model: Model, recording, settings, smooth: int = 0, eliminate: bool = True
) -> Structure:
    """:func:`identify_structure` on the frames and markers of ``settings`` of ``recording``
    (its positions smoothed first by a Savitzky-Golay window of ``smooth`` frames; 0: off):
    the pipeline of ``activebonds structure``."""
    from ...data.smoothing import smooth_positions
    from ..costs.windows import make_windows, neighbours_of
    from ..problem import select_data

    data = select_data(model, recording, settings)
    positions = smooth_positions(data.positions, data.mask, smooth) if smooth else data.positions
    windows = make_windows(positions, data.mask, data.dt, 1, neighbours=neighbours_of(model))
    return identify_structure(model, windows, eliminate)
