"""The verdict on a score: does the model predict better than no force at all?

Every place that scores a model (``fit``'s summary, ``evaluate``, ``report``, ``demo``, a
sweep's summary, :class:`~activebonds.identify.driver.FitResult` and
:class:`~activebonds.report.evaluate.Evaluation`) says it with these words and this rule,
beside the zero-force (constant-velocity) predictor on the same terms:

* **better** when the model's RMS error is below the zero-force predictor's by at least
  :data:`MARGIN_PCT` percent: ``better than zero force by 12.3 % (1.59 vs 1.81 mm)``;
* otherwise it is not: ``worse than zero force (1.842 vs 1.811 mm): the model does not explain
  this motion`` (``no better than zero force`` when the two agree within the margin either
  way, as a model whose forces vanish does);
* ``not judged`` when either number is missing (NaN: nothing to predict).

The judge's score records are one family, :class:`Score`: the model's error beside zero
force's on the same terms (RMS, in :attr:`Score.unit`) and the verdict on them. A
:class:`Verdict` is those two numbers alone; a :class:`Comparison` one kind of prediction
(one step, or K frames ahead: the model's free run from each recorded state) on one window,
overall and per marker, whose :meth:`Comparison.lines` are what people read; a
:class:`ParticleScore` one particle's one-step and free-run scores. Their JSON is
:class:`Record`'s (non-finite numbers as strings), as is that of one predictor's free-run
numbers (:class:`~activebonds.identify.judge.metrics.FreeRunMetrics`). Plain numbers only:
nothing here computes a prediction (:mod:`activebonds.identify.judge.predictions` does).
"""

from __future__ import annotations

import math
import typing
from collections.abc import Sequence
from dataclasses import MISSING, dataclass, fields
from typing import ClassVar

MARGIN_PCT = 0.1  # better by less than this (percent of the zero-force error): not better
EXPLAINS_NOT = "the model does not explain this motion"
ADVICE_MM = 1000.0  # a free run this far from the recording (RMS) gets a line of advice


def _number(x) -> float:
    try:
        return float(x)
    except (TypeError, ValueError):
        return math.nan


class Record:
    """The JSON of a score record (a frozen dataclass): :meth:`from_dict` reads every field
    back by its type, from the key :attr:`KEYS` names (default: the field's name); a missing
    key takes the field's default. Non-finite numbers are written as the strings 'inf',
    '-inf' and 'nan' (:func:`plain`) and read back by :attr:`number`."""

    KEYS: ClassVar[dict[str, str]] = {}
    number: ClassVar = staticmethod(float)  # a number back from its JSON value

    @classmethod
    def from_dict(cls, data: dict):
        """Back from the record's dict (raises KeyError, TypeError or ValueError if
        malformed)."""
        hints = typing.get_type_hints(cls)
        values = {}
        for f in fields(cls):
            key = cls.KEYS.get(f.name, f.name)
            if key not in data and f.default is not MISSING:
                continue
            values[f.name] = _read(hints[f.name], data[key], cls.number)
        return cls(**values)


def _read(kind, value, number):
    """A JSON value back as the field type ``kind``: a number, a bool, a string or a tuple
    of them."""
    if typing.get_origin(kind) is tuple:
        item = typing.get_args(kind)[0]
        return tuple(_read(item, v, number) for v in value)
    return number(value) if kind is float else kind(value)


