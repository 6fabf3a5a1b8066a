"""Step 2 of ``activebonds auto``, the structure: which of the scaffold's candidate bonds the
fitted frames need, on the recording as the marker noise lets them be judged
(:func:`smoothed`), and the decided structure with the scaffold's gravity and ground
contacts (``OUT/ground.toml``)."""

from __future__ import annotations

import json
from pathlib import Path

from .folder import Folder, Options, Windows

MAX_DECIDED = 300  # candidate bonds: above, structure keeps them all (no elimination)


def structure_step(folder: Folder, recording, split: Windows, options: Options, say) -> str:
    from ..identify.discover.structure import candidates
    from ..model import load_model

    scaffolded = load_model(folder.scaffold)
    n = len(candidates(scaffolded.spec))
    if n > MAX_DECIDED:
        return _undecided(folder, recording, split, options, say)
    from ..atomic import write_text_atomic
    from ..identify.discover.structure_choice import Variant, choose, decide
    from ..model import save_model

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
    from .. import bonds
    from ..identify.costs.windows import make_windows, neighbours_of
    from ..identify.discover.structure import exact_optimum
    from ..identify.discover.structure_choice import criterion
    from ..identify.problem import select_data
    from ..identify.settings import FitSettings
    from ..model import build, save_model

    extra = [b for b in scaffolded.bond if bonds.get(b.kind).linear is None]
    if scaffolded.gravity is None and not extra:
        if folder.ground.exists():
            folder.ground.unlink()
        return None
    spec = decided.model_copy(update={"gravity": scaffolded.gravity, "bond": decided.bond + extra})
    model = build(spec)
    data = select_data(model, recording, FitSettings(frames=split.fitted))
    windows = make_windows(data.positions, data.mask, data.dt, 1, neighbours=neighbours_of(model))
    solved, _ = exact_optimum(model, windows)
    save_model(solved, folder.ground)
    # its one-step RMS as the fit and `evaluate` score it (the exact optimum's own residual
    # holds the contacts at their start and is not the model's prediction)
    rms = criterion(build(solved), recording, split.fitted).rms_mm
    return {"contacts": len(extra), "gravity": scaffolded.gravity is not None, "rms_mm": rms}


def _undecided(folder: Folder, recording, split: Windows, options: Options, say) -> str:
    """Above MAX_DECIDED candidates: every candidate kept at its exact optimum."""
    from ..atomic import write_text_atomic
    from ..identify.discover.scaffold import scaffold
    from ..model import load_model, loads_model, save_model

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


def noise_of_fitted(recording, split: Windows, options: Options):
    """:func:`~.data.smoothing.noise_of` the fitted frames of the markers asked."""
    from ..data.smoothing import noise_of

    seen = recording.select(list(options.markers)) if options.markers else recording
    a, s = split.fitted
    return noise_of(seen.positions[a:s])


def smoothed(recording, split: Windows, window: int):
    """``recording`` with its fitted frames smoothed over ``window`` frames (0: as it is),
    each marker's run of recorded frames apart, never across the held-out boundary: the
    recording the structure is chosen on."""
    import dataclasses

    from ..data.smoothing import smooth_positions

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
    from ..identify.discover.structure import candidates, structure_of
    from ..identify.settings import FitSettings

    n = len(candidates(model.spec))
    eliminate = n <= MAX_DECIDED
    if not eliminate:
        say(
            f"      structure: {n} candidate bonds, more than {MAX_DECIDED}: no elimination "
            "(backward elimination's solves grow with the square of the candidates); "
            "every candidate kept, at its exact least-squares optimum"
        )
    result = structure_of(model, recording, FitSettings(frames=split.fitted), 0, eliminate)
    return result, eliminate, n
