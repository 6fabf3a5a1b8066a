"""The shot candidate: where marker noise dominates the one-step scores, the kept model
refined by multiple shooting (:data:`~.base.SHOOTING`, ``OUT/run-shot``), whose optimum the
noise does not bias; up to :data:`~.base.MAX_SHOT` parameters (above, it says so and leaves
it to ``fit --cost shooting``)."""

from __future__ import annotations

from .base import MAX_SHOT, SHOOTING, Proposal


class ShotCandidate:
    """The kept model, shot, where the noise dominates."""

    name = "shot"

    def propose(self, ws, kept) -> Proposal | None:
        from ...identify.rundir import RunDir
        from ...model import load_model

        if kept is None or not ws.noise.dominated:
            return None
        start = RunDir(kept.run).best_model_path
        genes = load_model(start).layout.n_genes
        if genes > MAX_SHOT:
            ws.say(
                f"      shot: the one-step optimum is biased by the marker noise (its dampings "
                f"above all); multiple shooting, which is not, is left to fit --cost shooting "
                f"above {MAX_SHOT} parameters ({genes} here)"
            )
            return None
        return Proposal(
            run="run-shot",
            model=start,
            settings=ws.settings().model_copy(
                update={**SHOOTING, "population": 4, "generations": 1}
            ),
            what=(
                f"the marker noise biases the one-step optimum (its dampings above all): "
                f"{kept.run.name}'s model refined by multiple shooting (horizon "
                f"{SHOOTING['horizon'][0]}, {SHOOTING['substeps']} Verlet substeps), which it "
                "does not bias"
            ),
        )