@dataclass(frozen=True)
class Score(Record):
    """THE score record: the model's RMS error beside the zero-force predictor's on the same
    terms (in :attr:`unit`), and the verdict on them. Every record of the judge that sets
    the model beside zero force is one (:class:`Verdict`, :class:`Comparison`,
    :class:`ParticleScore`'s scores)."""

    model_mm: float
    zero_force_mm: float
    unit: ClassVar[str] = "mm"
    number: ClassVar = staticmethod(_number)  # None or text: NaN, not judged

    @property
    def judged(self) -> bool:
        return not (math.isnan(self.model_mm) or math.isnan(self.zero_force_mm))

    @property
    def gain_pct(self) -> float:
        """How much smaller the model's error is, in percent of the zero-force error
        (negative: larger; NaN when not judged or the zero-force error is 0)."""
        if not self.judged or self.zero_force_mm <= 0 or math.isinf(self.zero_force_mm):
            return math.nan
        if math.isinf(self.model_mm):
            return -math.inf
        return 100.0 * (1.0 - self.model_mm / self.zero_force_mm)

    @property
    def better(self) -> bool | None:
        """True when the model beats zero force by at least :data:`MARGIN_PCT` %, False when
        it does not, None when not judged."""
        if not self.judged:
            return None
        gain = self.gain_pct
        if math.isnan(gain):  # zero force exact (or infinite): only an exact model ties it
            return bool(self.model_mm < self.zero_force_mm)
        return bool(gain >= MARGIN_PCT)

    @property
    def word(self) -> str:
        """``better``, ``worse``, ``no better`` or ``not judged``: a table's cell."""
        if self.better is None:
            return "not judged"
        if self.better:
            return "better"
        worse = self.model_mm > self.zero_force_mm * (1.0 + MARGIN_PCT / 100.0)
        return "worse" if worse else "no better"

    def text(self) -> str:
        """The verdict in words, with both numbers."""
        m, z, unit = _mm(self.model_mm), _mm(self.zero_force_mm), self.unit
        if self.better is None:
            return f"not judged ({m} vs {z} {unit} for zero force)"
        if self.better:
            gain = self.gain_pct
            by = f"by {gain:.3g} %" if math.isfinite(gain) else "(zero force fails)"
            return f"better than zero force {by} ({m} vs {z} {unit})"
        return f"{self.word} than zero force ({m} vs {z} {unit}): {EXPLAINS_NOT}"

    @property
    def overall(self) -> Verdict:
        """The two numbers alone, and their verdict."""
        return Verdict(self.model_mm, self.zero_force_mm)

    def pair(self) -> dict:
        """``{"model": ..., "zero_force": ...}``, plain JSON values."""
        return {"model": plain(self.model_mm), "zero_force": plain(self.zero_force_mm)}

    def to_dict(self) -> dict:
        """The verdict's plain JSON values (non-finite numbers as the strings 'inf', 'nan')."""
        return {
            "model_mm": plain(self.model_mm),
            "zero_force_mm": plain(self.zero_force_mm),
            "gain_pct": plain(self.gain_pct),
            "better": self.better,
            "verdict": self.word,
            "text": self.text(),
        }


@dataclass(frozen=True)
class Verdict(Score):
    """A score of the two numbers alone: ``better than zero force by 12.3 % (1.59 vs 1.81
    mm)``."""


def verdict(model_mm, zero_force_mm) -> Verdict:
    """The :class:`Verdict` of two RMS errors (mm; None counts as missing)."""
    return Verdict(_number(model_mm), _number(zero_force_mm))


def _mm(x: float) -> str:
    if math.isnan(x):
        return "—"
    return "∞" if math.isinf(x) else f"{x:.4g}"


def plain(x: float) -> float | str:
    """A number as JSON: itself, or 'inf', '-inf' or 'nan'."""
    return float(x) if math.isfinite(x) else str(float(x))


