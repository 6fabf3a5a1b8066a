"""From a recording to an evaluated model in one call: ``activebonds auto``.

The steps, each one's output in the output folder ``OUT``:

1. **scaffold** (:func:`~.scaffold.scaffold`) on the fitted frames: ``OUT/scaffold.toml``;
2. **structure** (:func:`~.structure.structure_of`): ``OUT/structure.toml`` and
   ``OUT/structure.json``. Backward elimination solves every remaining structure at each step
   (about ``n^2 / 2`` exact least squares for ``n`` candidates, each dearer with more of
   them: on the 41-marker human walk's 110 candidates, a second a solve, hours in all), so
   above :data:`MAX_DECIDED` candidates nothing is eliminated: every candidate is kept,
   its linear parameters at their exact least-squares optimum, and the run says so. Where
   the scaffold guessed gravity (no ``--up``, no ``--gravity``) and the springs' exact
   optimum is still worse than zero force (nothing found holds the body up: the contacts'
   reach leaves out too little), the scaffold is written again without gravity (the first
   kept in ``OUT/scaffold-gravity.toml``) and decided again, and the run says so;
3. **fit** (:func:`~.driver.fit`) from the structure's values (``init = "model"``), the
   refinement's cost chosen as ``fit --cost auto`` does (:func:`~.cost_choice.choose_cost`:
   multiple shooting where a window has at most 300 unknowns, else the restart cost):
   ``OUT/run/``;
4. **evaluate** (:func:`~activebonds.report.evaluate.evaluate`) the fitted model on the
   held-out tail (the last :data:`HELD_OUT` of the frames, never seen by steps 1-3) and on
   the fitted frames, one step and :data:`AHEAD` frames ahead, beside zero force:
   ``OUT/evaluation.json``;
5. **report** (:func:`~activebonds.report.write_report`) over the fitted and held-out frames:
   ``OUT/report.html``.

``OUT/auto.json`` records the recording (path, SHA-256), the options and each finished
step's wall time. Run again with the same recording and options, the finished steps are kept
and an interrupted fit resumes from its checkpoint.
"""

from __future__ import annotations

import json
import math
import shutil
import time
from collections.abc import Callable
from dataclasses import asdict, dataclass
from pathlib import Path

from .errors import InputError

HELD_OUT = 0.2  # the share of the frames held out at the end of the window
MAX_DECIDED = 40  # candidate springs: above, structure keeps them all (no elimination)
AHEAD = 10  # frames ahead of the multi-step verdict
POPULATION = 40  # the ES's, small: it starts at the structure's exact optimum
GENERATIONS = 200
CHECKPOINT_EVERY = 50  # generations between checkpoints (Ctrl-C loses at most these)
MIN_FRAMES = 10  # frames of the fitted window and of the held-out tail, at least
STEPS = ("scaffold", "structure", "fit", "evaluate", "report")
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


def windows(n_frames: int, frames: tuple[int, int | None], held_out: float) -> Windows:
    """The window ``frames`` of a recording of ``n_frames`` split into the fitted frames and
    the held-out tail (its last ``held_out`` share); InputError (one line) if either would
    have fewer than :data:`MIN_FRAMES`."""
    if not (isinstance(held_out, int | float) and 0 < held_out < 1):
        raise InputError("--held-out", f"must be a share of the frames in (0, 1), got {held_out}")
    a, b = frames
    b = n_frames if b is None else min(b, n_frames)
    if a >= b:
        raise InputError("--frames", f"{a}:{b} holds no frame of the {n_frames}")
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
    run = property(lambda self: self.path / "run")
    evaluation = property(lambda self: self.path / "evaluation.json")
    report = property(lambda self: self.path / "report.html")
    state = property(lambda self: self.path / STATE)

    def read_state(self) -> dict | None:
        try:
            return json.loads(self.state.read_text(encoding="utf-8"))
        except (OSError, ValueError):
            return None

    def write_state(self, state: dict) -> None:
        from .atomic import write_text_atomic

        write_text_atomic(self.state, json.dumps(state, indent=2) + "\n")


