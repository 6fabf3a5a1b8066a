"""The gait candidate: where the fitted frames are rhythmic, the model of the gait family
(:mod:`~activebonds.identify.discover.gait`: an anchor and a periodic force per marker, the
drive's phase entrained by the body) whose variant the fitted frames' second half chose
(:func:`~activebonds.auto.gait.choose`), solved exactly on every fitted frame
(``OUT/gait.toml``, ``OUT/run-gait``). Its markers, rate and frames are the recording's: no
name, rate or length is read but as numbers of the data."""

from __future__ import annotations

from .base import Proposal


class GaitCandidate:
    """A drive and periodic forces, where the motion repeats."""

    name = "gait"

    def propose(self, ws, kept) -> Proposal | None:
        from ...data.orientation import parse_up
        from ...model import save_model
        from ..gait import choose

        model_markers = list(ws.options.markers) if ws.options.markers else None
        recording = ws.structural
        if model_markers:
            recording = recording.select(model_markers)
        up = parse_up(ws.options.up, recording.positions.shape[2]) if ws.options.up else None
        each = ws.say if ws.verbose else (lambda line: None)
        chosen = choose(recording, ws.split.fitted, ws.options.ahead, up, ws.say, each)
        if chosen is None:
            return None
        path = ws.folder.path / "gait.toml"
        save_model(chosen.spec, path)
        ws.note(
            "fit",
            "gait",
            {
                "notes": list(chosen.notes),
                "variants": [j.line() for j in chosen.judged],
                "chosen": chosen.best.variant.text(),
            },
        )
        smoothed = " (the positions smoothed as for the structure)" if ws.noise.window else ""
        return Proposal(
            run="run-gait",
            model=path,
            settings=ws.one_step().model_copy(update={"population": 4, "generations": 1}),
            what=(
                f"a gait model{smoothed}: {chosen.best.variant.text()}, chosen among "
                f"{len(chosen.judged)} variants fitted on the fitted frames' first half and "
                "judged on the second; solved exactly on every fitted frame"
            ),
        )
