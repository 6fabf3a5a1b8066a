"""Step 3 of ``activebonds auto``, the fit: every registered candidate
(:data:`~.candidates.CANDIDATES`) in turn proposes a model against the one kept so far, which
is fitted (:meth:`~.workspace.Workspace.fit`), judged on the validation frames
(:func:`~.judge.judge`) and kept where the judge finds it better (or where it insists)."""

from __future__ import annotations

from . import table
from .candidates import CANDIDATES, Tried
from .judge import better, compared, judge
from .notes import fixed_masses_note


def decision(tried: Tried, kept: Tried | None, insist: bool) -> tuple[bool, str]:
    """Whether ``tried`` replaces ``kept`` (the judge's rule, or ``insist``), and why."""
    if kept is None:
        return True, "kept: the first"
    why = compared(tried.judged, kept.judged, kept.run.name)
    if better(tried.judged, kept.judged):
        return True, f"kept: {why}"
    if insist:
        return True, f"kept: --up or --gravity insists ({why})"
    return False, f"not kept: {why}"


def _has_gravity(model_path) -> bool:
    from ..model import load_model

    return load_model(model_path).spec.gravity is not None


def fit_step(ws) -> str:
    """Every candidate proposed, fitted, judged and kept or not (see the module's docstring);
    the table of them and the kept run's name recorded in the fit step (``steps.fit``)."""
    kept: Tried | None = None
    insisted = False  # the kept model is one --up or --gravity insisted on (it has gravity)
    rows: list[dict] = []
    for candidate in CANDIDATES.entries():
        proposal = candidate.propose(ws, kept)
        if proposal is None:
            continue
        if insisted and not _has_gravity(proposal.model):
            ws.say(
                f"      {candidate.name}: not fitted: --up or --gravity insists on gravity, "
                "which its model has none of"
            )
            continue
        ws.say(f"      {candidate.name}: {proposal.what}")
        fitted_mm = ws.fit(proposal.run, proposal.model, proposal.settings)
        run = ws.folder.path / proposal.run
        tried = Tried(candidate.name, run, judge(ws, run), fitted_mm)
        keep, why = decision(tried, kept, proposal.insist)
        for r in rows:
            if keep and r["kept"]:
                r["kept"], r["why"] = False, f"{r['why']}; replaced by {proposal.run}"
        rows.append(table.row(tried.name, run.name, tried.judged, fitted_mm, keep, why))
        if keep:
            kept = tried
            insisted = proposal.insist
    if kept is None:
        raise RuntimeError("no candidate model was proposed: nothing to fit")
    ws.note("fit", "run", kept.run.name)
    ws.note("fit", "candidates", rows)
    flight = ws.folder.run_flight if ws.folder.run_flight.exists() else None
    masses = fixed_masses_note(kept.run, flight) if kept.run != ws.folder.run_masses else None
    if masses:  # said after the verdict (Outcome.verdict_lines)
        ws.note("fit", "masses", masses)
    j = kept.judged
    a, b = j.frames
    return (
        f"kept {kept.run.name} of {len(rows)} candidate(s), on the validation frames {a}:{b}: "
        f"one step {j.one_step_mm:.4g} mm (zero force {j.zero_force_one_step_mm:.4g} mm, "
        f"{j.worse} of {j.markers} markers worse), {j.horizon} ahead {j.ahead_mm:.4g} mm "
        f"(zero force {j.zero_force_ahead_mm:.4g} mm): {kept.run}"
    )


def table_lines(ws) -> list[str]:
    """The fit step's table of candidates, as recorded, in lines to say."""
    return [f"      {line}" for line in table.lines(ws.step_record("fit").get("candidates", []))]
