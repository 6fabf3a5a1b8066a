"""A model's free runs scored as a gait, beside the zero-force predictor's
(:mod:`activebonds.report.gait` gives the numbers; this module runs the predictors).

The feet are, in order of precedence: the particles the caller names; the particles the
model puts in contact with a surface (its one-particle bonds of a kind with a
:attr:`~activebonds.bonds.BondKind.reach`: they push only where the particle reaches the
surface); the lowest markers by mean height (:func:`~activebonds.report.gait.lowest_markers`).
Up is the caller's axis, else against the model's gravity, else the recording's guess
(:func:`~activebonds.data.orientation.guess_ground`). The model's free runs start at the
recorded frames ``s - 1`` and ``s`` of the window (:func:`~activebonds.identify.judge.metrics.
free_run_from`); the zero-force predictor's run at constant velocity from the same frames.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from .. import bonds
from ..data import Trajectory
from ..data.orientation import AXES
from ..errors import InputError
from ..identify.judge.metrics import free_run_from
from ..model import Model
from . import gait as g


@dataclass(frozen=True, eq=False)
class GaitEvaluation:
    """A model and the zero-force predictor scored as gaits on a recorded window."""

    feet: tuple[str, ...]  # particle names
    feet_from: str  # how the feet were found, in words
    up: tuple[float, ...]
    up_from: str
    starts: tuple[int, ...]  # frames of the window
    run_frames: int  # frames of each run (STRIDES recorded periods)
    recording: g.GaitFeatures
    model: g.GaitScore
    zero_force: g.GaitScore
    model_runs: np.ndarray  # [S, N, P, D]
    zero_force_runs: np.ndarray
    recorded: np.ndarray  # [F, P, D] the window
    particles: tuple[str, ...]
    first_frame: int = 0  # the window's first frame in the recording (for the text)

    def better(self) -> dict[str, bool]:
        """Per number, whether the model is closer to the recording than zero force."""
        m, z = self.model, self.zero_force
        return {
            "period": _lt(m.period_error, z.period_error),
            "excursion": _lt(_worst(m.excursion_ratio), _worst(z.excursion_ratio)),
            "body": _lt(m.body_distance_mm, z.body_distance_mm),
            "cycle": _lt(m.cycle_rms_mm, z.cycle_rms_mm),
        }

    def record(self) -> dict:
        """Plain JSON values (non-finite floats as 'inf', '-inf' or 'nan')."""
        r = self.recording
        return g.plain(
            {
                "feet": list(self.feet),
                "feet_from": self.feet_from,
                "up": list(self.up),
                "up_from": self.up_from,
                "starts": [self.first_frame + s for s in self.starts],
                "run_frames": self.run_frames,
                "strides": g.STRIDES,
                "targets": targets(),
                "recording": {
                    "period_frames": r.period_frames,
                    "excursion_mm": list(r.excursion_mm),
                    "body_distance_mm": r.body_distance_mm,
                    "own_wander_mm": r.own_wander_mm,
                    "spread_mm": r.spread_mm,
                    "spread_shape_mm": r.spread_shape_mm,
                },
                "model": self.model.to_dict(),
                "zero_force": self.zero_force.to_dict(),
                "better_than_zero_force": self.better(),
            }
        )

    def rows(self) -> list[tuple[str, ...]]:
        """The compact table: (number, recording, model, pass, zero force, pass, model
        better than zero force, target)."""
        r, m, z = self.recording, self.model, self.zero_force
        better = self.better()

        def ok(x: bool) -> str:
            return "pass" if x else "FAIL"

        def yes(x: bool) -> str:
            return "yes" if x else "no"

        rows = [
            (
                "period (frames)",
                _num(r.period_frames),
                _num(m.period_frames),
                ok(m.period_ok),
                _num(z.period_frames),
                ok(z.period_ok),
                yes(better["period"]),
                f"within {g.PERIOD_TOLERANCE:.0%}",
            )
        ]
        for i, foot in enumerate(self.feet):
            rows.append(
                (
                    f"{foot} excursion (mm)",
                    _num(r.excursion_mm[i]),
                    _num(m.excursion_ratio[i] * r.excursion_mm[i]),
                    ok(abs(m.excursion_ratio[i] - 1.0) <= g.EXCURSION_TOLERANCE),
                    _num(z.excursion_ratio[i] * r.excursion_mm[i]),
                    ok(abs(z.excursion_ratio[i] - 1.0) <= g.EXCURSION_TOLERANCE),
                    yes(_lt(abs(m.excursion_ratio[i] - 1), abs(z.excursion_ratio[i] - 1))),
                    f"within {g.EXCURSION_TOLERANCE:.0%}",
                )
            )
        rows += [
            (
                "body from mean position, max (mm)",
                _num(r.body_distance_mm),
                _num(m.body_distance_mm),
                ok(m.body_ok),
                _num(z.body_distance_mm),
                ok(z.body_ok),
                yes(better["body"]),
                f"<= {g.OWN_FACTOR:g}x its own over a run's span ({_num(r.own_wander_mm)}): "
                f"{_num(m.body_limit_mm)}",
            ),
            (
                "cycle-average RMS (mm; recording: spread)",
                _num(r.spread_mm),
                _num(m.cycle_rms_mm),
                ok(m.cycle_ok),
                _num(z.cycle_rms_mm),
                ok(z.cycle_ok),
                yes(better["cycle"]),
                f"<= {g.OWN_FACTOR:g}x its own spread: {_num(m.cycle_limit_mm)}",
            ),
            (
                "  its shape, means removed (mm)",
                _num(r.spread_shape_mm),
                _num(m.cycle_shape_rms_mm),
                "",
                _num(z.cycle_shape_rms_mm),
                "",
                yes(_lt(m.cycle_shape_rms_mm, z.cycle_shape_rms_mm)),
                "(information)",
            ),
        ]
        return rows

    @property
    def caption(self) -> str:
        up = _up_text(self.up)
        return (
            f"Gait: {len(self.starts)} free runs of {g.STRIDES} strides ({self.run_frames} "
            f"frames) from frames {', '.join(str(self.first_frame + s) for s in self.starts)}; "
            f"up {up} ({self.up_from}); feet {', '.join(self.feet)} ({self.feet_from}). "
            "Period: median over runs; excursion: per foot, median over runs; body: largest "
            "over runs and frames; cycle RMS: median over runs, after the best phase shift."
        )


COLUMNS = (
    "",
    "recording",
    "model",
    "",
    "zero force",
    "",
    "model better",
    "target",
)


def targets() -> dict[str, float]:
    return {
        "period_tolerance": g.PERIOD_TOLERANCE,
        "excursion_tolerance": g.EXCURSION_TOLERANCE,
        "own_factor": g.OWN_FACTOR,
        "own_floor_mm": g.OWN_FLOOR_MM,
    }


def _lt(a: float, b: float) -> bool:
    a = float("inf") if np.isnan(a) else a
    b = float("inf") if np.isnan(b) else b
    return bool(a < b)


def _worst(ratios: Sequence[float]) -> float:
    r = np.asarray(ratios, np.float64)
    return float(np.max(np.where(np.isnan(r), np.inf, np.abs(r - 1.0)))) if r.size else np.nan


def _num(x: float) -> str:
    if np.isnan(x):
        return "—"
    if np.isinf(x):
        return "∞"
    return f"{x:.4g}"


def _up_text(up: Sequence[float]) -> str:
    u = np.asarray(up, np.float64)
    i = int(np.argmax(np.abs(u)))
    if np.count_nonzero(u) == 1 and i < len(AXES):
        return ("+" if u[i] > 0 else "-") + AXES[i]
    return str([float(v) for v in u])


def contact_feet(model: Model) -> list[int]:
    """The particles of the model's one-particle bonds whose kind acts only where the
    particle reaches a surface (:attr:`~activebonds.bonds.BondKind.reach`), in order."""
    names = model.particle_names
    found = {
        names.index(b.particles[0])
        for b in model.spec.bond
        if not getattr(b, "absent", False)
        and (kind := bonds.get(b.kind)).arity == 1
        and kind.reach is not None
    }
    return sorted(found)


def choose_up(model: Model, data: Trajectory, up: Sequence[float] | None):
    if up is not None:
        return tuple(float(u) for u in up), "named"
    grav = np.asarray(model.params.gravity, np.float64)
    if np.linalg.norm(grav) > 0:
        return tuple(float(v) for v in -grav / np.linalg.norm(grav)), "against the model's gravity"
    from ..data.orientation import guess_ground

    found = guess_ground(data)
    if found is None:
        raise InputError("--up", "the recording does not say which way is up: name it")
    return tuple(found.normal), "the recording's guess"


def choose_feet(model: Model, data: Trajectory, up, feet: Sequence[str] | None):
    names = model.particle_names
    if feet:
        out = []
        for f in feet:
            if f in names:
                out.append(names.index(f))
            elif f in data.markers:
                out.append(list(data.markers).index(f))
            else:
                raise InputError("--feet", f"'{f}' is not a particle of the model")
        return sorted(set(out)), "named"
    found = contact_feet(model)
    if found:
        return found, "the model's contacts"
    return g.lowest_markers(data.positions, up), "the lowest markers by mean height"


def recorded_gait(model: Model, data: Trajectory, feet=None, up=None):
    """(the recording's gait :func:`~.gait.features`, (up, whence), (feet, whence)), the
    vertical and the feet found from the model or the recording where not given; an
    :class:`InputError` where the feet are not some of the markers or their heights have no
    period in ``data`` (no gait)."""
    rec = np.asarray(data.positions, np.float64)
    up_vec, up_from = choose_up(model, data, up)
    feet_idx, feet_from = choose_feet(model, data, up_vec, feet)
    if not feet_idx or len(feet_idx) == rec.shape[1]:
        raise InputError("--feet", "name the feet: some markers, not all")
    ref = g.features(rec, up_vec, feet_idx)
    if not np.isfinite(ref.period_frames):
        raise InputError(
            "--gait",
            f"the heights of {', '.join(model.particle_names[i] for i in feet_idx)} have no "
            "period in these frames (no gait to compare with)",
        )
    return ref, (up_vec, up_from), (feet_idx, feet_from)


def gait_evaluation(
    model: Model,
    data: Trajectory,
    *,
    substeps: int = 1,
    integrator: str = "euler",
    feet: Sequence[str] | None = None,
    up: Sequence[float] | None = None,
    offset: int = 0,
    starts: int = g.STARTS,
    strides: int = g.STRIDES,
    first_frame: int = 0,
    before: np.ndarray | None = None,
) -> GaitEvaluation:
    """The model's and zero force's free runs from ``starts`` frames of ``data`` (markers in
    the model's particle order), ``strides`` recorded periods each, scored as gaits against
    ``data`` (``offset``: frames from the model's time origin to ``data``'s first frame;
    ``first_frame``: that frame's number in the recording, for the text; ``before``: the
    recorded frames between the origin and ``data``).
    Raises :class:`InputError` when the feet's heights have no period in ``data``."""
    rec = np.asarray(data.positions, np.float64)
    ref, (up_vec, up_from), (feet_idx, feet_from) = recorded_gait(model, data, feet, up)
    n = g.stride_frames(ref, strides)
    chosen = g.gait_starts(rec, starts)
    runs = np.stack(
        [
            free_run_from(model, rec, data.dt, s, n, substeps, integrator, offset, before=before)
            for s in chosen
        ]
    )
    zero = g.constant_velocity_runs(rec, chosen, n)
    return GaitEvaluation(
        feet=tuple(model.particle_names[i] for i in feet_idx),
        feet_from=feet_from,
        up=tuple(up_vec),
        up_from=up_from,
        starts=tuple(chosen),
        run_frames=n,
        recording=ref,
        model=g.summarise([g.score_run(r, ref) for r in runs], ref),
        zero_force=g.summarise([g.score_run(r, ref) for r in zero], ref),
        model_runs=runs,
        zero_force_runs=zero,
        recorded=rec,
        particles=tuple(model.particle_names),
        first_frame=int(first_frame),
    )
