"""Which variant of a scaffold's linear structure ``activebonds auto`` keeps: chosen on a
validation tail of the fitted frames, never on the held-out ones.

The exact least squares (:mod:`.lsq`) and the BIC (:mod:`.structure`) judge a structure on
the frames it was fitted to. A model that predicts new frames must also do well where the
body is not quite where it was: on a treadmill it wanders, and a marker tied to a place in
the room (an anchor) is pulled back to where it stood while the rest of the body moves on.
So the variants below are each fitted (exact least squares, with or without the BIC's
elimination) on the first :data:`TRAIN` of the fitted frames and scored by their one-step
error on the rest, the **validation tail**, beside the zero-force predictor's there:

* **masses**: as scaffolded (equal), or in inverse proportion to each marker's RMS
  acceleration over the frames (the same total): a pair of bodies pushed apart by one force
  accelerate in inverse proportion to their masses, so a marker that barely accelerates (a
  horse's withers) is heavy beside one that does (a hoof), and a spring that moves the hoof
  hardly moves it; or **conserving momentum**: the masses (same total) whose centre of mass
  moves as internal forces and a uniform gravity let it, on a parabola in time
  (:func:`momentum_masses`), unbiased by equal marker noise. Where the scaffold has ground
  contacts, only the frames in flight count (every contact off its plane: :func:`flight_frames`),
  each flight with its own parabola. Where another outside force acts (a treadmill, a hand)
  they mean nothing; the tail decides, and a vector of mixed signs is no variant at all;
* **anchors** (a scaffold's unary spring-dampers): as scaffolded (springs with free anchors),
  as dampers alone (stiffness 0: a drag towards rest in the room, no place to hold), or none;
* **decided**: the candidates the BIC keeps, or every candidate.

Gravity and the bonds the exact least squares does not solve (ground contacts) are left out
of every variant: they are the fit's to add (``activebonds auto`` fits them from the chosen
variant and keeps them where the BIC of the fitted frames says they earn their parameters).

The chosen variant is the one with the lowest one-step RMS on the tail among those that beat
zero force at every marker there (if none does, among all); variants within :data:`TIE` of
that RMS are tied, and the one with the fewest bonds among them is chosen (a candidate whose
value the tail cannot tell from zero is not kept). Where no variant predicts the tail better
than zero force overall (a body coasting or at rest there), the tail cannot choose and the
default variant is kept: the BIC's decision with the scaffold's masses and anchors, as
``structure`` decides (:func:`pick`). The chosen variant is then decided and solved again on
all the fitted frames (:func:`decide`).

(Tried: the masses conserving momentum as the default instead, on the thrown MuJoCo body of
``scripts/mujoco_thrown.py`` whose tail cannot choose: the masses came within 2 %, but the
held-out predictions were worse, one step 0.3307 against 0.2745 mm and 10 ahead 3.092
against 2.2 mm.)
"""

from __future__ import annotations

from dataclasses import asdict, dataclass
from itertools import product

import numpy as np

from ... import bonds
from ...data.coverage import present_windows
from ...data.orientation import MIN_PHASE
from ...model import Model, build
from ...model.schema import ModelSpec
from ...nanstats import nanmean

TRAIN = 0.8  # the share of the fitted frames each variant is fitted on; the rest is the tail
# variants within this share of the lowest tail RMS are tied: the fewest bonds win. At 1 % the
# horses' held-out scores got worse (trot fitted on 0-479: one step 4.666 -> 4.746 mm; walk
# fitted on 0-299: 3.089 -> 3.100 mm, ten ahead 79.88 -> 81.89 mm); at 0.1 % they keep their
# choices, and MuJoCo's noisy tendons (tests/test_auto_noise.py) lose their spurious bonds
TIE = 0.001
MIN_TAIL = 10  # frames: a shorter tail chooses nothing (the default variant is kept)
MASSES = ("scaffold", "acceleration", "momentum")
ANCHORS = ("springs", "dampers", "none")