@dataclass(frozen=True)
class Comparison(Score):
    """One kind of prediction on one window: the model's and the zero-force predictor's RMS
    errors (mm), overall (pooled over every term) and per marker."""

    horizon: int  # frames ahead: 1 for the one-step prediction
    markers: tuple[str, ...]
    model_per_marker: tuple[float, ...]
    zero_force_per_marker: tuple[float, ...]
    terms: int = 0  # (start, marker) terms counted
    KEYS: ClassVar[dict[str, str]] = {
        "model_per_marker": "model_per_marker_mm",
        "zero_force_per_marker": "zero_force_per_marker_mm",
    }

    @property
    def what(self) -> str:
        """``one step`` or ``10 frames ahead``."""
        return "one step" if self.horizon == 1 else f"{self.horizon} frames ahead"

    @property
    def per_marker(self) -> dict[str, Verdict]:
        return {
            m: Verdict(a, b)
            for m, a, b in zip(
                self.markers, self.model_per_marker, self.zero_force_per_marker, strict=True
            )
        }

    def worse_markers(self) -> list[str]:
        """The markers where the model is not better than zero force (judged ones only)."""
        return [m for m, v in self.per_marker.items() if v.better is False]

    def markers_text(self) -> str:
        """``better than zero force at every marker (7)`` or ``not better than zero force at
        2 of 7 markers: Head 0.79 vs 0.39 mm, ...``."""
        judged = {m: v for m, v in self.per_marker.items() if v.judged}
        if not judged:
            return "no marker judged"
        worse = [m for m, v in judged.items() if not v.better]
        if not worse:
            return f"better than zero force at every marker ({len(judged)})"
        listed = ", ".join(
            f"{m} {_mm(judged[m].model_mm)} vs {_mm(judged[m].zero_force_mm)} mm" for m in worse
        )
        return f"not better than zero force at {len(worse)} of {len(judged)} markers: {listed}"

    def lines(self, label: str) -> list[str]:
        """Two lines: ``verdict, LABEL, one step: better than zero force by ...`` and the
        markers where it is not."""
        head = f"verdict, {label}, {self.what}"
        return [f"{head}: {self.overall.text()}", f"{head}, per marker: {self.markers_text()}"]

    def to_dict(self) -> dict:
        return {
            "horizon": self.horizon,
            "model_mm": plain(self.model_mm),
            "zero_force_mm": plain(self.zero_force_mm),
            "markers": list(self.markers),
            "model_per_marker_mm": [plain(x) for x in self.model_per_marker],
            "zero_force_per_marker_mm": [plain(x) for x in self.zero_force_per_marker],
            "terms": int(self.terms),
            "verdict": self.overall.to_dict(),
            "worse_markers": self.worse_markers(),
        }


@dataclass(frozen=True)
class ParticleScore:
    """One particle's two :class:`Score` records: one step, and the free run from the first
    free-run start (as :class:`~activebonds.identify.judge.metrics.FreeRunMetrics`')."""

    particle: str
    marker: str
    one_step: Score
    free_run: Score

    # the four numbers by the names evaluate's readers know
    one_step_rms_mm = property(lambda self: self.one_step.model_mm)
    zero_force_one_step_rms_mm = property(lambda self: self.one_step.zero_force_mm)
    free_run_rms_mm = property(lambda self: self.free_run.model_mm)
    zero_force_free_run_rms_mm = property(lambda self: self.free_run.zero_force_mm)

    def to_dict(self) -> dict:
        return {
            "particle": self.particle,
            "marker": self.marker,
            "one_step_rms_mm": self.one_step.pair(),
            "free_run_rms_mm": self.free_run.pair(),
        }


def comparisons_from(records: Sequence[dict] | None) -> list[Comparison]:
    """:class:`Comparison` objects back from their dicts (none for a record without them)."""
    return [Comparison.from_dict(r) for r in records or ()]


def lines(label: str, comparisons: Sequence[Comparison]) -> list[str]:
    """Every comparison's :meth:`Comparison.lines` under one label."""
    return [line for c in comparisons for line in c.lines(label)]


def holds(model, data=None) -> dict:
    """What holds or drives a model's body, for :func:`free_run_advice`: ``gravity`` (a
    nonzero gravity), ``contacts`` (its ground contacts), ``anchors`` (its unary springs) and
    ``drive`` (a rhythmic drive); with the recorded window ``data`` (its ``positions`` [F, P,
    D] and ``mask`` [F, P]), ``repeats``: whether it repeats itself
    (:func:`~activebonds.data.period.recording_period`, of the heights along the model's
    gravity, of every coordinate without one). Plain JSON values, kept in the records."""
    import numpy as np

    from ... import bonds
    from ...data.period import recording_period

    counts = model.bond_counts()
    gravity = np.asarray(model.params.gravity, float)
    out = {
        "gravity": bool(np.linalg.norm(gravity) > 0),
        "contacts": int(counts.get(bonds.contact.KIND.name, 0)),
        "anchors": int(counts.get(bonds.unary.KIND.name, 0)),
        "drive": model.spec.drive is not None,
    }
    if data is not None:
        up = -gravity if out["gravity"] else None
        out["repeats"] = bool(np.isfinite(recording_period(data.positions, data.mask, up)))
    return out


DRIVE = "a rhythmic drive ([drive] and neural bonds)"


