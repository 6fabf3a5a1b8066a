"""What ``activebonds auto`` says of its outcome: the held-out verdicts and the notes on
what limits them (frames that hardly move, masses not identified, marker noise)."""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

from .folder import Folder

NOISY_ONE_STEP = (
    " (at this marker noise a one-step score is mostly the noise's: the frames-ahead one says "
    "whether the model explains the motion)"
)


@dataclass
class Outcome:
    """What ``auto`` produced: the output folder's state and the held-out evaluation."""

    folder: Folder
    state: dict
    held_out: object  # report.evaluate.Evaluation
    fitted: object

    def verdict_lines(self) -> list[str]:
        """The held-out verdicts, overall and per marker, one step and K frames ahead, then
        what limits them: held-out frames that hardly move (:func:`still_note`), masses the
        fit did not identify (the fit step's note)."""
        notes = [still_note(self.held_out, self.fitted)]
        notes.append((self.state.get("steps", {}).get("fit") or {}).get("masses"))
        return self.held_out.lines() + [n for n in notes if n]

    def verdict(self) -> str:
        """The last line: the held-out one-step and K-ahead verdicts, overall."""
        a, b = self.held_out.frames
        # where the marker noise dominates (the recording smoothed for the structure), a
        # one-step score beats zero force by smoothing the noise, not by the dynamics
        noisy = bool((self.state.get("noise") or {}).get("window"))
        parts = [
            f"{c.what}: {c.overall.text()}"
            + (NOISY_ONE_STEP if noisy and c.what == "one step" else "")
            for c in self.held_out.comparisons
        ]
        return f"verdict, held-out frames {a}:{b}: " + "; ".join(parts)


STILL = 0.1  # held-out frames whose zero-force error is below this share of the fitted ones'


def still_note(held_out, fitted) -> str | None:
    """Where the held-out frames hardly move (zero force's one-step error there below
    :data:`STILL` of its error on the fitted frames), a note that they can hardly judge the
    model's dynamics: doing nothing predicts a body at rest, whatever the model; else None."""
    if held_out.verdict is None or fitted is None or fitted.verdict is None:
        return None
    still, moving = held_out.verdict.zero_force_mm, fitted.verdict.zero_force_mm
    if not (math.isfinite(still) and math.isfinite(moving)) or not still < STILL * moving:
        return None
    a, b = held_out.frames
    return (
        f"note: frames {a}:{b} hardly move (zero force's one-step error {still:.4g} mm there, "
        f"{moving:.4g} mm on the fitted frames): a body nearly at rest is predicted by doing "
        "nothing, so they can hardly judge the model's dynamics; hold out frames that move "
        "(--frames, --held-out)"
    )


def fixed_masses_note(run: Path, flight: Path | None = None) -> str | None:
    """Where the kept run's model has no free mass, a note that its stiffnesses and dampings
    are relative to masses it did not identify; else None. ``flight``: the run that tried
    to identify them on a flight and was not kept (the note then says so, not how to try)."""
    from ..identify.discover.structure_choice import mass_of
    from ..identify.rundir import RunDir
    from ..model import load_model

    spec = load_model(RunDir(run).best_model_path).spec
    if any(spec.free_masses()):
        return None
    kg = {p.name: mass_of(p) for p in spec.particle}
    if len({round(m, 6) for m in kg.values()}) == 1:
        each = f"{next(iter(kg.values())):.4g} kg each"
    else:
        each = ", ".join(f"{n} {m:.4g}" for n, m in list(kg.items())[:8]) + " kg"
        each += " ..." if len(kg) > 8 else ""
    head = (
        f"masses: not identified ({each}): every stiffness and damping is relative to them, "
        "off by as much as a mass is; "
    )
    if flight is not None:
        return head + (
            f"the flight's fit ({flight.name}) did not identify them well enough to keep; "
            "its refinement and uncertainty say how far it got (docs/howto/auto.md)"
        )
    return head + (
        "to identify them, free the masses under total_mass (mass = { value, min, max }) and "
        "refit the kept model, on frames in flight where there are some (docs/howto/auto.md)"
    )


def noise_line(noise) -> str:
    """What the marker ``noise`` makes ``auto`` do, in one line."""
    if not noise.dominated:
        return f"{noise.line()}: negligible, nothing smoothed"
    return (
        f"{noise.line()}: one-step scores would judge the noise, so the structure is chosen on "
        f"positions smoothed over {noise.window} frames (Savitzky-Golay, cubic); the fit "
        "and the held-out scores are on the recording"
    )


class Scored:
    """An evaluation's record (evaluation.json), read back, with its verdict lines."""

    def __init__(self, record: dict):
        from ..identify.judge.burn_in import BurnIn
        from ..identify.judge.verdict import comparisons_from, free_run_advice

        self.record = record
        self.frames = tuple(record["frames"])
        self.comparisons = comparisons_from(record["comparisons"])
        self.burn_in = BurnIn.from_record(record["burn_in"]) if "burn_in" in record else None
        self._advice = free_run_advice(
            record["model"].get("free_run_rms_mm", math.nan), record.get("holds")
        )

    @property
    def verdict(self):
        """The one-step verdict, overall (None without a comparison), as an Evaluation's."""
        return self.comparisons[0].overall if self.comparisons else None

    def lines(self) -> list[str]:
        a, b = self.frames
        out = [line for c in self.comparisons for line in c.lines(f"frames {a}:{b}")]
        after = self.burn_in.lines() if self.burn_in is not None else []
        return out + after + ([self._advice] if self._advice else [])


def absent_note(recording, markers, held_out: tuple[int, int]) -> str | None:
    """The line that says, before anything is fitted, which of ``markers`` are never present
    in the held-out frames (their held-out scores cannot be formed), or None."""
    a, b = held_out
    present = recording.select(list(markers)).window(a, b).mask.any(axis=0)
    absent = [m for m, seen in zip(markers, present, strict=True) if not seen]
    if not absent:
        return None
    return (
        f"note: {len(absent)} of {len(markers)} markers never present in the held-out frames "
        f"{a}:{b} ({', '.join(absent)}): the held-out verdict cannot judge them (a longer "
        "--held-out or other --frames can)"
    )