@dataclass(frozen=True)
class Variant:
    """One variant of a scaffold's linear structure."""

    masses: str = "scaffold"  # MASSES
    anchors: str = "springs"  # ANCHORS ("springs" where the scaffold has no anchor)
    decided: bool = True  # the BIC's elimination (False: every candidate present)

    def text(self) -> str:
        masses = {
            "scaffold": "scaffold masses",
            "acceleration": "masses ~ 1/rms acceleration",
            "momentum": "masses conserving momentum",
        }[self.masses]
        anchors = {"springs": "anchors", "dampers": "anchors as dampers", "none": "no anchor"}
        decided = "BIC-decided" if self.decided else "every candidate"
        return f"{masses}, {anchors[self.anchors]}, {decided}"


@dataclass(frozen=True)
class Scored:
    """A variant fitted on the first frames and scored on the tail (mm)."""

    variant: Variant
    tail_rms_mm: float
    tail_zero_force_mm: float
    per_marker_mm: tuple[float, ...]
    zero_force_per_marker_mm: tuple[float, ...]
    bonds: int  # present bonds

    @property
    def every_marker_better(self) -> bool:
        return all(
            m < z for m, z in zip(self.per_marker_mm, self.zero_force_per_marker_mm, strict=True)
        )

    def record(self) -> dict:
        return {**asdict(self), "variant": asdict(self.variant), "text": self.variant.text()}


@dataclass(frozen=True)
class Choice:
    """The variants' scores on the tail and the one chosen (None: no choice was made)."""

    chosen: Variant
    scored: tuple[Scored, ...]
    train: tuple[int, int]
    tail: tuple[int, int]
    markers: tuple[str, ...]
    why: str = ""  # where the tail could not choose, why (the default variant kept)

    def record(self) -> dict:
        return {
            "why": self.why,
            "rule": "lowest one-step RMS on the validation tail among the variants better than "
            f"zero force at every marker there (else among all); within {TIE:.1%} of it, the "
            "fewest bonds; where none is better than zero force there, the BIC's decision with "
            "the scaffold's masses and anchors",
            "train_frames": list(self.train),
            "tail_frames": list(self.tail),
            "markers": list(self.markers),
            "chosen": asdict(self.chosen),
            "chosen_text": self.chosen.text(),
            "variants": [s.record() for s in self.scored],
        }

    def line(self) -> str:
        a, b = self.tail
        if self.why:
            return f"on the validation tail {a}:{b} among {len(self.scored)} variants: {self.why}"
        best = next(s for s in self.scored if s.variant == self.chosen)
        return (
            f"chosen on the validation tail {a}:{b} (fitted on {self.train[0]}:{self.train[1]}) "
            f"among {len(self.scored)} variants: {self.chosen.text()}, {best.tail_rms_mm:.4g} "
            f"mm (zero force {best.tail_zero_force_mm:.4g} mm)"
        )


def has_anchors(spec: ModelSpec) -> bool:
    return any(b.kind == bonds.unary.KIND.name for b in spec.bond)


def variants(spec: ModelSpec, positions=None, dt: float = 1.0) -> list[Variant]:
    """Every variant of the scaffold ``spec``, in the order ties are settled; the momentum
    masses only where ``positions`` [F, P, D] give positive ones (:func:`momentum_masses`)."""
    anchors = ANCHORS if has_anchors(spec) else ("springs",)
    masses = [
        m
        for m in MASSES
        if m != "momentum"
        or (
            positions is not None
            and momentum_masses(positions, dt, 1.0, flight_frames(spec, positions)) is not None
        )
    ]
    return [Variant(m, a, d) for m, a, d in product(masses, anchors, (True, False))]