def free_run_advice(free_run_rms_mm, held: dict | None = None) -> str | None:
    """One line of advice for a free run that leaves the recording by metres (RMS above
    :data:`ADVICE_MM`, or non-finite), None otherwise. It depends on what holds the model
    (``held``, from :func:`holds`; None: not known, as in older records):

    * with ground contacts: they did not keep it on the recording's path; anchors or a drive
      (what it lacks of them), stiffer contacts, or judging it over a shorter horizon;
    * gravity and no contacts: the body falls; ground contacts (``scaffold`` writes them),
      anchors or a drive;
    * neither: nothing holds or drives it; anchors or a drive.

    A rhythmic drive is advised only for a recording that repeats itself (``repeats``, or
    not known): a thrown or passive body that does not is told of contacts, anchors and
    gravity only.
    """
    x = _number(free_run_rms_mm)
    if math.isnan(x) or x <= ADVICE_MM:
        return None
    far = "goes non-finite" if math.isinf(x) else f"ends {x / 1000:.3g} m (RMS) from the recording"
    if held is None:
        return (
            f"advice: the free run {far}: nothing holds the body or drives it; add ground "
            "contacts (gravity without support falls), anchors (unary springs) or a rhythmic "
            "drive"
        )
    repeats = held.get("repeats") is not False  # unknown (an older record): as if it did
    lacks = [
        what
        for what, has, applies in (
            ("anchors (unary springs)", held.get("anchors"), True),
            (DRIVE, held.get("drive"), repeats),
        )
        if applies and not has
    ]
    n = int(held.get("contacts") or 0)
    if n:
        add = f"add {_either(lacks)}, " if lacks else ""
        return (
            f"advice: the free run {far} although the model has {n} ground contact"
            f"{'s' if n != 1 else ''}: they do not hold it on the recording's path; {add}"
            "make the contacts stiffer (raise their stiffness and its bounds), or judge it "
            "over a shorter horizon (evaluate --horizon, the frames-ahead comparison) than a "
            "free run of the whole window"
        )
    if held.get("gravity"):
        options = ["ground contacts (activebonds scaffold writes them)", *lacks]
        return (
            f"advice: the free run {far}: the model has gravity and no ground contacts, so "
            f"the body falls; add {_either(options)}"
        )
    if not repeats:
        ground = "gravity with ground contacts (activebonds scaffold writes them)"
        if lacks:
            return (
                f"advice: the free run {far}: nothing holds the body (the recording does not "
                f"repeat itself: no rhythmic drive); add {_either([*lacks, ground])}"
            )
        return (
            f"advice: the free run {far} although the model has anchors: make them stiffer, "
            f"add {ground}, or judge it over a shorter horizon (evaluate --horizon)"
        )
    if not lacks:
        return (
            f"advice: the free run {far} although the model has anchors and a rhythmic "
            "drive: stiffer anchors, or judge it over a shorter horizon (evaluate --horizon)"
        )
    return f"advice: the free run {far}: nothing holds the body or drives it; add {_either(lacks)}"


def _either(options: list[str]) -> str:
    return options[0] if len(options) == 1 else f"{', '.join(options[:-1])} or {options[-1]}"


def judged_comparisons(records: dict) -> dict[str, list[Comparison]]:
    """The comparisons post-fit stages' records hold (``records``: stage name -> record):
    ``"fitted"`` from the baselines stage (the fitted frames), ``"held_out"`` from the
    validation stage (the validation frames), where those ran."""
    out = {}
    for key, stage in (("fitted", "baselines"), ("held_out", "validation")):
        if "judged" in (records.get(stage) or {}):
            out[key] = comparisons_from(records[stage]["judged"])
    return out


def fit_verdict(records: dict) -> tuple[str, Verdict] | None:
    """The one-step verdict of a fit from its stages' records: on the held-out frames when
    there are some, else on the fitted frames, with which (None before the baselines ran)."""
    found = judged_comparisons(records)
    for key in ("held_out", "fitted"):
        if found.get(key):
            return key.replace("_", "-") + " frames", found[key][0].overall
    return None


def short_text(v: Verdict) -> str:
    """``better than zero force by 31.6 %``, ``worse than zero force``, ``not judged``."""
    if v.better is None:
        return "not judged"
    if v.better and math.isfinite(v.gain_pct):
        return f"better than zero force by {v.gain_pct:.3g} %"
    return f"{v.word} than zero force"
