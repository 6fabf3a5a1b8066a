"""The steps of ``activebonds auto``, registered in order (:data:`STEPS`), and how they are
run: each announced (``[k/n] name: what``, ``n`` the registry's count), timed and recorded in
``OUT/auto.json`` with its note and what it noted beside it
(:meth:`~.workspace.Workspace.note`), or said done where an earlier run finished it."""

from __future__ import annotations

import shutil
import time
from collections.abc import Callable
from dataclasses import asdict, dataclass
from pathlib import Path

from ..registry import Registry
from .folder import Folder, Options, Windows
from .notes import noise_line


@dataclass(frozen=True)
class Step:
    """One step: its name, what it does (said before it, from the workspace), its work
    (``run(ws)``, returning its note) and the lines said after its line (``after(ws)``, also
    where an earlier run finished it)."""

    name: str
    doing: Callable[[object], str]
    run: Callable[[object], str]
    after: Callable[[object], list[str]] | None = None


def _scaffold(ws) -> str:
    from .scaffold import write_scaffold

    return write_scaffold(ws.folder, ws.scaffold, ws.say)


def _structure(ws) -> str:
    from .structure import structure_step

    return structure_step(ws.folder, ws.structural, ws.split, ws.options, ws.say)


def _fit(ws) -> str:
    from .fit import fit_step

    return fit_step(ws)


def _table(ws) -> list[str]:
    from .fit import table_lines

    return table_lines(ws)


def _evaluate(ws) -> str:
    from .evaluation import evaluations, write_evaluation

    held, fitted = evaluations(ws.kept_run, ws.recording, ws.split, ws.options)
    return write_evaluation(ws.folder, held(), fitted())


def _report(ws) -> str:
    from .evaluation import how_made, write_html

    a, b = ws.split.fitted[0], ws.split.held_out[1]
    made = how_made(ws.state)
    return write_html(ws.kept_run, ws.folder.report, b - a, ws.folder.evaluation, made)


def _evaluating(ws) -> str:
    s, b = ws.split.held_out
    return (
        f"the fitted model on the held-out frames {s}:{b} and the fitted ones, one step and "
        f"{ws.options.ahead} frames ahead, beside zero force"
    )


STEPS: Registry[Step] = Registry(
    "auto step",
    [
        Step("scaffold", lambda ws: "a candidate model of the fitted frames", _scaffold),
        Step(
            "structure",
            lambda ws: (
                "which candidate bonds the fitted frames need (exact least squares, "
                "BIC, a validation tail)"
            ),
            _structure,
        ),
        Step(
            "fit",
            lambda ws: (
                "the candidate models, each fitted and judged on the validation frames "
                f"(population {ws.options.population}, {ws.options.generations} generations, then "
                "the refinement)"
            ),
            _fit,
            _table,
        ),
        Step("evaluate", _evaluating, _evaluate),
        Step(
            "report",
            lambda ws: "the HTML report of the run over the fitted and held-out frames",
            _report,
        ),
    ],
)


def run_steps(ws) -> None:
    """Every registered step in turn (see the module's docstring)."""
    steps, say = ws.state["steps"], ws.say
    n = len(STEPS.names())
    for k, step in enumerate(STEPS.entries(), 1):
        if step.name in steps:
            say(f"[{k}/{n}] {step.name}: done before ({steps[step.name]['seconds']:.0f} s)")
        else:
            say(f"[{k}/{n}] {step.name}: {step.doing(ws)}")
            ws.notes.pop(step.name, None)
            t0 = time.perf_counter()
            note = step.run(ws)
            seconds = time.perf_counter() - t0
            noted = ws.notes.pop(step.name, {})
            steps[step.name] = {"seconds": round(seconds, 1), "note": note, **noted}
            ws.folder.write_state(ws.state)
            say(f"[{k}/{n}] {step.name}: {note} ({seconds:.0f} s)")
        for line in step.after(ws) if step.after is not None else ():
            say(line)


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
            "validation_frames": list(split.validation),
            "steps": {},
        }
        folder.write_state(state)
    else:
        done = [s for s in STEPS.names() if s in state["steps"]]
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
