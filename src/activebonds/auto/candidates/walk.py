"""The walk candidate: where the fitted frames are a walk (a stride repeats, markers touch a
floor and the body travels over it: :func:`~activebonds.identify.discover.walk.recognise`),
the model of the walk family (:mod:`~activebonds.identify.discover.walk`: a force periodic in
the stride's phase on every marker, nothing tying the body to the room), solved exactly on
every fitted frame (``OUT/walk.toml``, ``OUT/run-walk``). It needs fewer strides than the gait
candidate (a gait lab's walkway holds one or two). Its markers, rate and frames are the
recording's: no name, rate or length is read but as numbers of the data."""

from __future__ import annotations

from .base import Proposal


class WalkCandidate:
    """Forces in the phase of the stride, where the body walks over a floor."""

    name = "walk"

    def propose(self, ws, kept) -> Proposal | None:
        import numpy as np

        from ...data.orientation import parse_up
        from ...identify.discover.gait import solve
        from ...identify.discover.walk import (
            Walk,
            WalkVariant,
            harmonics_seen,
            recognise,
            walk_spec,
        )
        from ...model import save_model

        recording = ws.structural
        if ws.options.markers:
            recording = recording.select(list(ws.options.markers))
        names = list(recording.markers)
        x = np.asarray(recording.positions, np.float64)
        a, s = ws.split.fitted
        dimension = x.shape[2]
        up = parse_up(ws.options.up, dimension) if ws.options.up else None
        found = recognise(x[a:s], recording.rate, names, up)
        if not isinstance(found, Walk):
            ws.say(f"      walk: not proposed: {found}")
            return None
        for line in found.lines(names):
            ws.say(f"      walk: {line}")
        mass = ws.options.total_mass / len(names) if ws.options.total_mass else 1.0
        variant = WalkVariant()
        seen = harmonics_seen(x[a:s], found.stride, variant.harmonics)
        fewer = [f"{names[i]} {h}" for i, h in enumerate(seen) if h < variant.harmonics]
        if fewer:
            ws.say(
                f"      walk: {len(fewer)} marker(s) predicted over part of the stride only: "
                f"fewer harmonics (0: no force) ({', '.join(fewer)})"
            )
        spec = walk_spec(x[a:s], names, found.stride, variant, mass, seen=seen)
        if not spec.bond:
            ws.say("      walk: not proposed: no marker is predicted over enough of the stride")
            return None
        model = solve(spec, recording, (a, s))
        path = ws.folder.path / "walk.toml"
        save_model(model.spec, path)
        ws.note("fit", "walk", {"notes": found.lines(names), "variant": variant.text()})
        smoothed = " (the positions smoothed as for the structure)" if ws.noise.window else ""
        return Proposal(
            run="run-walk",
            model=path,
            settings=ws.one_step().model_copy(
                update={"population": 4, "generations": 1, "refine": "none"}
            ),
            what=(
                f"a walk model{smoothed}: {variant.text()}, the stride's phase a clock from the "
                "fitted frames' first; solved exactly on every fitted frame"
            ),
        )
