"""Step 3 of ``activebonds auto``, the fit: the structure fitted from its exact optimum on the
one-step cost, beside the ground model; the kept run's masses identified on a flight and, where
marker noise dominates, its model refined by multiple shooting, each kept only where it predicts
the fitted frames better."""

from __future__ import annotations

import math
from pathlib import Path

from .folder import fit_settings
from .notes import fixed_masses_note

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


def fit_step(
    folder, recording_path, recording, split, options, say, fit_progress, state, noise
) -> str:
    """The structure fitted from its exact optimum on the one-step cost (OUT/run)
    (``recording``: the one the structure was chosen on, smoothed as ``noise`` says); where
    there is a ground model, it fitted too (OUT/run-ground, the cost as fit --cost auto) and
    kept where its one-step BIC on the fitted frames is lower; where ``noise`` dominates, the
    kept one refined by multiple shooting (:func:`shoot`). Records the kept run's name in
    the fit step of ``state``."""
    from ..identify.discover.structure_choice import criterion
    from ..identify.rundir import RunDir
    from ..model import load_model

    settings = fit_settings(options, split)
    one_step = settings.model_copy(update={"cost": "restart", "horizon": (1,)})
    say(
        "      cost: one step (the structure's linear parameters start at the exact optimum of "
        "this cost; the ES seeded there keeps it or finds better)"
    )
    linear = fit_into(folder.run, folder.structure, recording_path, one_step, say, fit_progress)
    kept, why = folder.run, ""
    if folder.ground.exists():
        say(
            f"      the model with gravity and ground contacts ({folder.ground}), from its "
            "exact optimum with the contacts held: the same cost, one step, by which the two "
            "are compared"
        )
        ground_rms = fit_into(
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
    kept, weighed = weigh_on_flight(
        folder, kept, recording_path, recording, split, settings, say, fit_progress
    )
    why += weighed
    if noise.dominated:
        kept, shot = shoot(folder, kept, recording_path, settings, say, fit_progress)
        why += shot
    state["parts"].setdefault("fit", {})["run"] = kept.name
    tried = folder.run_flight if folder.run_flight.exists() else None
    masses = fixed_masses_note(kept, tried) if kept != folder.run_masses else None
    if masses:
        say(f"      {masses}")
        state["parts"]["fit"]["masses"] = masses
    return f"{headline}{why}"


def weigh_on_flight(
    folder, kept: Path, recording_path, recording, split, settings, say, fit_progress
) -> tuple[Path, str]:
    """Where the kept run's masses are fixed and its model has gravity and contacts, and the
    fitted frames hold a flight (:func:`~.identify.flight_masses.longest_flight`): its masses
    freed under ``total_mass`` and identified with its bonds by multiple shooting on the
    flight (:data:`SHOOTING`, OUT/run-flight), then its contacts fitted on every fitted
    frame with the masses held and the bond parameters the flight determined well
    (:func:`~.identify.flight_masses.determined`; the one-step cost, OUT/run-masses), which
    is kept where it predicts the fitted frames :data:`SHOOTING`'s horizon ahead better than
    the kept run (as :func:`shoot` judges). Up to :data:`MAX_SHOT` parameters. (kept run,
    note)."""
    from ..identify.discover.flight_masses import anchors, freed, longest_flight
    from ..identify.problem import select_data
    from ..identify.rundir import RunDir
    from ..identify.settings import FitSettings
    from ..model import load_model, save_model

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
    fit_into(folder.run_flight, folder.flight, recording_path, shooting, say, fit_progress)
    return _held_masses(
        folder, kept, model.spec, flight, recording_path, settings, say, fit_progress
    )


def _held_masses(
    folder, kept: Path, spec, flight, recording_path, settings, say, fit_progress
) -> tuple[Path, str]:
    """The flight's fit (OUT/run-flight) read: its masses and the bond parameters it
    determined held, the contacts and the rest fitted again on every fitted frame
    (OUT/run-masses), kept where it predicts the fitted frames better than ``kept`` (of
    ``spec``): :func:`weigh_on_flight`'s second half. (kept run, note)."""
    import csv

    import numpy as np

    from ..identify.discover.flight_masses import HOLD, determined, held
    from ..identify.rundir import RunDir
    from ..model import load_model, save_model

    a, b = flight
    weighed = load_model(RunDir(folder.run_flight).best_model_path)
    masses = np.asarray(weighed.params.mass, np.float64)
    bond_genes = sum(g.name.startswith("bond[") for g in weighed.layout.genes)
    with (folder.run_flight / "uncertainty.csv").open(encoding="utf-8") as f:
        hold = determined(csv.DictReader(f))
    each = ", ".join(f"{p.name} {m:.4g}" for p, m in zip(spec.particle, masses, strict=True))
    say(
        f"      masses: {each} kg (run-flight: their intervals in its uncertainty.csv); the "
        f"contacts fitted on every fitted frame with these masses held, and the "
        f"{len(hold)} bond parameter(s) the flight determined within {100 * HOLD:g} % (of "
        f"{bond_genes}), the rest fitted again (one step, as {kept.name} was)"
    )
    save_model(held(weighed.spec, masses, hold), folder.masses)
    one_step = settings.model_copy(update={"cost": "restart", "horizon": (1,)})
    rms = fit_into(folder.run_masses, folder.masses, recording_path, one_step, say, fit_progress)
    before, after = ahead_mm(kept), ahead_mm(folder.run_masses)
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


def shoot(folder, kept: Path, recording_path, settings, say, fit_progress) -> tuple[Path, str]:
    """Where marker noise dominates: the kept run's model refined by multiple shooting
    (:data:`SHOOTING`, OUT/run-shot), whose optimum the noise does not bias, unless it has
    more than :data:`MAX_SHOT` parameters; the shot model kept in its place where it predicts
    the fitted frames the shooting's horizon ahead better (a family that cannot explain the
    motion, such as springs without the gravity and ground they stand on, shoots worse).
    (kept run, note)."""
    from ..identify.rundir import RunDir
    from ..model import load_model

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
    fit_into(folder.run_shot, start, recording_path, shooting, say, fit_progress)
    before, after = ahead_mm(kept), ahead_mm(folder.run_shot)
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


def ahead_mm(run: Path) -> float:
    """A run's RMS (mm) :data:`SHOOTING`'s horizon frames ahead on its fitted frames (its
    baselines' ``judged`` comparisons; inf where it has none)."""
    from ..identify.rundir import RunDir

    record = RunDir(run).record("baselines") or {}
    h = SHOOTING["horizon"][0]
    found = [c["model_mm"] for c in record.get("judged", []) if c.get("horizon") == h]
    return float(found[0]) if found and math.isfinite(found[0]) else math.inf


def fit_into(run_path, model_path, recording_path, settings, say, fit_progress) -> float:
    """A fit of ``model_path`` in ``run_path``: resumed where it holds a checkpoint (a
    completed run resumes at once: its stages' records are kept, a missing one is run), else
    run anew; its summary lines said. Returns its best one-step RMS (mm)."""
    from contextlib import nullcontext

    from ..identify.driver import fit, resume
    from ..identify.rundir import RunDir

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
    for line in printed_lines(result.lines()):
        say(f"      {line}")
    return result.rms_mm


WARNING = "uncertainty: warning: "


def printed_lines(lines: list[str]) -> list[str]:
    """A fit's summary as ``auto`` prints it: the uncertainty's warnings (long, some advising
    a refit ``auto`` decides itself) counted in one line, their words in the report."""
    warned = [line for line in lines if line.startswith(WARNING)]
    kept = [line for line in lines if not line.startswith(WARNING)]
    if warned:
        kept.append(
            f"uncertainty: {len(warned)} warning{'s' * (len(warned) > 1)} on these intervals, "
            "in the report's Uncertainty section"
        )
    return kept