def prepare(out: Path, recording_path: Path, options: Options, overwrite: bool) -> dict | None:
    """The state of an earlier run of the same recording and options in ``out`` (to continue
    it), or None to start anew; InputError for a folder this cannot use. With ``overwrite``,
    an earlier ``auto`` folder is replaced (any other folder is refused)."""
    from .identify.rundir import sha256_file

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
    same = state.get("sha256") == sha256_file(recording_path) and state.get(
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


@dataclass
class Outcome:
    """What ``auto`` produced: the output folder's state and the held-out evaluation."""

    folder: Folder
    state: dict
    held_out: object  # report.evaluate.Evaluation
    fitted: object

    def verdict_lines(self) -> list[str]:
        """The held-out verdicts, overall and per marker, one step and K frames ahead."""
        return self.held_out.lines()

    def verdict(self) -> str:
        """The last line: the held-out one-step and K-ahead verdicts, overall."""
        a, b = self.held_out.frames
        parts = [f"{c.what}: {c.overall.text()}" for c in self.held_out.comparisons]
        return f"verdict, held-out frames {a}:{b}: " + "; ".join(parts)


def run(
    recording_path: Path,
    out: Path,
    options: Options,
    *,
    overwrite: bool = False,
    say: Callable[[str], None] = print,
    fit_progress=None,
) -> Outcome:
    """Every step of ``activebonds auto`` (see the module's docstring), each announced by
    ``say``; ``fit_progress(generations, starting)``: a context manager yielding the fit's
    progress (with a ``status``), or None. Bad input raises InputError before anything is
    written."""
    from .data import read_trajectory
    from .identify.rundir import sha256_file
    from .identify.scaffold import scaffold

    recording = read_trajectory(recording_path)
    if options.ahead < 1:
        raise InputError("--ahead", f"must be at least 1, got {options.ahead}")
    split = windows(recording.n_frames, options.frames, options.held_out)
    fit_settings(options, split)  # the fit's options checked before anything is written
    found = scaffold(  # checks the markers, the mass, the vertical: before anything is written
        recording,
        markers=list(options.markers) if options.markers else None,
        frames=split.fitted,
        total_mass=options.total_mass,
        up=options.up,
        gravity=options.gravity,
        name=recording_path.stem,
    )
    state = prepare(out, recording_path, options, overwrite)
    folder = Folder(out)
    if state is None:
        if overwrite and folder.read_state() is not None:
            shutil.rmtree(out)
        out.mkdir(exist_ok=True)
        state = {
            "recording": str(recording_path),
            "sha256": sha256_file(recording_path),
            "options": options.record(),
            "fitted_frames": list(split.fitted),
            "held_out_frames": list(split.held_out),
            "steps": {},
        }
        folder.write_state(state)
    else:
        done = [s for s in STEPS if s in state["steps"]]
        say(f"continuing {out}: {', '.join(done) or 'no step'} finished")
    steps = state["steps"]
    a, s = split.fitted
    b = split.held_out[1]
    say(
        f"frames {a}:{b}: fitting {a}:{s} ({s - a} frames), holding out {s}:{b} "
        f"({b - s} frames, the last {100 * options.held_out:g} %)"
    )

    def step(k: int, name: str, what: str, body: Callable[[], str]) -> None:
        if name in steps:
            say(f"[{k}/5] {name}: done before ({steps[name]['seconds']:.0f} s)")
            return
        say(f"[{k}/5] {name}: {what}")
        t0 = time.perf_counter()
        note = body()
        seconds = time.perf_counter() - t0
        steps[name] = {"seconds": round(seconds, 1), "note": note}
        folder.write_state(state)
        say(f"[{k}/5] {name}: {note} ({seconds:.0f} s)")

    def do_scaffold() -> str:
        from .atomic import write_text_atomic
        from .model import loads_model

        loads_model(found.text, str(folder.scaffold))
        for note in found.notes:
            say(f"      {note}")
        write_text_atomic(folder.scaffold, found.text)
        return (
            f"{found.particles} particles, {found.bonds} candidate springs, {found.contacts} "
            f"ground contacts, gravity {found.gravity}: {folder.scaffold}"
        )

    step(1, "scaffold", "a candidate model of the fitted frames", do_scaffold)
    step(
        2,
        "structure",
        "which candidate springs the fitted frames need (BIC, exact least squares)",
        lambda: _structure(folder, recording, split, options, say),
    )
    step(
        3,
        "fit",
        f"from the structure's values, population {options.population}, "
        f"{options.generations} generations, then the refinement",
        lambda: _fit(folder, recording_path, recording, split, options, say, fit_progress),
    )
    held, fitted = _evaluations(folder, recording, split, options)
    step(
        4,
        "evaluate",
        f"the fitted model on the held-out frames {s}:{b} and the fitted ones, one step and "
        f"{options.ahead} frames ahead, beside zero force",
        lambda: _write_evaluation(folder, held(), fitted()),
    )
    step(
        5,
        "report",
        "the HTML report of the run over the fitted and held-out frames",
        lambda: _report(folder, b - a),
    )
    state["total_seconds"] = round(sum(v["seconds"] for v in steps.values()), 1)
    folder.write_state(state)
    record = json.loads(folder.evaluation.read_text(encoding="utf-8"))
    return Outcome(folder, state, _Scored(record["held_out"]), _Scored(record["fitted"]))


def _structure(folder: Folder, recording, split: Windows, options: Options, say) -> str:
    from .atomic import write_text_atomic
    from .identify.scaffold import scaffold
    from .model import load_model, loads_model, save_model

    result, eliminate, n = _decide(load_model(folder.scaffold), recording, split, say)
    guessed = options.gravity is None and options.up is None
    if guessed and result.spec.gravity is not None and result.rms_mm >= result.zero_force_rms_mm:
        say(
            f"      structure: with the guessed gravity the springs' exact optimum is worse than "
            f"zero force ({result.rms_mm:.4g} vs {result.zero_force_rms_mm:.4g} mm: nothing "
            "found holds the body up); scaffolding again without gravity, the first candidate "
            f"kept in {folder.scaffold_gravity} (--up AXIS or --gravity insists on it)"
        )
        found = scaffold(
            recording,
            markers=list(options.markers) if options.markers else None,
            frames=split.fitted,
            total_mass=options.total_mass,
            gravity=False,
            name=recording_name(recording),
        )
        loads_model(found.text, str(folder.scaffold))
        write_text_atomic(folder.scaffold_gravity, folder.scaffold.read_text(encoding="utf-8"))
        write_text_atomic(folder.scaffold, found.text)
        result, eliminate, n = _decide(load_model(folder.scaffold), recording, split, say)
    save_model(result.spec, folder.structure)
    record = {"eliminated": eliminate, "candidates": n, "max_decided": MAX_DECIDED}
    write_text_atomic(
        folder.structure_record, json.dumps({**record, **result.record()}, indent=2) + "\n"
    )
    kept = sum(d.present for d in result.decisions) if eliminate else n
    return (
        f"{kept} of {n} springs kept{'' if eliminate else ' (not decided)'}; one-step RMS "
        f"{result.rms_mm:.4g} mm (zero force {result.zero_force_rms_mm:.4g} mm): "
        f"{folder.structure}"
    )


def recording_name(recording) -> str:
    """The model's name: the recording file's stem."""
    return Path(str(recording.source or "scaffold")).stem


def _decide(model, recording, split: Windows, say):
    """(structure_of's result, whether it eliminated, the candidates) of a scaffold."""
    from .identify.settings import FitSettings
    from .identify.structure import candidates, structure_of

    n = len(candidates(model.spec))
    eliminate = n <= MAX_DECIDED
    if not eliminate:
        say(
            f"      structure: {n} candidate springs, more than {MAX_DECIDED}: no elimination "
            f"(its exact least squares grow with the square of the candidates, hours here); "
            "every candidate kept, at its exact least-squares optimum"
        )
    result = structure_of(model, recording, FitSettings(frames=split.fitted), 0, eliminate)
    return result, eliminate, n


def _fit(folder, recording_path, recording, split, options, say, fit_progress) -> str:
    from contextlib import nullcontext

    from .identify.cost_choice import choose_cost
    from .identify.driver import fit, resume
    from .identify.problem import select_recordings, variant
    from .identify.rundir import RunDir, newest_checkpoint, read_status
    from .model import load_model

    settings = fit_settings(options, split)
    spec = variant(load_model(folder.structure), settings.bonds)
    data = select_recordings(spec, [recording], settings)[0]
    settings, why = choose_cost(
        settings, spec.layout.n_genes, data.positions.shape[1] * data.positions.shape[2], False
    )
    say(f"      {why}")
    run_dir = RunDir(folder.run)
    progress = fit_progress or (lambda total, starting: nullcontext(None))
    status = read_status(folder.run).get("status") if run_dir.is_run() else None
    with progress(settings.generations, "compiling") as bar:
        hooks = {"progress": bar, "status": bar.status} if bar is not None else {}
        if status not in (None, "completed") and newest_checkpoint(folder.run) is not None:
            say(f"      resuming the interrupted fit in {folder.run}")
            result = resume(folder.run, **hooks)
        else:
            result = fit(
                folder.structure, recording_path, settings, out=folder.run, overwrite=True, **hooks
            )
    if result.status != "completed":
        raise RuntimeError(f"the fit ended {result.status}; see {folder.run}")
    for line in result.lines():
        say(f"      {line}")
    return f"best one-step RMS {result.rms_mm:.4g} mm on the fitted frames: {folder.run}"


def fit_settings(options: Options, split: Windows):
    """The fit's settings (its cost still to choose); InputError naming a bad option."""
    from pydantic import ValidationError

    from .identify.settings import FitSettings

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
        first = e.errors()[0]
        name = "--" + str(first["loc"][0]).replace("_", "-") if first["loc"] else "options"
        raise InputError(name, first["msg"].removeprefix("Value error, ")) from None


class _Scored:
    """An evaluation's record (evaluation.json), read back, with its verdict lines."""

    def __init__(self, record: dict):
        from .identify.verdict import comparisons_from, free_run_advice

        self.record = record
        self.frames = tuple(record["frames"])
        self.comparisons = comparisons_from(record["comparisons"])
        self._advice = free_run_advice(
            record["model"].get("free_run_rms_mm", math.nan), record.get("holds")
        )

    def lines(self) -> list[str]:
        a, b = self.frames
        out = [line for c in self.comparisons for line in c.lines(f"frames {a}:{b}")]
        return out + ([self._advice] if self._advice else [])


def _evaluations(folder: Folder, recording, split: Windows, options: Options):
    """Two thunks: the fitted model evaluated on the held-out frames and on the fitted ones."""

    def on(frames):
        def evaluate_there():
            from .identify.rundir import RunDir
            from .model import load_model
            from .report.evaluate import evaluate

            model = load_model(RunDir(folder.run).best_model_path)
            return evaluate(model, recording, frames=frames, horizon=options.ahead)

        return evaluate_there

    return on(split.held_out), on(split.fitted)


def _write_evaluation(folder: Folder, held, fitted) -> str:
    from .atomic import write_text_atomic

    record = {"held_out": held.record(), "fitted": fitted.record()}
    write_text_atomic(folder.evaluation, json.dumps(record, indent=2) + "\n")
    one = held.comparisons[0]
    return (
        f"held out, one step: {one.model_mm:.4g} mm (zero force {one.zero_force_mm:.4g} mm): "
        f"{folder.evaluation}"
    )


def _report(folder: Folder, frames: int) -> str:
    from .report import write_report

    return str(write_report(folder.run, folder.report, frames=frames))