def acceleration_masses(positions: np.ndarray, dt: float, total: float) -> np.ndarray:
    """Masses summing to ``total`` in inverse proportion to each marker's RMS acceleration
    (second differences over ``dt^2`` where three frames are recorded), [P]; equal where a
    marker's acceleration cannot be measured or is zero."""
    x = np.asarray(positions, np.float64)
    acc = (x[2:] - 2 * x[1:-1] + x[:-2]) / dt**2
    a2 = np.sum(acc**2, axis=-1)  # [F - 2, P], NaN where missing
    with np.errstate(invalid="ignore"):
        rms = np.sqrt(nanmean(a2, axis=0))
    if not np.all(np.isfinite(rms) & (rms > 0)):
        return np.full(x.shape[1], total / x.shape[1])
    inverse = 1.0 / rms
    return total * inverse / inverse.sum()


FLIGHT_MARGIN = 0.01  # m: a frame is in flight where every contact is this far off its plane


def flight_frames(spec: ModelSpec, positions) -> np.ndarray | None:
    """Where ``spec`` has contacts: the frames [F] in which every contact's particle is more
    than :data:`FLIGHT_MARGIN` off its plane (``normal . x > height + margin``), so that only
    the internal forces and gravity act (a thrown or jumping body between landings); None
    without contacts (every frame)."""
    contacts = [b for b in spec.bond if b.kind == bonds.contact.KIND.name and not b.absent]
    if not contacts:
        return None
    names = [p.name for p in spec.particle]
    x = np.asarray(positions, np.float64)
    flight = np.ones(x.shape[0], bool)
    for b in contacts:
        normal = np.asarray(b.normal, np.float64)
        normal = normal / np.linalg.norm(normal)
        height = b.height.value if hasattr(b.height, "value") else b.height
        height = 0.0 if height is None else float(height)  # the kind's default plane
        with np.errstate(invalid="ignore"):
            above = x[:, names.index(b.particles[0])] @ normal > height + FLIGHT_MARGIN
        flight &= above
    return flight


def momentum_masses(
    positions: np.ndarray, dt: float, total: float, frames: np.ndarray | None = None
) -> np.ndarray | None:
    """Masses summing to ``total`` whose centre of mass moves as internal forces (and a
    uniform gravity) let it: on a parabola in time, ``sum_i m_i x_i(t) = a + b t + c t^2``.
    The unit ``m`` minimising the part of ``sum_i m_i x_i(t)`` no parabola explains over the
    frames where every marker is recorded (the right singular vector, with the smallest
    singular value, of the markers' positions with each one's best parabola removed), scaled
    to ``total``. Positions, not accelerations: their noise is not amplified by differences,
    and equal noise on every marker adds a multiple of the identity to the Gram matrix, which
    moves no singular vector. ``frames`` [F] (e.g. :func:`flight_frames`): only those, each
    run of at least ``orientation.MIN_PHASE`` of them with its own parabola (between two landings the
    centre of mass flies on a new one). None where fewer frames are complete than that takes
    or the vector has a sign change or a zero (no set of masses moves so), [P] otherwise."""
    x = np.asarray(positions, np.float64)
    f, p, d = x.shape
    complete = np.isfinite(x).all(axis=(1, 2))
    runs = (
        [np.arange(f)]
        if frames is None
        else [np.arange(a, b) for a, b in present_windows(frames, MIN_PHASE)]
    )
    rests = []
    for run in runs:
        kept = run[complete[run]]
        if len(kept) < 4:
            continue
        t = kept * dt
        basis, _ = np.linalg.qr(np.vander((t - t.mean()) / max(np.ptp(t), dt), 3))
        seen = x[kept]
        rests.append(seen - np.einsum("fk,gk,gpd->fpd", basis, basis, seen))  # parabola removed
    if p < 2 or sum(len(r) for r in rests) < p + 3 * len(rests):
        return None
    rest = np.concatenate(rests)
    _, _, vt = np.linalg.svd(np.moveaxis(rest, 1, -1).reshape(-1, p), full_matrices=False)
    m = vt[-1] * np.sign(vt[-1].sum())
    if not np.all(m > 1e-6 * np.abs(m).max()):
        return None
    return total * m / m.sum()


