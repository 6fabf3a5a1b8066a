"""From a recording to an evaluated model in one call: ``activebonds auto``, a search over
candidate models judged by one rule.

The steps (:data:`~.steps.STEPS`), each one's output in the output folder ``OUT``:

1. **scaffold** (:mod:`~.scaffold`) on the fitted frames: ``OUT/scaffold.toml``;
2. **structure** (:mod:`~.structure`, :mod:`~activebonds.identify.discover.structure_choice`):
   which of the scaffold's candidate bonds the fitted frames need, up to :data:`MAX_DECIDED`
   candidates (variants fitted by exact least squares on the first 80 % of the fitted frames,
   chosen on the rest, the validation tail), on the fitted frames smoothed where the marker
   noise dominates (:func:`smoothed`): ``OUT/structure.toml``, ``OUT/structure.json``; with the
   scaffold's gravity and ground contacts, ``OUT/ground.toml``;
3. **fit** (:mod:`~.fit`): every registered candidate (:data:`~.candidates.CANDIDATES`:
   ``structure``, the structure from its exact optimum on the one-step cost, ``OUT/run``;
   ``ground``, ``OUT/run-ground``; ``masses``, the flight's masses held, ``OUT/run-masses``;
   ``gait``, a drive and periodic forces where the motion repeats, ``OUT/run-gait``;
   ``walk``, a periodic force per marker in the stride's phase where the body walks over a
   floor, ``OUT/run-walk``; ``shot``, multiple shooting where the noise dominates,
   ``OUT/run-shot``) proposes a model
   against the one kept so far; it is fitted, judged on the validation frames (the last 20 %
   of the fitted frames: :attr:`Windows.validation`) by one rule (:mod:`~.judge`: fewer
   markers worse than zero force one step, then a lower RMS ``--ahead`` frames ahead) and
   kept where better (``--up``/``--gravity`` insist on the ground model). The candidates and
   their scores are said in one table and recorded (``steps.fit.candidates``); ``auto.json``
   names the kept run (``steps.fit.run``);
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
import warnings
from collections.abc import Callable
from pathlib import Path

from ..errors import InputError
from . import structure
from .candidates import CANDIDATES, MAX_SHOT, SHOOTING, Proposal, Tried
from .folder import (
    AHEAD,
    CHECKPOINT_EVERY,
    GENERATIONS,
    HELD_OUT,
    MIN_FRAMES,
    POPULATION,
    STATE,
    Folder,
    Options,
    Windows,
    fit_settings,
    prepare,
    windows,
)
from .judge import Judged, better, judge
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
from .steps import STEPS, Step, begin, run_steps
from .structure import MAX_DECIDED, noise_of_fitted, recording_name, smoothed
from .workspace import Workspace

__all__ = [
    "AHEAD",
    "CANDIDATES",
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
    "Judged",
    "Options",
    "Outcome",
    "Proposal",
    "Step",
    "Tried",
    "Windows",
    "Workspace",
    "better",
    "fit_settings",
    "fixed_masses_note",
    "judge",
    "noise_line",
    "noise_of_fitted",
    "prepare",
    "recording_name",
    "run",
    "smoothed",
    "still_note",
    "structure",
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
    verbose: bool = True,
) -> Outcome:
    """Every step of ``activebonds auto`` (see the module's docstring), each announced by
    ``say``; ``fit_progress(generations, starting)``: a context manager yielding the fit's
    progress (with a ``status``), or None; ``verbose``: each fit's summary said (else one
    line a fit). Bad input raises InputError before anything is
    written. numpy's RuntimeWarnings (a mean of no frames on a gappy recording) are not
    shown: what they mean is said in the scores."""
    import numpy as np

    with warnings.catch_warnings(), np.errstate(all="ignore"):
        warnings.simplefilter("ignore", RuntimeWarning)
        return _run(recording_path, out, options, overwrite, say, fit_progress, verbose)


def _run(recording_path: Path, out: Path, options: Options, overwrite, say, fit_progress,
         verbose):  # fmt: skip
    from ..data import read_trajectory
    from ..model import loads_model
    from .scaffold import scaffold_of

    recording = read_trajectory(recording_path)
    if options.ahead < 1:
        raise InputError("--ahead", f"must be at least 1, got {options.ahead}")
    split = windows(recording.n_frames, options.frames, options.held_out)
    fit_settings(options, split)  # the fit's options checked before anything is written
    # the scaffold checks the markers, the mass, the vertical: before anything is written
    found = scaffold_of(recording, split, options, recording_path.stem)
    noise = noise_of_fitted(recording, split, options)
    state = prepare(out, recording_path, options, overwrite)
    folder = Folder(out)
    state = begin(folder, state, recording_path, options, split, noise, overwrite, say)
    absent = absent_note(recording, loads_model(found.text).markers, split.held_out)
    if absent:
        say(absent)
    ws = Workspace(
        folder=folder,
        recording_path=recording_path,
        recording=recording,
        structural=smoothed(recording, split, noise.window),
        split=split,
        options=options,
        noise=noise,
        say=say,
        fit_progress=fit_progress,
        state=state,
        scaffold=found,
        verbose=verbose,
    )
    run_steps(ws)
    state["total_seconds"] = round(sum(v["seconds"] for v in state["steps"].values()), 1)
    folder.write_state(state)
    record = json.loads(folder.evaluation.read_text(encoding="utf-8"))
    return Outcome(folder, state, Scored(record["held_out"]), Scored(record["fitted"]))
