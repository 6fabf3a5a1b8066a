"""The masses candidate: where the kept model's masses are fixed, it has gravity and ground
contacts, and the fitted frames hold a flight
(:func:`~activebonds.identify.discover.flight_masses.longest_flight`), its masses freed under
``total_mass`` and identified with its bonds by multiple shooting on the flight
(:data:`~.base.SHOOTING`; ``OUT/flight.toml``, ``OUT/run-flight``, fitted here), then the
model with those masses and the bond parameters the flight determined well held, its contacts
and the rest fitted on every fitted frame, one step (``OUT/masses.toml``, ``OUT/run-masses``:
the proposal). Up to :data:`~.base.MAX_SHOT` parameters."""

from __future__ import annotations

from .base import MAX_SHOT, SHOOTING, Proposal


class MassesCandidate:
    """The flight's masses, held."""

    name = "masses"

    def propose(self, ws, kept) -> Proposal | None:
        from ...identify.discover.flight_masses import anchors, freed, longest_flight
        from ...identify.problem import select_data
        from ...identify.rundir import RunDir
        from ...identify.settings import FitSettings
        from ...model import load_model, save_model

        if kept is None:
            return None
        model = load_model(RunDir(kept.run).best_model_path)
        if any(model.spec.free_masses()):
            return None
        data = select_data(model, ws.recording, FitSettings(frames=ws.split.fitted))
        flight = longest_flight(model.spec, data.positions, ws.split.fitted[0])
        if flight is None:
            return None
        a, b = flight
        genes = model.layout.n_genes + len(model.spec.particle)
        if genes > MAX_SHOT:
            ws.say(
                f"      masses: frames {a}:{b} are in flight, but identifying the masses there "
                f"by multiple shooting is left to fit --cost shooting above {MAX_SHOT} "
                f"parameters ({genes} here)"
            )
            return None
        dropped = anchors(model.spec)
        ws.say(
            f"      masses: frames {a}:{b} are in flight (every contact off its plane: gravity "
            f"and the bonds alone act): {kept.run.name}'s masses freed under total_mass and "
            f"identified there with its bonds by multiple shooting (horizon "
            f"{SHOOTING['horizon'][0]}, {SHOOTING['substeps']} Verlet substeps)"
            + (
                f"; its {dropped} anchor(s) dropped: nothing in the room holds a body in flight"
                if dropped
                else ""
            )
        )
        save_model(freed(model.spec), ws.folder.flight)
        shooting = ws.settings().model_copy(
            update={**SHOOTING, "frames": (a, b), "population": 4, "generations": 1}
        )
        ws.fit(ws.folder.run_flight.name, ws.folder.flight, shooting)
        return held_masses(ws, kept.run.name, model.spec)


def held_masses(ws, kept_name: str, spec) -> Proposal:
    """The flight's fit (``OUT/run-flight``) read: its masses and the bond parameters its
    uncertainty record determined within :data:`~.flight_masses.HOLD` held
    (``OUT/masses.toml``), the rest to fit on every fitted frame, one step."""
    import numpy as np

    from ...identify.discover.flight_masses import HOLD, determined, held
    from ...identify.rundir import RunDir
    from ...model import load_model, save_model

    run = RunDir(ws.folder.run_flight)
    weighed = load_model(run.best_model_path)
    masses = np.asarray(weighed.params.mass, np.float64)
    genes = weighed.layout.genes
    record = run.record("uncertainty") or {}
    hold = determined(record.get("estimates", []), genes)
    own = sum(g.owner == "bond" and g.type is None for g in genes)
    each = ", ".join(f"{p.name} {m:.4g}" for p, m in zip(spec.particle, masses, strict=True))
    ws.say(f"      masses: {each} kg (run-flight: their intervals in its uncertainty.csv)")
    save_model(held(weighed.spec, masses, hold), ws.folder.masses)
    return Proposal(
        run="run-masses",
        model=ws.folder.masses,
        settings=ws.one_step(),
        what=(
            f"the contacts fitted on every fitted frame with the flight's masses held, and the "
            f"{len(hold)} bond parameter(s) it determined within {100 * HOLD:g} % (of {own}), "
            f"the rest fitted again (one step, as {kept_name} was)"
        ),
    )