def linear_spec(spec: ModelSpec, variant: Variant, positions, dt: float) -> ModelSpec:
    """The scaffold ``spec`` as ``variant`` has it: no gravity, no bond the exact least
    squares does not solve, anchors and masses as the variant says (``positions`` [F, P, D]:
    the frames the masses are measured on)."""
    unary = bonds.unary.KIND.name
    kept = []
    for b in spec.bond:
        if bonds.get(b.kind).linear is None:
            continue  # contacts: the fit's to add
        if b.kind == unary and variant.anchors == "none":
            continue
        if b.kind == unary and variant.anchors == "dampers":
            anchor = b.anchor.value if hasattr(b.anchor, "value") else b.anchor
            b = b.model_copy(update={"stiffness": 0.0, "anchor": [float(a) for a in anchor]})
        kept.append(b)
    particles = list(spec.particle)
    if variant.masses != "scaffold":
        total = sum(mass_of(p) for p in particles)
        if variant.masses == "momentum":
            masses = momentum_masses(positions, dt, total, flight_frames(spec, positions))
            if masses is None:  # not on these frames: equal, as scaffolded
                masses = np.full(len(particles), total / len(particles))
        else:
            masses = acceleration_masses(positions, dt, total)
        particles = [
            p.model_copy(update={"mass": float(m)}) for p, m in zip(particles, masses, strict=True)
        ]
    return spec.model_copy(update={"bond": kept, "gravity": None, "particle": particles})


def mass_of(p) -> float:
    """A particle's mass (kg), fixed or free (its value)."""
    return float(p.mass.value if hasattr(p.mass, "value") else p.mass)


def decide(model: Model, recording, frames: tuple[int, int], variant: Variant):
    """``variant`` of the scaffold ``model`` decided and solved on ``frames`` of
    ``recording`` (:func:`~.structure.structure_of`): a :class:`~.structure.Structure`."""
    from ..problem import select_data
    from ..settings import FitSettings
    from .structure import candidates, structure_of

    settings = FitSettings(frames=frames)
    data = select_data(model, recording, settings)
    spec = linear_spec(model.spec, variant, data.positions, data.dt)
    linear = build(spec)
    eliminate = variant.decided and bool(candidates(spec))
    return structure_of(linear, recording, settings, 0, eliminate)


def choose(model: Model, recording, frames: tuple[int, int], say=None) -> Choice | None:
    """The variants of the scaffold ``model`` fitted on the first :data:`TRAIN` of ``frames``
    and scored on the rest (see the module's docstring); None where the tail would hold
    fewer than :data:`MIN_TAIL` frames or the training part fewer than that."""
    from ..judge.baselines import zero_force_predictions
    from ..judge.predictions import one_step, rms_mm
    from ..problem import select_data
    from ..settings import FitSettings

    a, b = frames
    split = a + int(round(TRAIN * (b - a)))
    if b - split < MIN_TAIL or split - a < MIN_TAIL:
        return None
    tail = select_data(model, recording, FitSettings(frames=(split, b)))
    rec = np.asarray(tail.positions, np.float64)
    zero = zero_force_predictions(rec, 1)[0]
    zero_each = rms_mm(zero, rec)
    zero_all = _overall(zero, rec)
    scored = []
    train = select_data(model, recording, FitSettings(frames=(a, split)))
    for variant in variants(model.spec, train.positions, train.dt):
        found = decide(model, recording, (a, split), variant)
        fitted = build(found.spec)
        one = one_step(fitted, rec, tail.dt)
        each = rms_mm(one, rec)
        s = Scored(
            variant=variant,
            tail_rms_mm=_overall(one, rec),
            tail_zero_force_mm=zero_all,
            per_marker_mm=tuple(float(v) for v in each),
            zero_force_per_marker_mm=tuple(float(v) for v in zero_each),
            bonds=sum(1 for bd in found.spec.bond if not bd.absent),
        )
        scored.append(s)
        if say is not None:
            flag = "" if s.every_marker_better else " (a marker not better than zero force)"
            say(f"      {variant.text()}: {s.tail_rms_mm:.4g} mm on the tail{flag}")
    chosen, why = pick(scored)
    return Choice(chosen, tuple(scored), (a, split), (split, b), tuple(tail.markers), why)


