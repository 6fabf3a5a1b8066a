"""From a recording to an evaluated model in one call: ``activebonds auto``.

The steps, each one's output in the output folder ``OUT``:

1. **scaffold** (:func:`~.scaffold.scaffold`) on the fitted frames: ``OUT/scaffold.toml``;
2. **structure** (:mod:`~.identify.structure_choice`, :func:`~.structure.structure_of`):
   ``OUT/structure.toml`` and ``OUT/structure.json``. Up to :data:`MAX_DECIDED` candidates,
   variants of the scaffold's linear part (its masses as scaffolded, in inverse proportion to
   each marker's acceleration or conserving momentum; its anchors as springs, as dampers
   alone or none; the candidates the BIC keeps or every one) are fitted by exact least squares
   on the first 80 % of the fitted frames and scored on the rest, the validation tail; the
   variant with the lowest one-step RMS there among those better than zero force at every
   marker (else the lowest; within 0.1 %, the fewest bonds) is decided and solved again on every
   fitted frame. Where marker noise dominates the one-step scores
   (:func:`~.data.smoothing.noise_of`, said before step 1), this step sees the fitted frames
   smoothed (:func:`smoothed`). Where the scaffold has gravity
   or ground contacts, they are added to it in ``OUT/ground.toml``, its linear parameters
   solved again with the contacts held (the start of the ground fit). Backward elimination
   solves every remaining structure at each step (about ``n^2 / 2`` exact least squares for
   ``n`` candidates, each dearer with more of them: on the 41-marker human walk's 110
   candidates, a second a solve, hours in all), so above :data:`MAX_DECIDED` candidates
   nothing is eliminated nor chosen: every candidate is kept, its linear parameters at their
   exact least-squares optimum, and the run says so. There, where the scaffold guessed
   gravity (no ``--up``, no ``--gravity``) and the springs' exact optimum is still worse than
   zero force (nothing found holds the body up: the contacts' reach leaves out too little),
   the scaffold is written again without gravity (the first kept in
   ``OUT/scaffold-gravity.toml``) and decided again, and the run says so;
3. **fit** (:func:`~.driver.fit`) of the structure from its exact optimum (``init =
   "model"``: the ES seeded there) on the one-step cost, whose optimum it is, and by which
   the pipeline judges a model: ``OUT/run/``. Where there is a ground model, it is fitted the
   same way from its own start (``OUT/run-ground/``) and kept where its one-step BIC on the
   fitted frames is lower than the structure's (its contacts and gravity earn their
   parameters) or ``--up`` / ``--gravity`` insists on gravity, else the structure's fit is
   (:func:`~.structure_choice.criterion`).
   Where the kept model has gravity and contacts and the fitted frames hold a flight
   (:func:`~.identify.flight_masses.longest_flight`), its masses are identified there with its
   bonds by multiple shooting, then its contacts fitted with them held (``OUT/run-flight/``,
   ``OUT/run-masses/``: :func:`_masses`), which is kept.
   Where marker noise dominates, the kept model is refined by multiple shooting
   (``OUT/run-shot/``, :func:`_shoot`), up to :data:`MAX_SHOT` parameters.
   ``auto.json`` names the kept run (``steps.fit.run``). Elsewhere, for parameters unbiased by
   marker noise, refit the kept model with ``fit --cost shooting``;
4. **evaluate** (:func:`~activebonds.report.evaluate.evaluate`) the kept model on the
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
MAX_DECIDED = 40  # candidate bonds: above, structure keeps them all (no elimination)
AHEAD = 10  # frames ahead of the multi-step verdict
POPULATION = 40  # the ES's, small: it starts at the structure's exact optimum
GENERATIONS = 200
CHECKPOINT_EVERY = 50  # generations between checkpoints (Ctrl-C loses at most these)
# where marker noise dominates the one-step scores (:class:`~.data.smoothing.Noise`), the kept
# model is refined by multiple shooting, whose optimum noise does not bias, up to this many
# parameters (the stage of the 5-mass, 24-parameter MuJoCo recording: 5-16 s)
MAX_SHOT = 100
SHOOTING = {
    "cost": "shooting",
    "horizon": (10,),
    "integrator": "verlet",
    "substeps": 5,
    # a model that explains the motion converges in tens of steps (MuJoCo's tendons: 20-48);
    # one that does not crawls, and a crawl's end is no better an answer
    "max_steps": 100,
}
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
        from .atomic import write_text_atomic

        write_text_atomic(self.state, json.dumps(state, indent=2) + "\n")


def prepare(out: Path, recording_path: Path, options: Options, overwrite: bool) -> dict | None:
    """The state of an earlier run of the same recording and options in ``out`` (to continue
    it), or None to start anew; InputError for a folder this cannot use. With ``overwrite``,
    an earlier ``auto`` folder is replaced (any other folder is refused)."""
    from .identify.rundir import RunDir

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
        notes.append((self.state.get("parts", {}).get("fit") or {}).get("masses"))
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
    from .identify.discover.structure_choice import mass_of
    from .identify.rundir import RunDir
    from .model import load_model

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
    from .identify.discover.scaffold import scaffold
    from .identify.rundir import RunDir

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
    noise = noise_of_fitted(recording, split, options)
    structural = smoothed(recording, split, noise.window)
    state = prepare(out, recording_path, options, overwrite)
    folder = Folder(out)
    if state is None:
        if overwrite and folder.read_state() is not None:
            shutil.rmtree(out)
        out.mkdir(exist_ok=True)
        state = {
            "recording": str(recording_path),
            "sha256": RunDir.sha256(recording_path),
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
    say(noise_line(noise))
    state["noise"] = asdict(noise)

    def step(k: int, name: str, what: str, body: Callable[[], str]) -> None:
        if name in steps:
            say(f"[{k}/5] {name}: done before ({steps[name]['seconds']:.0f} s)")
            return
        state["parts"] = {}  # what a step records beside its note
        say(f"[{k}/5] {name}: {what}")
        t0 = time.perf_counter()
        note = body()
        seconds = time.perf_counter() - t0
        parts = state.pop("parts").get(name, {})
        steps[name] = {"seconds": round(seconds, 1), "note": note, **parts}
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
            f"{found.particles} particles, {found.bonds} candidate bonds, {found.contacts} "
            f"ground contacts, gravity {found.gravity}: {folder.scaffold}"
        )

    step(1, "scaffold", "a candidate model of the fitted frames", do_scaffold)
    step(
        2,
        "structure",
        "which candidate bonds the fitted frames need (exact least squares, BIC, a validation "
        "tail)",
        lambda: _structure(folder, structural, split, options, say),
    )
    step(
        3,
        "fit",
        f"from the structure's exact optimum, population {options.population}, "
        f"{options.generations} generations, then the refinement",
        lambda: _fit(
            folder, recording_path, structural, split, options, say, fit_progress, state, noise
        ),
    )
    kept = folder.path / steps["fit"].get("run", "run")
    held, fitted = _evaluations(kept, recording, split, options)
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
        lambda: _report(kept, folder.report, b - a, folder.evaluation, _made(state)),
    )
    state["total_seconds"] = round(sum(v["seconds"] for v in steps.values()), 1)
    folder.write_state(state)
    record = json.loads(folder.evaluation.read_text(encoding="utf-8"))
    return Outcome(folder, state, _Scored(record["held_out"]), _Scored(record["fitted"]))


def _structure(folder: Folder, recording, split: Windows, options: Options, say) -> str:
    from .identify.discover.structure import candidates
    from .model import load_model

    scaffolded = load_model(folder.scaffold)
    n = len(candidates(scaffolded.spec))
    if n > MAX_DECIDED:
        return _undecided(folder, recording, split, options, say)
    from .atomic import write_text_atomic
    from .identify.discover.structure_choice import Variant, choose, decide
    from .model import save_model

    choice = choose(scaffolded, recording, split.fitted, say)
    variant = choice.chosen if choice is not None else Variant()
    if choice is not None:
        say(f"      {choice.line()}")
    result = decide(scaffolded, recording, split.fitted, variant)
    save_model(result.spec, folder.structure)
    ground = _ground(folder, scaffolded.spec, result.spec, recording, split)
    record = {
        "eliminated": variant.decided,
        "candidates": n,
        "max_decided": MAX_DECIDED,
        "variant": variant.text(),
        "choice": choice.record() if choice is not None else None,
        "ground": ground,
    }
    write_text_atomic(
        folder.structure_record, json.dumps({**record, **result.record()}, indent=2) + "\n"
    )
    kept = sum(not b.absent for b in result.spec.bond)
    extra = (
        f"; with gravity and contacts: {folder.ground} ({ground['rms_mm']:.4g} mm)"
        if ground
        else ""
    )
    return (
        f"{kept} of {len(result.spec.bond)} bonds kept ({variant.text()}); one-step RMS "
        f"{result.rms_mm:.4g} mm (zero force {result.zero_force_rms_mm:.4g} mm): "
        f"{folder.structure}{extra}"
    )


def _ground(folder: Folder, scaffolded, decided, recording, split: Windows) -> dict | None:
    """The decided structure with the scaffold's gravity and the bonds the exact least
    squares does not solve (ground contacts), its linear parameters solved again with the
    contacts held: OUT/ground.toml, or None where the scaffold has neither."""
    from . import bonds
    from .identify.costs.restart import make_windows
    from .identify.discover.structure import exact_optimum
    from .identify.discover.structure_choice import criterion
    from .identify.problem import select_data
    from .identify.settings import FitSettings
    from .model import build, save_model

    extra = [b for b in scaffolded.bond if bonds.get(b.kind).linear is None]
    if scaffolded.gravity is None and not extra:
        if folder.ground.exists():
            folder.ground.unlink()
        return None
    spec = decided.model_copy(update={"gravity": scaffolded.gravity, "bond": decided.bond + extra})
    model = build(spec)
    data = select_data(model, recording, FitSettings(frames=split.fitted))
    solved, _ = exact_optimum(model, make_windows(data.positions, data.mask, data.dt, 1))
    save_model(solved, folder.ground)
    # its one-step RMS as the fit and `evaluate` score it (the exact optimum's own residual
    # holds the contacts at their start and is not the model's prediction)
    rms = criterion(build(solved), recording, split.fitted).rms_mm
    return {"contacts": len(extra), "gravity": scaffolded.gravity is not None, "rms_mm": rms}


def _undecided(folder: Folder, recording, split: Windows, options: Options, say) -> str:
    """Above MAX_DECIDED candidates: every candidate kept at its exact optimum."""
    from .atomic import write_text_atomic
    from .identify.discover.scaffold import scaffold
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
    if folder.ground.exists():
        folder.ground.unlink()
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


def noise_line(noise) -> str:
    """What the marker ``noise`` makes ``auto`` do, in one line."""
    if not noise.dominated:
        return f"{noise.line()}: negligible, nothing smoothed"
    return (
        f"{noise.line()}: one-step scores would judge the noise, so the structure is chosen on "
        f"positions smoothed over {noise.window} frames (Savitzky-Golay, cubic); the fit "
        "and the held-out scores are on the recording"
    )


def noise_of_fitted(recording, split: Windows, options: Options):
    """:func:`~.data.smoothing.noise_of` the fitted frames of the markers asked."""
    from .data.smoothing import noise_of

    seen = recording.select(list(options.markers)) if options.markers else recording
    a, s = split.fitted
    return noise_of(seen.positions[a:s])


def smoothed(recording, split: Windows, window: int):
    """``recording`` with its fitted frames smoothed over ``window`` frames (0: as it is),
    each marker's run of recorded frames apart, never across the held-out boundary: the
    recording the structure is chosen on."""
    import dataclasses

    from .data.smoothing import smooth_positions

    if not window:
        return recording
    a, s = split.fitted
    positions = recording.positions.copy()
    positions[a:s] = smooth_positions(positions[a:s], recording.mask[a:s], window)
    return dataclasses.replace(recording, positions=positions)


def recording_name(recording) -> str:
    """The model's name: the recording file's stem."""
    return Path(str(recording.source or "scaffold")).stem


def _decide(model, recording, split: Windows, say):
    """(structure_of's result, whether it eliminated, the candidates) of a scaffold."""
    from .identify.discover.structure import candidates, structure_of
    from .identify.settings import FitSettings

    n = len(candidates(model.spec))
    eliminate = n <= MAX_DECIDED
    if not eliminate:
        say(
            f"      structure: {n} candidate bonds, more than {MAX_DECIDED}: no elimination "
            f"(its exact least squares grow with the square of the candidates, hours here); "
            "every candidate kept, at its exact least-squares optimum"
        )
    result = structure_of(model, recording, FitSettings(frames=split.fitted), 0, eliminate)
    return result, eliminate, n


def _fit(folder, recording_path, recording, split, options, say, fit_progress, state, noise) -> str:
    """The structure fitted from its exact optimum on the one-step cost (OUT/run)
    (``recording``: the one the structure was chosen on, smoothed as ``noise`` says); where
    there is a ground model, it fitted too (OUT/run-ground, the cost as fit --cost auto) and
    kept where its one-step BIC on the fitted frames is lower; where ``noise`` dominates, the
    kept one refined by multiple shooting (:func:`_shoot`). Records the kept run's name in
    the fit step of ``state``."""
    from .identify.discover.structure_choice import criterion
    from .identify.rundir import RunDir
    from .model import load_model

    settings = fit_settings(options, split)
    one_step = settings.model_copy(update={"cost": "restart", "horizon": (1,)})
    say(
        "      cost: one step (the structure's linear parameters start at the exact optimum of "
        "this cost; the ES seeded there keeps it or finds better)"
    )
    linear = _fit_into(folder.run, folder.structure, recording_path, one_step, say, fit_progress)
    kept, why = folder.run, ""
    if folder.ground.exists():
        say(
            f"      the model with gravity and ground contacts ({folder.ground}), from its "
            "exact optimum with the contacts held: the same cost, one step, by which the two "
            "are compared"
        )
        ground_rms = _fit_into(
            folder.run_ground, folder.ground, recording_path, one_step, say, fit_progress
        )
        scores = {
            path: criterion(load_model(RunDir(path).best_model_path), recording, split.fitted)
            for path in (folder.run, folder.run_ground)
        }
        plain, ground = scores[folder.run], scores[folder.run_ground]
        insisted = options.gravity is True or options.up is not None
        if ground.bic < plain.bic or insisted:
            kept = folder.run_ground
        # the criterion's RMS is on the frames the structure was chosen on (smoothed where
        # the noise dominates), the runs' own on the recording: said apart
        on = f"with the positions smoothed over {noise.window} frames" if noise.window else ""
        why = (
            f"; {folder.run.name} {linear:.4g} mm, {folder.run_ground.name} {ground_rms:.4g} "
            f"mm; kept {kept.name}"
            + (" (--up or --gravity insists on gravity)" if insisted else "")
            + f": one-step BIC{' ' + on if on else ''} {ground.bic:.6g} with gravity and "
            f"contacts ({ground.rms_mm:.4g} mm, {ground.k} parameters), {plain.bic:.6g} "
            f"without ({plain.rms_mm:.4g} mm, {plain.k})"
        )
        if kept == folder.run_ground:
            linear = ground_rms
        state["parts"]["fit"] = {
            "criterion": {"run": plain.record(), "run-ground": ground.record()}
        }
    headline = f"best one-step RMS {linear:.4g} mm on the fitted frames: {kept}"
    kept, weighed = _masses(
        folder, kept, recording_path, recording, split, settings, say, fit_progress
    )
    why += weighed
    if noise.dominated:
        kept, shot = _shoot(folder, kept, recording_path, settings, say, fit_progress)
        why += shot
    state["parts"].setdefault("fit", {})["run"] = kept.name
    tried = folder.run_flight if folder.run_flight.exists() else None
    masses = fixed_masses_note(kept, tried) if kept != folder.run_masses else None
    if masses:
        say(f"      {masses}")
        state["parts"]["fit"]["masses"] = masses
    return f"{headline}{why}"


def _masses(
    folder, kept: Path, recording_path, recording, split, settings, say, fit_progress
) -> tuple[Path, str]:
    """Where the kept run's masses are fixed and its model has gravity and contacts, and the
    fitted frames hold a flight (:func:`~.identify.flight_masses.longest_flight`): its masses
    freed under ``total_mass`` and identified with its bonds by multiple shooting on the
    flight (:data:`SHOOTING`, OUT/run-flight), then its contacts fitted on every fitted
    frame with the masses held and the bond parameters the flight determined well
    (:func:`~.identify.flight_masses.determined`; the one-step cost, OUT/run-masses), which
    is kept where it predicts the fitted frames :data:`SHOOTING`'s horizon ahead better than
    the kept run (as :func:`_shoot` judges). Up to :data:`MAX_SHOT` parameters. (kept run,
    note)."""
    import csv

    import numpy as np

    from .identify.discover.flight_masses import (
        HOLD,
        anchors,
        determined,
        freed,
        held,
        longest_flight,
    )
    from .identify.problem import select_data
    from .identify.rundir import RunDir
    from .identify.settings import FitSettings
    from .model import load_model, save_model

    model = load_model(RunDir(kept).best_model_path)
    if any(model.spec.free_masses()):
        return kept, ""
    data = select_data(model, recording, FitSettings(frames=split.fitted))
    flight = longest_flight(model.spec, data.positions, split.fitted[0])
    if flight is None:
        return kept, ""
    a, b = flight
    genes = model.layout.n_genes + len(model.spec.particle)
    if genes > MAX_SHOT:
        say(
            f"      masses: frames {a}:{b} are in flight, but identifying the masses there by "
            f"multiple shooting is left to fit --cost shooting above {MAX_SHOT} parameters "
            f"({genes} here)"
        )
        return kept, f"; masses not identified ({genes} parameters)"
    dropped = anchors(model.spec)
    say(
        f"      masses: frames {a}:{b} are in flight (every contact off its plane: gravity "
        f"and the bonds alone act): {kept.name}'s masses freed under total_mass and "
        f"identified there with its bonds by multiple shooting (horizon "
        f"{SHOOTING['horizon'][0]}, {SHOOTING['substeps']} Verlet substeps)"
        + (
            f"; its {dropped} anchor(s) dropped: nothing in the room holds a body in flight"
            if dropped
            else ""
        )
    )
    save_model(freed(model.spec), folder.flight)
    shooting = settings.model_copy(
        update={**SHOOTING, "frames": (a, b), "population": 4, "generations": 1}
    )
    _fit_into(folder.run_flight, folder.flight, recording_path, shooting, say, fit_progress)
    weighed = load_model(RunDir(folder.run_flight).best_model_path)
    masses = np.asarray(weighed.params.mass, np.float64)
    bond_genes = sum(g.name.startswith("bond[") for g in weighed.layout.genes)
    with (folder.run_flight / "uncertainty.csv").open(encoding="utf-8") as f:
        hold = determined(csv.DictReader(f))
    each = ", ".join(f"{p.name} {m:.4g}" for p, m in zip(model.spec.particle, masses, strict=True))
    say(
        f"      masses: {each} kg (run-flight: their intervals in its uncertainty.csv); the "
        f"contacts fitted on every fitted frame with these masses held, and the "
        f"{len(hold)} bond parameter(s) the flight determined within {100 * HOLD:g} % (of "
        f"{bond_genes}), the rest fitted again (one step, as {kept.name} was)"
    )
    save_model(held(weighed.spec, masses, hold), folder.masses)
    one_step = settings.model_copy(update={"cost": "restart", "horizon": (1,)})
    rms = _fit_into(folder.run_masses, folder.masses, recording_path, one_step, say, fit_progress)
    before, after = _ahead_mm(kept), _ahead_mm(folder.run_masses)
    h = SHOOTING["horizon"][0]
    if not after < before:  # a flight fit gone wrong (short of its optimum, a misfit) shows here
        say(
            f"      masses: the model with the flight's masses predicts the fitted frames {h} "
            f"ahead no better than {kept.name}'s ({after:.4g} vs {before:.4g} mm): the flight "
            f"did not identify them well enough (see {folder.run_flight.name}'s refinement and "
            f"uncertainty); {kept.name} kept"
        )
        return (
            kept,
            f"; masses from the flight {a}:{b} not kept ({h} ahead {after:.4g} vs {before:.4g} mm)",
        )
    return folder.run_masses, (
        f"; masses identified on the flight {a}:{b} ({folder.run_flight.name}), the contacts "
        f"fitted with them held: {folder.run_masses} ({rms:.4g} mm; {h} ahead on the fitted "
        f"frames {after:.4g} vs {before:.4g} mm)"
    )


def _shoot(folder, kept: Path, recording_path, settings, say, fit_progress) -> tuple[Path, str]:
    """Where marker noise dominates: the kept run's model refined by multiple shooting
    (:data:`SHOOTING`, OUT/run-shot), whose optimum the noise does not bias, unless it has
    more than :data:`MAX_SHOT` parameters; the shot model kept in its place where it predicts
    the fitted frames the shooting's horizon ahead better (a family that cannot explain the
    motion, such as springs without the gravity and ground they stand on, shoots worse).
    (kept run, note)."""
    from .identify.rundir import RunDir
    from .model import load_model

    start = RunDir(kept).best_model_path
    genes = load_model(start).layout.n_genes
    if genes > MAX_SHOT:
        say(
            f"      the one-step optimum is biased by the marker noise (its dampings above "
            f"all); multiple shooting, which is not, is left to fit --cost shooting above "
            f"{MAX_SHOT} parameters ({genes} here)"
        )
        return kept, f"; not shot ({genes} parameters)"
    say(
        f"      the marker noise biases the one-step optimum (its dampings above all): "
        f"{kept.name}'s model refined by multiple shooting (horizon {SHOOTING['horizon'][0]}, "
        f"{SHOOTING['substeps']} Verlet substeps), which it does not bias"
    )
    shooting = settings.model_copy(update={**SHOOTING, "population": 4, "generations": 1})
    _fit_into(folder.run_shot, start, recording_path, shooting, say, fit_progress)
    before, after = _ahead_mm(kept), _ahead_mm(folder.run_shot)
    h = SHOOTING["horizon"][0]
    if not after < before:  # shooting fits several frames ahead: judged there, fitted frames
        say(
            f"      the shot model predicts the fitted frames {h} ahead no better than "
            f"{kept.name}'s ({after:.4g} vs {before:.4g} mm): the model family does not "
            f"explain this motion well enough for shooting to help; {kept.name} kept"
        )
        return kept, f"; shot, not kept ({h} ahead {after:.4g} vs {before:.4g} mm)"
    return folder.run_shot, (
        f"; refined by multiple shooting: {folder.run_shot} ({h} frames ahead on the fitted "
        f"frames {after:.4g} vs {before:.4g} mm)"
    )


def _ahead_mm(run: Path) -> float:
    """A run's RMS (mm) :data:`SHOOTING`'s horizon frames ahead on its fitted frames (its
    baselines' ``judged`` comparisons; inf where it has none)."""
    from .identify.rundir import RunDir

    record = RunDir(run).record("baselines") or {}
    h = SHOOTING["horizon"][0]
    found = [c["model_mm"] for c in record.get("judged", []) if c.get("horizon") == h]
    return float(found[0]) if found and math.isfinite(found[0]) else math.inf


def _fit_into(run_path, model_path, recording_path, settings, say, fit_progress) -> float:
    """A fit of ``model_path`` in ``run_path``: resumed where it holds a checkpoint (a
    completed run resumes at once: its stages' records are kept, a missing one is run), else
    run anew; its summary lines said. Returns its best one-step RMS (mm)."""
    from contextlib import nullcontext

    from .identify.driver import fit, resume
    from .identify.rundir import RunDir

    run_dir = RunDir(run_path)
    progress = fit_progress or (lambda total, starting: nullcontext(None))
    status = run_dir.status().get("status") if run_dir.is_run() else None
    with progress(settings.generations, "compiling") as bar:
        hooks = {"progress": bar, "status": bar.status} if bar is not None else {}
        if status is not None and run_dir.newest_checkpoint() is not None:
            say(f"      resuming the fit in {run_path} ({status})")
            result = resume(run_path, **hooks)
        else:
            result = fit(
                model_path, recording_path, settings, out=run_path, overwrite=True, **hooks
            )
    if result.status != "completed":
        raise RuntimeError(f"the fit ended {result.status}; see {run_path}")
    for line in result.lines():
        say(f"      {line}")
    return result.rms_mm


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
        from .identify.judge.verdict import comparisons_from, free_run_advice

        self.record = record
        self.frames = tuple(record["frames"])
        self.comparisons = comparisons_from(record["comparisons"])
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
        return out + ([self._advice] if self._advice else [])


def _evaluations(run: Path, recording, split: Windows, options: Options):
    """Two thunks: the kept run's model evaluated on the held-out frames and on the fitted
    ones."""

    def on(frames):
        def evaluate_there():
            from .identify.rundir import RunDir
            from .model import load_model
            from .report.evaluate import evaluate

            model = load_model(RunDir(run).best_model_path)
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


def _made(state: dict) -> list[str]:
    """How the kept model was made, for the report: the noise's line and the first three
    steps' notes (every run tried, kept or not, and why), the masses' note."""
    from .data.smoothing import Noise

    steps = state["steps"]
    out = [noise_line(Noise(**state["noise"]))] if "noise" in state else []
    out += [f"{name}: {steps[name]['note']}" for name in STEPS[:3] if name in steps]
    if steps.get("fit", {}).get("masses"):
        out.append(steps["fit"]["masses"])
    return out


def _report(run: Path, report: Path, frames: int, evaluation: Path, made=()) -> str:
    """The run's report, its held-out verdicts (one step and K ahead) the evaluation's,
    ``made`` (:func:`_made`) a section of its own."""
    from .report import write_report
    from .report.html import Beyond

    held = json.loads(evaluation.read_text(encoding="utf-8"))["held_out"]
    beyond = Beyond.from_record(held)
    return str(write_report(run, report, frames=frames, beyond=beyond, made=made))
