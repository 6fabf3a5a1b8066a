"""What ``activebonds auto`` is asked and where it writes: its options, the fitted frames
and the held-out tail, the output folder and its state (``OUT/auto.json``), the fit's
settings."""

from __future__ import annotations

import json
from dataclasses import asdict, dataclass
from pathlib import Path

from ..data.trajectory import frame_window
from ..errors import InputError, option_error

HELD_OUT = 0.2  # the share of the frames held out at the end of the window

AHEAD = 10  # frames ahead of the multi-step verdict
# frames of the held-out free runs' burn-in (the state estimated there, then the run:
# identify.judge.burn_in), where the held-out tail has such a stretch
BURN_IN = 10
POPULATION = 40  # the ES's, small: it starts at the structure's exact optimum
GENERATIONS = 200
CHECKPOINT_EVERY = 50  # generations between checkpoints (Ctrl-C loses at most these)

MIN_FRAMES = 10  # frames of the fitted window and of the held-out tail, at least
STATE = "auto.json"


@dataclass(frozen=True)
class Options:
    """What ``activebonds auto`` is asked (the options recorded in ``OUT/auto.json``)."""

    markers: tuple[str, ...] | None = None
    frames: tuple[int, int | None] = (0, None)
    held_out: float = HELD_OUT
    total_mass: float | None = None
    up: str | None = None
    gravity: bool | None = None
    population: int = POPULATION
    generations: int = GENERATIONS
    seed: int = 0
    ahead: int = AHEAD

    def record(self) -> dict:
        d = asdict(self)
        d["markers"] = list(self.markers) if self.markers else None
        d["frames"] = list(self.frames)
        return d


@dataclass(frozen=True)
class Windows:
    """The fitted frames and the held-out tail, [start, stop) of the recording."""

    fitted: tuple[int, int]
    held_out: tuple[int, int]

    @property
    def validation(self) -> tuple[int, int]:
        """The validation frames: the tail of the fitted frames, their last share beyond
        :data:`~activebonds.identify.discover.structure_choice.TRAIN` (20 %), at least
        :data:`~activebonds.identify.discover.structure_choice.MIN_TAIL` frames: the tail the
        structure step chooses its variant on, and the one ``auto``'s judge scores every
        candidate on. Never the held-out frames."""
        from ..identify.discover.structure_choice import MIN_TAIL, TRAIN

        a, b = self.fitted
        split = a + int(round(TRAIN * (b - a)))
        return (max(a, min(split, b - MIN_TAIL)), b)


def windows(n_frames: int, frames: tuple[int, int | None], held_out: float) -> Windows:
    """The window ``frames`` of a recording of ``n_frames`` split into the fitted frames and
    the held-out tail (its last ``held_out`` share); InputError (one line) if either would
    have fewer than :data:`MIN_FRAMES`."""
    if not (isinstance(held_out, int | float) and 0 < held_out < 1):
        raise InputError("--held-out", f"must be a share of the frames in (0, 1), got {held_out}")
    window = frame_window(n_frames, *frames, "--frames")  # the rule of fit, evaluate, fill
    a, b = window.start, window.stop
    split = b - max(1, round(held_out * (b - a)))
    if split - a < MIN_FRAMES or b - split < MIN_FRAMES:
        raise InputError(
            "--frames",
            f"{a}:{b} is too short: fitting {split - a} frames and holding out {b - split} "
            f"needs at least {MIN_FRAMES} each",
        )
    return Windows((a, split), (split, b))


@dataclass
class Folder:
    """The output folder's files."""

    path: Path

    scaffold = property(lambda self: self.path / "scaffold.toml")
    scaffold_gravity = property(lambda self: self.path / "scaffold-gravity.toml")
    structure = property(lambda self: self.path / "structure.toml")
    structure_record = property(lambda self: self.path / "structure.json")
    ground = property(lambda self: self.path / "ground.toml")
    run = property(lambda self: self.path / "run")
    run_ground = property(lambda self: self.path / "run-ground")
    run_shot = property(lambda self: self.path / "run-shot")
    flight = property(lambda self: self.path / "flight.toml")
    run_flight = property(lambda self: self.path / "run-flight")
    masses = property(lambda self: self.path / "masses.toml")
    run_masses = property(lambda self: self.path / "run-masses")
    evaluation = property(lambda self: self.path / "evaluation.json")
    report = property(lambda self: self.path / "report.html")
    state = property(lambda self: self.path / STATE)

    def read_state(self) -> dict | None:
        try:
            return json.loads(self.state.read_text(encoding="utf-8"))
        except (OSError, ValueError):
            return None

    def write_state(self, state: dict) -> None:
        from ..atomic import write_text_atomic

        write_text_atomic(self.state, json.dumps(state, indent=2) + "\n")


def prepare(out: Path, recording_path: Path, options: Options, overwrite: bool) -> dict | None:
    """The state of an earlier run of the same recording and options in ``out`` (to continue
    it), or None to start anew; InputError for a folder this cannot use. With ``overwrite``,
    an earlier ``auto`` folder is replaced (any other folder is refused)."""
    from ..identify.rundir import RunDir

    folder = Folder(out)
    if not out.exists():
        if not out.absolute().parent.is_dir():
            raise InputError(out, "the folder it goes in does not exist")
        return None
    if not out.is_dir():
        raise InputError(out, "is a file, not a folder")
    state = folder.read_state()
    if state is None:
        if any(out.iterdir()):
            raise InputError(
                out, "exists and is not a folder of activebonds auto; choose another --out"
            )
        return None
    same = state.get("sha256") == RunDir.sha256(recording_path) and state.get(
        "options"
    ) == json.loads(json.dumps(options.record()))
    if overwrite:
        return None
    if not same:
        raise InputError(
            out,
            "holds a run of another recording or other options; pass --overwrite to replace "
            "it, or the same recording and options to continue it",
        )
    return state


def fit_settings(options: Options, split: Windows):
    """The fit's settings (its cost still to choose); InputError naming a bad option."""
    from pydantic import ValidationError

    from ..identify.settings import FitSettings

    try:
        return FitSettings(
            frames=split.fitted,
            population=options.population,
            generations=options.generations,
            seed=options.seed,
            init="model",
            checkpoint_every=CHECKPOINT_EVERY,
        )
    except ValidationError as e:
        raise option_error(e) from None