def pick(scored) -> tuple[Variant, str]:
    """The variant the tail chooses among ``scored`` (the module's rule) and, where the tail
    cannot choose, why: no variant predicts it better than zero force (a tail where the body
    coasts or rests, which zero force predicts best), so their differences say nothing of the
    structure; the default variant (the BIC's decision, as ``structure`` makes it) is kept."""
    finite = [s for s in scored if np.isfinite(s.tail_rms_mm)]
    if not any(s.tail_rms_mm < s.tail_zero_force_mm for s in finite):
        lowest = min(finite, key=lambda s: s.tail_rms_mm) if finite else None
        said = (
            f" (the lowest {lowest.tail_rms_mm:.4g} vs {lowest.tail_zero_force_mm:.4g} mm)"
            if lowest is not None
            else ""
        )
        why = (
            f"no variant predicts the tail better than zero force{said}: the tail cannot "
            f"choose; kept the BIC's decision ({Variant().text()})"
        )
        return Variant(), why
    better = [s for s in finite if s.every_marker_better]
    pool = better or finite
    lowest = min(s.tail_rms_mm for s in pool)
    tied = [s for s in pool if s.tail_rms_mm <= (1.0 + TIE) * lowest] or pool
    return min(tied, key=lambda s: (s.bonds, s.tail_rms_mm)).variant, ""


def _overall(predicted: np.ndarray, recorded: np.ndarray) -> float:
    """RMS (mm) over every (frame, marker) term both hold."""
    err2 = np.sum((np.asarray(predicted) - np.asarray(recorded)) ** 2, axis=-1)
    ok = np.isfinite(err2)
    return float(np.sqrt(err2[ok].mean()) * 1000.0) if ok.any() else float("nan")


@dataclass(frozen=True)
class Criterion:
    """A model's one-step BIC on the fitted frames: ``n ln(RSS / n) + k ln n`` (n residual
    coordinates, k free parameters), as :mod:`.structure` decides bonds."""

    rss: float  # m^2
    n: int  # residual coordinates
    k: int  # free parameters (genes)
    rms_mm: float

    @property
    def bic(self) -> float:
        return self.n * float(np.log(max(self.rss, 1e-300) / self.n)) + self.k * float(
            np.log(self.n)
        )

    def record(self) -> dict:
        return {**asdict(self), "bic": self.bic}


def criterion(model: Model, recording, frames: tuple[int, int]) -> Criterion:
    """The one-step BIC of ``model`` on ``frames`` of ``recording`` (every frame predicted
    from the two recorded before it, one Euler step, as the fit's one-step cost)."""
    from ..judge.predictions import one_step
    from ..problem import select_data
    from ..settings import FitSettings

    data = select_data(model, recording, FitSettings(frames=frames))
    rec = np.asarray(data.positions, np.float64)
    one = one_step(model, rec, data.dt)
    err2 = np.sum((one - rec) ** 2, axis=-1)
    complete = np.isfinite(rec).all(axis=(1, 2))
    inputs = np.zeros(rec.shape[0], bool)
    inputs[2:] = complete[1:-1] & complete[:-2]
    counted = np.isfinite(rec).all(axis=-1) & inputs[:, None]  # the terms the cost counts
    bad = counted & ~np.isfinite(err2)
    rss = float("inf") if bad.any() else float(np.sum(err2[counted]))
    terms = int(counted.sum())
    rms = float(np.sqrt(rss / max(terms, 1)) * 1000.0)
    return Criterion(rss=rss, n=terms * rec.shape[-1], k=model.layout.n_genes, rms_mm=rms)
