"""Which model of the gait family (:mod:`~activebonds.identify.discover.gait`) a rhythmic
recording needs, chosen on frames its fit did not see.

The fitted frames are halved: each variant is built and solved (exact least squares) on the
first half, its rhythm and signals found there alone, and judged on the second half with the
model's time from the first half's start (the drive's phase tracked from there,
``evaluate --origin``): its markers' one-step errors beside zero force's, the gait targets of
its free runs (period within 3 %, every foot's excursion within 25 %, the body's wander and the
cycle-average RMS within 1.25x the recording's own, :mod:`~activebonds.report.gait`), its
free runs after a burn-in beside the recording's mean gait, and its error ``ahead`` frames
ahead. The order (:func:`key`): fewest markers worse than zero force one step, then most
targets met, then the lowest error ahead. The variants are searched one change at a time from
:data:`START` (:data:`CHANGES`), a change kept where it judges better. The chosen variant is
built and solved again on every fitted frame.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, replace

import numpy as np

from ..identify.discover.gait import GaitVariant, find_rhythm, gait_spec, solve, survey
from .judge import finite_or_inf

START = GaitVariant()
# one change at a time from the start, in this order, each kept where it judges better
CHANGES = (
    ("kappa", (0.08, 0.32)),
    ("harmonics", (4, 8)),
    ("decay", (1.0, 8.0)),
    ("quadrature", (False,)),
)
BURN_IN = 10  # frames of the free runs' burn-in on the judged half


@dataclass(frozen=True)
class Judged:
    """A variant's scores on the judged half (mm)."""

    variant: GaitVariant
    worse_markers: int
    targets_met: int
    targets: int
    one_step_mm: float
    zero_force_one_step_mm: float
    ahead_mm: float
    zero_force_ahead_mm: float

    def key(self) -> tuple:
        return (self.worse_markers, -self.targets_met, finite_or_inf(self.ahead_mm))

    def line(self) -> str:
        return (
            f"{self.variant.text()}: one step {self.one_step_mm:.3g} mm (zero force "
            f"{self.zero_force_one_step_mm:.3g}), {self.worse_markers} marker(s) worse; "
            f"{self.targets_met} of {self.targets} gait targets; ahead {self.ahead_mm:.4g} mm "
            f"(zero force {self.zero_force_ahead_mm:.4g})"
        )


@dataclass(frozen=True)
class Chosen:
    """The chosen gait model (a ModelSpec solved on every fitted frame), every variant
    judged, and the rhythm and signals' words."""

    spec: object
    judged: tuple[Judged, ...]
    best: Judged
    notes: tuple[str, ...]


def judge(model, recording, frames, origin: int, ahead: int, variant) -> Judged:
    """``model`` judged on ``frames`` of ``recording`` (its time from ``origin``)."""
    from ..errors import InputError
    from ..report.evaluate import evaluate

    options = {"frames": frames, "origin": origin, "horizon": ahead}
    try:
        record = evaluate(model, recording, gait=True, burn_in=BURN_IN, **options).record()
    except InputError:  # the judged frames too short for a burn-in, or feet with no period
        record = evaluate(model, recording, **options).record()
    one, far = record["comparisons"][0], record["comparisons"][-1]
    gait = record.get("gait") or {}
    passes = dict(gait["model"]["passes"]) if gait else {}
    burn = record.get("burn_in") or {}
    if burn.get("template_within") is not None:
        passes["burn_in"] = float(burn["model_within"]) >= float(burn["template_within"])
    return Judged(
        variant,
        len(one["worse_markers"]),
        sum(bool(v) for v in passes.values()),
        len(passes),
        float(one["model_mm"]),
        float(one["zero_force_mm"]),
        float(far["model_mm"]),
        float(far["zero_force_mm"]),
    )


def choose(
    recording,
    fitted: tuple[int, int],
    ahead: int,
    up=None,
    say: Callable[[str], None] = print,
    each: Callable[[str], None] | None = None,
) -> Chosen | None:
    """The gait model of ``recording``'s ``fitted`` frames, or None (said) where they are not
    rhythmic (:attr:`~activebonds.identify.discover.gait.Rhythm.rhythmic`) or no signal
    repeats; ``each``: where each variant's scores are said (default ``say``)."""
    each = say if each is None else each
    a, s = fitted
    m = a + (s - a) // 2
    x = np.asarray(recording.positions, np.float64)
    names = list(recording.markers)
    built = _builder(x, recording.rate, up)
    found = built(a, s)
    if found is None:
        say("      gait: not proposed: the fitted frames repeat nothing (no stride period)")
        return None
    rhythm, _ = found
    say(f"      gait: {rhythm.line()}")
    if not rhythm.rhythmic:
        return None
    if built(a, m) is None:
        say(
            "      gait: not proposed: the fitted frames' first half has no stride period of "
            "its own to fit a variant on (fit more strides)"
        )
        return None
    tried: dict[GaitVariant, Judged] = {}

    def tried_on(variant: GaitVariant) -> Judged:
        if variant not in tried:
            rh, signals = built(a, m)
            spec = gait_spec(x[a:m], names, rh, signals, variant)
            model = solve(spec, recording, (a, m))
            tried[variant] = judge(model, recording, (m, s), a, ahead, variant)
            each(f"      gait {tried[variant].line()}")
        return tried[variant]

    best = tried_on(START)
    for field, values in CHANGES:
        for value in values:
            candidate = tried_on(replace(best.variant, **{field: value}))
            if candidate.key() < best.key():
                best = candidate
    rhythm, signals = found
    spec = gait_spec(x[a:s], names, rhythm, signals, best.variant)
    solved = solve(spec, recording, (a, s))
    notes = (rhythm.line(), f"drive read from {signals[0].text(names)}")
    return Chosen(solved.spec, tuple(tried.values()), best, notes)


def _builder(x, rate, up):
    """(rhythm, signals) of frames a:b of positions ``x`` (NaN where missing), cached; None
    where nothing repeats there."""
    cache: dict[tuple[int, int], object] = {}
    axes = tuple(range(x.shape[2])) if up is None else (int(np.argmax(np.abs(up))),)

    def built(a: int, b: int):
        if (a, b) not in cache:
            window = x[a:b]
            rhythm = find_rhythm(window, rate, None, up)
            if rhythm is None:
                cache[(a, b)] = None
            else:
                signals = survey(window, rhythm.frequency, rate, axes)
                cache[(a, b)] = (rhythm, signals) if signals else None
        return cache[(a, b)]

    return built
