"""Which fitted numbers the data determine: Gauss-Newton standard errors at the optimum.

With residuals r(theta) (metres) at the fit's optimum and J = dr/dtheta (natural units), the
Gauss-Newton covariance is ``s^2 (J^T J)^-1`` with ``s^2 = |r|^2 / dof`` the residual variance
(dof: residual coordinates minus variables). It is computed through the SVD of J with its
columns scaled to unit norm, so units do not matter:

* directions whose singular value is below ``RANK_RTOL`` of the largest are *not determined*
  (numerically singular J^T J): every parameter with a part in them is marked "not
  determined" and the direction is named in words ("mass scale", "stiffness and rest_length
  of type:neck trade off");
* a determined parameter whose 95 % interval is wider than its search range is also marked
  "not determined" (the data narrow it no more than the bounds do), with the direction that
  carries most of its variance named the same way.

A parameter searched in log space (a positive stiffness, damping or mass) has its interval
formed there, ``value * exp(+-1.96 se / value)`` (the delta method on ``log(value)``): never
below 0, and held against its log range ``log(max / min)``.

Which residuals: those of the fit's last cost (the restart cost at the ES's horizon, or the
last refinement stage's horizon; for multiple shooting the window start states are extra
variables, nuisance parameters whose uncertainty widens the others'). The intervals are
exact for an output-error cost (a free run or shooting) with Gaussian, independent marker
noise, in the limit of many frames. For the one-step cost with noisy markers they are not:
the noise is in the regressors too and biases the optimum itself (docs/experiments/shooting.md), which
no covariance describes.
"""

from __future__ import annotations

import csv
import io
import math
from collections.abc import Sequence
from dataclasses import asdict, dataclass, field, replace

import numpy as np

from ...model.names import labeller
from .. import costs
from ..problem import Identification
from ..settings import FitSettings

RANK_RTOL = 1e-8  # singular values below this share of the largest: not determined
Z95 = 1.959963984540054  # the normal quantile of a two-sided 95 % interval
NAMED = 0.3  # a parameter is named in a direction where its component is at least this
MAX_JACOBIAN_BYTES = 2**30  # a larger dense Jacobian (long shooting fits) is not formed
BLOCK_BYTES = 2**27  # a tall Jacobian is factored a block of rows of about this size at a time


@dataclass(frozen=True)
class Estimate:
    """One free parameter: value, standard error and 95 % interval (natural units)."""

    name: str
    value: float
    std_error: float | None  # None: not determined
    low: float | None
    high: float | None
    determined: bool
    note: str  # why not determined, in words ("" when it is)
    label: str = ""  # the name as people read it ("spring A-B stiffness"); ``name`` is the key


@dataclass
class Uncertainty:
    """The Gauss-Newton report of one fit."""

    estimates: list[Estimate]
    cost: str  # the name of the cost whose residuals these are (identify.costs)
    horizon: int
    residuals: int  # residual coordinates
    variables: int  # parameters plus nuisance variables (shooting start states)
    rank: int
    condition: float  # of the column-scaled Jacobian (inf when singular)
    sigma_mm: float  # residual standard deviation per coordinate, mm
    directions: list[str] = field(default_factory=list)  # not determined, in words

    def record(self) -> dict:
        out = asdict(self)
        for key in ("condition", "sigma_mm"):  # JSON has no inf or NaN: null
            out[key] = out[key] if math.isfinite(out[key]) else None
        return out

    def csv_text(self) -> str:
        buf = io.StringIO()
        w = csv.writer(buf, lineterminator="\n")
        w.writerow(
            [
                "parameter",
                "value",
                "std_error",
                "ci95_low",
                "ci95_high",
                "determined",
                "note",
                "label",
            ]
        )
        for e in self.estimates:
            num = [
                f"{x:.10g}" if x is not None else "not determined"
                for x in (e.std_error, e.low, e.high)
            ]
            determined = "yes" if e.determined else "no"
            w.writerow([e.name, f"{e.value:.10g}", *num, determined, e.note, e.label or e.name])
        return buf.getvalue()


def describe(names: list[str], vector: np.ndarray, masses: set[int], label=None) -> str:
    """A direction of parameter space in words: the parameters that move along it
    (``label``: a parameter's or group's name -> the words shown; default: the name)."""
    show = label or (lambda n: n)
    big = [i for i in range(len(vector)) if abs(vector[i]) >= NAMED * np.abs(vector).max()]
    if masses and masses <= set(big):
        return "mass scale (the masses and the forces can grow together)"
    parts = [names[i] for i in big]
    groups = {n.rsplit(".", 1)[0] for n in parts if "." in n}
    if len(parts) >= 2 and len(groups) == 1 and all("." in n for n in parts):
        fields = [n.rsplit(".", 1)[1] for n in parts]
        return f"{' and '.join(fields)} of {show(groups.pop())} trade off"
    parts = [show(n) for n in parts]
    if len(parts) == 1:
        return f"{parts[0]} does not change the residuals"
    return f"{', '.join(parts[:-1])} and {parts[-1]} trade off"


