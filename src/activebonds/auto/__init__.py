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
   ``OUT/run-masses/``: :func:`~.refits.weigh_on_flight`), which is kept.
   Where marker noise dominates, the kept model is refined by multiple shooting
   (``OUT/run-shot/``, :func:`~.refits.shoot`), up to :data:`MAX_SHOT` parameters.
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
from collections.abc import Callable
from pathlib import Path

from ..errors import InputError
from .folder import (
    AHEAD,
    CHECKPOINT_EVERY,
    GENERATIONS,
    HELD_OUT,
    MIN_FRAMES,
    POPULATION,
    STATE,
    STEPS,
    Folder,
    Options,
    Windows,
    fit_settings,
    prepare,
    windows,
)
from .notes import (
    NOISY_ONE_STEP,
    STILL,
    Outcome,
    Scored,
    absent_note,
    fixed_masses_note,
    noise_line,
    still_note,
)
from .refits import MAX_SHOT, SHOOTING, fit_step
from .steps import (
    Steps,
    begin,
    evaluations,
    how_made,
    scaffold_of,
    write_evaluation,
    write_html,
    write_scaffold,
)
from .structure import MAX_DECIDED, noise_of_fitted, recording_name, smoothed, structure_step

__all__ = [
    "AHEAD",
    "CHECKPOINT_EVERY",
    "GENERATIONS",
    "HELD_OUT",
    "MAX_DECIDED",
    "MAX_SHOT",
    "MIN_FRAMES",
    "NOISY_ONE_STEP",
    "POPULATION",
    "SHOOTING",
    "STATE",
    "STEPS",
    "STILL",
    "Folder",
    "Options",
    "Outcome",
    "Windows",
    "fit_settings",
    "fixed_masses_note",
    "noise_line",
    "noise_of_fitted",
    "prepare",
    "recording_name",
    "run",
    "smoothed",
    "still_note",
    "windows",
]


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
    from ..data import read_trajectory
    from ..model import loads_model

    recording = read_trajectory(recording_path)
    if options.ahead < 1:
        raise InputError("--ahead", f"must be at least 1, got {options.ahead}")
    split = windows(recording.n_frames, options.frames, options.held_out)
    fit_settings(options, split)  # the fit's options checked before anything is written
    # the scaffold checks the markers, the mass, the vertical: before anything is written
    found = scaffold_of(recording, split, options, recording_path.stem)
    noise = noise_of_fitted(recording, split, options)
    structural = smoothed(recording, split, noise.window)
    state = prepare(out, recording_path, options, overwrite)
    folder = Folder(out)
    state = begin(folder, state, recording_path, options, split, noise, overwrite, say)
    absent = absent_note(recording, loads_model(found.text).markers, split.held_out)
    if absent:
        say(absent)
    steps = state["steps"]
    a, s = split.fitted
    b = split.held_out[1]
    step = Steps(folder, state, say)
    step(
        1,
        "scaffold",
        "a candidate model of the fitted frames",
        lambda: write_scaffold(folder, found, say),
    )
    step(
        2,
        "structure",
        "which candidate bonds the fitted frames need (exact least squares, BIC, a validation "
        "tail)",
        lambda: structure_step(folder, structural, split, options, say),
    )
    step(
        3,
        "fit",
        f"from the structure's exact optimum, population {options.population}, "
        f"{options.generations} generations, then the refinement",
        lambda: fit_step(
            folder, recording_path, structural, split, options, say, fit_progress, state, noise
        ),
    )
    kept = folder.path / steps["fit"].get("run", "run")
    held, fitted = evaluations(kept, recording, split, options)
    step(
        4,
        "evaluate",
        f"the fitted model on the held-out frames {s}:{b} and the fitted ones, one step and "
        f"{options.ahead} frames ahead, beside zero force",
        lambda: write_evaluation(folder, held(), fitted()),
    )
    step(
        5,
        "report",
        "the HTML report of the run over the fitted and held-out frames",
        lambda: write_html(kept, folder.report, b - a, folder.evaluation, how_made(state)),
    )
    state["total_seconds"] = round(sum(v["seconds"] for v in steps.values()), 1)
    folder.write_state(state)
    record = json.loads(folder.evaluation.read_text(encoding="utf-8"))
    return Outcome(folder, state, Scored(record["held_out"]), Scored(record["fitted"]))
