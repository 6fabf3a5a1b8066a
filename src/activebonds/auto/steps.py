"""The steps of ``activebonds auto`` and how each is run: announced, timed and recorded in
``OUT/auto.json``, or skipped where an earlier run finished it; the scaffold's, the evaluation's
and the report's work."""

from __future__ import annotations

import json
import shutil
import time
from collections.abc import Callable
from dataclasses import asdict
from pathlib import Path

from .folder import BURN_IN, STEPS, Folder, Options, Windows
from .notes import noise_line


def scaffold_of(recording, split: Windows, options: Options, name: str):
    """The candidate model of the fitted frames (:func:`~activebonds.identify.discover.scaffold.
    scaffold` with the options), its inputs checked."""
    from ..identify.discover.scaffold import scaffold

    return scaffold(
        recording,
        markers=list(options.markers) if options.markers else None,
        frames=split.fitted,
        total_mass=options.total_mass,
        up=options.up,
        gravity=options.gravity,
        name=name,
    )


def begin(
    folder: Folder,
    state: dict | None,
    recording_path: Path,
    options: Options,
    split: Windows,
    noise,
    overwrite: bool,
    say: Callable[[str], None],
) -> dict:
    """The run's state: ``state`` (:func:`~.folder.prepare`'s, an earlier run's, continued) or,
    where it is None, a new one written in the folder (made, or emptied with ``overwrite``);
    the frames and the marker ``noise`` said."""
    from ..identify.rundir import RunDir

    out = folder.path
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
    a, s = split.fitted
    b = split.held_out[1]
    say(
        f"frames {a}:{b}: fitting {a}:{s} ({s - a} frames), holding out {s}:{b} "
        f"({b - s} frames, the last {100 * options.held_out:g} %)"
    )
    say(noise_line(noise))
    state["noise"] = asdict(noise)
    return state


class Steps:
    """Runs the steps in turn: each announced, timed and recorded in the folder's state with
    its note (and what it records beside it in ``state["parts"][name]``), or said done where
    an earlier run finished it."""

    def __init__(self, folder: Folder, state: dict, say: Callable[[str], None]):
        self.folder, self.state, self.say = folder, state, say

    def __call__(self, k: int, name: str, what: str, body: Callable[[], str]) -> None:
        steps, say = self.state["steps"], self.say
        if name in steps:
            say(f"[{k}/5] {name}: done before ({steps[name]['seconds']:.0f} s)")
            return
        self.state["parts"] = {}  # what a step records beside its note
        say(f"[{k}/5] {name}: {what}")
        t0 = time.perf_counter()
        note = body()
        seconds = time.perf_counter() - t0
        parts = self.state.pop("parts").get(name, {})
        steps[name] = {"seconds": round(seconds, 1), "note": note, **parts}
        self.folder.write_state(self.state)
        say(f"[{k}/5] {name}: {note} ({seconds:.0f} s)")


def write_scaffold(folder: Folder, found, say: Callable[[str], None]) -> str:
    """Step 1: the scaffold ``found`` (checked to load) written, its notes said."""
    from ..atomic import write_text_atomic
    from ..model import loads_model

    loads_model(found.text, str(folder.scaffold))
    for note in found.notes:
        say(f"      {note}")
    write_text_atomic(folder.scaffold, found.text)
    return (
        f"{found.particles} particles, {found.bonds} candidate bonds, {found.contacts} "
        f"ground contacts, gravity {found.gravity}: {folder.scaffold}"
    )


def evaluations(run: Path, recording, split: Windows, options: Options):
    """Two thunks: the kept run's model evaluated on the held-out frames and on the fitted
    ones."""

    def on(frames, burn_in=None):
        def evaluate_there():
            from ..identify.judge.burn_in import burn_in_starts
            from ..identify.rundir import RunDir
            from ..model import load_model
            from ..report.evaluate import evaluate

            model = load_model(RunDir(run).best_model_path)
            after = None  # free runs after a burn-in, where the frames have a start for one
            if burn_in is not None:
                seen = recording.select(list(model.markers)).window(*frames).positions
                after = burn_in if burn_in_starts(seen, burn_in, 1, 1) else None
            return evaluate(model, recording, frames=frames, horizon=options.ahead, burn_in=after)

        return evaluate_there

    return on(split.held_out, BURN_IN), on(split.fitted)


def write_evaluation(folder: Folder, held, fitted) -> str:
    from ..atomic import write_text_atomic

    record = {"held_out": held.record(), "fitted": fitted.record()}
    write_text_atomic(folder.evaluation, json.dumps(record, indent=2) + "\n")
    one = held.comparisons[0]
    return (
        f"held out, one step: {one.model_mm:.4g} mm (zero force {one.zero_force_mm:.4g} mm): "
        f"{folder.evaluation}"
    )


def how_made(state: dict) -> list[str]:
    """How the kept model was made, for the report: the noise's line and the first three
    steps' notes (every run tried, kept or not, and why), the masses' note."""
    from ..data.smoothing import Noise

    steps = state["steps"]
    out = [noise_line(Noise(**state["noise"]))] if "noise" in state else []
    out += [f"{name}: {steps[name]['note']}" for name in STEPS[:3] if name in steps]
    if steps.get("fit", {}).get("masses"):
        out.append(steps["fit"]["masses"])
    return out


def write_html(run: Path, report: Path, frames: int, evaluation: Path, made=()) -> str:
    """The run's report, its held-out verdicts (one step and K ahead) the evaluation's,
    ``made`` (:func:`how_made`) a section of its own."""
    from ..report import write_report
    from ..report.html import Beyond

    held = json.loads(evaluation.read_text(encoding="utf-8"))["held_out"]
    beyond = Beyond.from_record(held)
    return str(write_report(run, report, frames=frames, beyond=beyond, made=made))