def _undetermined(names, values, note: str):
    """Every parameter "not determined" for one reason: (estimates, rank, condition, s^2,
    directions) as :func:`from_jacobian` returns them."""
    gone = [
        Estimate(n, float(v), None, None, None, False, note)
        for n, v in zip(names, values, strict=True)
    ]
    return gone, 0, math.inf, math.nan, [note]


def _triangle(jac: np.ndarray, scale: np.ndarray) -> np.ndarray:
    """A matrix with the singular values and right singular vectors of ``jac / scale``
    [m, p]: where m is well above p, the triangular factor of its QR decomposition, formed
    a block of rows at a time (each block's rows stacked under the factor so far), so that
    neither the scaled copy nor the SVD's left vectors ([m, p] each) are formed; else the
    scaled matrix itself."""
    from scipy.linalg import qr

    m, p = jac.shape
    step = max(4 * p, BLOCK_BYTES // (8 * max(p, 1)))  # rows a block: at least 4 p
    if m <= 2 * step:
        return jac / scale
    r = np.zeros((0, p))
    for a in range(0, m, step):
        block = np.vstack([r, jac[a : a + step] / scale])
        r = qr(block, mode="r", overwrite_a=True, check_finite=False)[0][:p]
    return r


def _decompose(jac: np.ndarray):
    """The SVD of the Jacobian with unit-norm columns: (column norms, singular values, V^T,
    the directions above RANK_RTOL)."""
    norms = np.linalg.norm(jac, axis=0)
    _, sv, vt = np.linalg.svd(_triangle(jac, np.where(norms == 0, 1.0, norms)), full_matrices=False)
    ok = sv > RANK_RTOL * (sv[0] if sv.size and sv[0] > 0 else 1.0)
    return norms, sv, vt, ok


def from_jacobian(
    jac: np.ndarray,
    resid: np.ndarray,
    names: list[str],
    values: np.ndarray,
    spans: np.ndarray,
    dof: int,
    masses: set[int] = frozenset(),
    label=None,
    log=None,
) -> tuple[list[Estimate], int, float, float, list[str]]:
    """Estimates of the first ``len(names)`` variables (the others are nuisance) from the
    Jacobian [m, p + q] and residuals [m] at the optimum: (estimates, rank, condition, s^2,
    directions not determined in words; ``label``: as in :func:`describe`).

    ``log`` [p]: the variables searched in log space (positive): their intervals are formed
    there, ``value * exp(+-1.96 se / value)`` (never below 0), and their ``spans`` are log
    ranges, ``log(max / min)``; the standard error stays in natural units."""
    show = label or (lambda n: n)
    p = len(names)
    jac = np.asarray(jac, np.float64)
    if jac.size == 0 or not (np.all(np.isfinite(jac)) and np.all(np.isfinite(resid))):
        return _undetermined(
            names, values, "the residuals or their Jacobian are not finite at the optimum"
        )
    if dof <= 0:
        note = f"no residual degrees of freedom ({dof}): the residual variance is unknown"
        return _undetermined(names, values, note)
    norms, sv, vt, ok = _decompose(jac)
    dead = norms == 0
    rank = int(ok.sum())
    condition = float(sv[0] / sv[-1]) if sv[-1] > 0 and rank == sv.size else math.inf
    s2 = float(resid @ resid) / dof
    v_ok, s_ok = vt[ok].T, sv[ok]  # [p + q, r]
    contrib = (v_ok / s_ok) ** 2  # variance of each scaled variable, per direction (x s^2)
    var_scaled = s2 * contrib.sum(axis=1)
    null = vt[~ok].T  # [p + q, n_null]
    in_null = np.linalg.norm(null, axis=1) > 1e-6 if null.size else np.zeros(len(norms), bool)
    in_null |= dead
    directions = []
    for j in range(null.shape[1] if null.size else 0):
        if np.linalg.norm(null[:p, j]) > 1e-6:
            directions.append(describe(names, null[:p, j], set(masses), label))
        else:  # only nuisance variables (shooting start states) move along it
            directions.append("a start state that no recorded frame sees (no parameter)")
    if dead[:p].any():
        directions += [
            f"{show(names[i])} does not change the residuals" for i in np.flatnonzero(dead[:p])
        ]
    estimates = []
    for i in range(p):
        if in_null[i]:
            hits = [j for j in range(null.shape[1] if null.size else 0) if abs(null[i, j]) > 1e-6]
            unseen = f"{show(names[i])} does not change the residuals"
            note = directions[hits[0]] if hits else unseen
            estimates.append(Estimate(names[i], float(values[i]), None, None, None, False, note))
            continue
        se = float(math.sqrt(var_scaled[i]) / norms[i])
        v = float(values[i])
        in_log = log is not None and bool(log[i]) and v > 0
        half = Z95 * (se / v if in_log else se)
        if half > spans[i]:
            worst = int(np.argmax(contrib[i]))
            if np.linalg.norm(v_ok[:p, worst]) <= 1e-6:
                worst = int(np.argmax(contrib[i, :] * (np.linalg.norm(v_ok[:p], axis=0) > 1e-6)))
            note = "interval wider than the search range: " + describe(
                names, v_ok[:p, worst], set(masses), label
            )
            estimates.append(Estimate(names[i], float(values[i]), None, None, None, False, note))
            continue
        low, high = (v * math.exp(-half), v * math.exp(half)) if in_log else (v - half, v + half)
        note = "interval in log space (searched there)" if in_log else ""
        estimates.append(Estimate(names[i], v, se, low, high, True, note))
    return estimates, rank, condition, s2, directions


def _masses_in_kg(estimates, decomposition, s2, ratio, theta, rest, spans):
    """Free masses under ``total_mass`` are genes w_i with m_i = rest w_i / sum(w): report
    m_i (kg) with its standard error by the delta method (the weights' gauge drops out);
    ``decomposition``: :func:`_decompose` of the Jacobian with its gauge row."""
    norms, sv, vt, ok = decomposition
    w = theta[ratio]
    v = vt[ok][:, ratio] / norms[ratio]
    cov_w = s2 * (v.T / sv[ok] ** 2) @ v
    total = w.sum()
    grad = rest * (np.eye(len(w)) / total - np.outer(w, np.ones(len(w))) / total**2)
    se = np.sqrt(np.maximum(np.diag(grad @ cov_w @ grad.T), 0.0))
    out = list(estimates)
    for j, i in enumerate(ratio):
        e = estimates[i]
        name = e.name.removesuffix(".weight") + ".mass"
        m = float(rest * w[j] / total)
        if not e.determined:
            out[i] = Estimate(name, m, None, None, None, False, e.note)
            continue
        half = Z95 * float(se[j]) / m  # in log space, as the weights are searched
        if half > spans[j]:
            note = "interval wider than the search range (kg)"
            out[i] = Estimate(name, m, None, None, None, False, note)
            continue
        note = "kg, a share of total_mass; interval in log space"
        low, high = m * math.exp(-half), m * math.exp(half)
        out[i] = Estimate(name, m, float(se[j]), low, high, True, note)
    return out


def _span(gene) -> float:
    """The search range a 95 % interval is held against: ``max - min``, or ``log(max / min)``
    for a gene searched in log space (its interval is formed there)."""
    if gene.log and gene.lower > 0 and gene.upper > 0:
        return math.log(gene.upper / gene.lower)
    return gene.upper - gene.lower


def shooting_rejected(stages) -> list[str]:
    """Why the refinement's stages on other costs were not kept (``stages``: its
    :class:`~activebonds.identify.solvers.refine.Stage` records or their dicts), one line each:
    a stage its cost rejected, or a one-step stage refined in its place."""
    out = []
    for s in stages:
        s = s if isinstance(s, dict) else s.record()
        why = s.get("instead_of_shooting") or costs.get(s["cost"]).rejection(s)
        if why:
            out.append(why)
    return out


def warnings(
    cost: str,
    horizon: int,
    substeps: int,
    rejected: Sequence[str] = (),
    checked=None,
    modes: str | None | bool = False,
) -> list[str]:
    """Where the intervals of a fit on cost ``cost`` at ``horizon`` with ``substeps`` cannot
    be trusted, in words (measured on the triangle, docs/experiments/uncertainty.md). ``rejected``: why
    the fit's shooting stages were not kept (:func:`shooting_rejected`); then the one-step
    warning says so, instead of sending the user to a shooting fit that was already tried.
    ``checked``: the fit moved to finer substeps (:func:`.integrator_check.check`: its result,
    or why it was not made); where it was made, its numbers replace the warning in words (and
    a fit that does not move gets none). ``modes``: where no such check was made, the
    fitted springs' fastest oscillation against the step (:func:`.modes.warning`: its
    sentence, or None where the step resolves it); False: not computed, the warning stays in
    words."""
    out = []
    caveat = costs.get(cost).interval_warning(horizon, rejected)
    if caveat:
        out.append(caveat)
    if hasattr(checked, "warning"):
        if checked.warning():
            out.append(checked.warning())
    elif modes is not False:
        if modes:
            out.append(modes)
    elif int(substeps) == 1:
        out.append(
            "the integrator takes one step per frame: if the motion is finer than the frames, "
            "the parameters can sit several standard errors off with no visible symptom (64 % "
            "coverage of 95 % intervals measured); refit at --substeps 4 and check that the "
            "parameters move by less than their intervals"
        )
    return out


MISFIT = 3.0  # residuals this many times what the markers' noise alone leaves: a misfit


def noise_gain(cost: str, horizon: int) -> float:
    """The residual RMS a correct model leaves on ``cost`` at ``horizon``, per coordinate, in
    units of the markers' white noise sigma (:meth:`~activebonds.identify.costs.base.Cost.noise_gain`)."""
    return costs.get(cost).noise_gain(horizon)


def misfit(sigma_mm: float, noise_mm: float, cost: str, horizon: int) -> str | None:
    """Where the fit's residuals (``sigma_mm`` a coordinate) are more than :data:`MISFIT`
    times what the markers' noise (``noise_mm`` a coordinate, :func:`.smoothing.noise_of`)
    leaves on its cost, the warning in words: the model misses forces of the recording, the
    intervals describe the noise and not that misfit, and the parameters absorb it (on
    MuJoCo's thrown body, stiffnesses 35 % low: docs/experiments/uncertainty.md); else None."""
    if not (np.isfinite(sigma_mm) and np.isfinite(noise_mm)) or noise_mm <= 0:
        return None
    expected = noise_gain(cost, horizon) * noise_mm
    ratio = sigma_mm / expected
    if ratio <= MISFIT:
        return None
    return (
        f"the model does not explain the recording to its noise: its residuals are "
        f"{ratio:.3g} times what the markers' noise alone leaves on this cost ({sigma_mm:.3g} "
        f"vs {expected:.3g} mm a coordinate; noise {noise_mm:.3g} mm from the fourth "
        "differences), so it misses forces of this motion; the intervals describe the noise, "
        "not this misfit, which the parameters absorb: they can be off by far more than their "
        "intervals (a body simulated by MuJoCo: stiffnesses 35 % low, outside their intervals)"
    )


def estimate(
    ident: Identification,
    settings: FitSettings,
    genome: np.ndarray,
    horizon: int | None = None,
    cost: str = costs.DEFAULT,
    states=None,
) -> Uncertainty:
    """The Gauss-Newton report of the fit ``genome`` (search space) of ``ident`` on the cost
    ``cost`` at ``horizon`` (default: the ES's); ``states``: for ``shooting``, the per-frame
    states [(x, v)] of each recording at the optimum (the refinement's)."""
    layout = ident.model.layout
    horizon = int(horizon or settings.es_horizon)
    theta = np.asarray(layout.natural(np.asarray(genome, np.float64)), np.float64)
    chosen = costs.get(cost)
    if chosen.needs_states and states is None:  # without them, the restart cost's report
        chosen = costs.get(costs.DEFAULT)
    residuals = chosen.residual_function(ident, settings, horizon, states)
    observed, nuisance, links = residuals.observed, residuals.nuisance, residuals.links
    jac, resid = chosen.information(
        ident, settings, horizon, states, theta, residuals, MAX_JACOBIAN_BYTES
    )
    names = [g.name for g in layout.genes]
    spans = np.array([_span(g) for g in layout.genes], np.float64)
    masses = {i for i, g in enumerate(layout.genes) if g.owner == "mass"}
    # Continuity links are constraints (zero at a converged shooting optimum), not data.
    dof = observed - (len(theta) + nuisance) + links
    ratio = sorted(masses) if layout.mass_rest is not None else []
    if not np.all(np.isfinite(jac)):
        ratio = []  # reported as not finite by from_jacobian, weights as they are
    if ratio:  # the weights' common scale changes nothing: one gauge row fixes it
        dof += 1
        gauge = np.zeros(jac.shape[1])
        gauge[ratio] = theta[ratio] / np.linalg.norm(theta[ratio])
        jac = np.vstack([jac, gauge * np.linalg.norm(jac, axis=0).max()])
        resid = np.append(resid, 0.0)
        masses = set()
    label = labeller(ident.model.spec)
    estimates, rank, condition, s2, directions = from_jacobian(
        jac, resid, names, theta, spans, dof, masses, label, log=layout.log
    )
    if ratio and np.isfinite(s2):  # the weights' log ranges: a mass's share moves as much
        estimates = _masses_in_kg(
            estimates, _decompose(jac), s2, ratio, theta, layout.mass_rest, spans[ratio]
        )
    estimates = [replace(e, label=label(e.name)) for e in estimates]
    return Uncertainty(
        estimates=estimates,
        cost=chosen.name,
        horizon=horizon,
        residuals=int(observed),
        variables=int(len(theta) + nuisance),
        rank=rank,
        condition=condition,
        sigma_mm=float(math.sqrt(max(s2, 0.0)) * 1000.0),
        directions=directions,
    )
