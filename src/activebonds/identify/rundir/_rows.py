"""What a notebook shows of a run (private to :class:`~.RunDir`, which shows its own and
lends it to the report's ``RunRecord``)."""

from __future__ import annotations


def run_rows(status: dict, settings: dict, records: dict, model=None) -> list[tuple[str, object]]:
    """What a notebook shows of a run (status.json, run.json's settings, the post-fit stages'
    records, the best model or None): (name, value) rows."""
    from ...notebook import number
    from ..judge.verdict import fit_verdict
    from ..stages.baselines import ZERO

    g, total = status.get("generation"), status.get("generations", settings.get("generations"))
    rows: list[tuple[str, object]] = [
        ("status", status.get("status", "unknown")),
        ("generations", f"{g if g is not None else '?'} of {total}"),
        (
            "search",
            f"{settings.get('optimizer', '?')}, population {settings.get('population', '?')}",
        ),
        ("best RMS one-step error", number(status.get("best_rms_mm"), "mm")),
    ]
    zero = (records.get("baselines") or {}).get("zero_force_rms_mm")
    if zero is not None:
        rows.append((ZERO, number(zero, "mm")))
    if (found := fit_verdict(records)) is not None:
        rows.append((f"verdict, {found[0]}, one step", found[1].text()))
    rows.append(("best model", repr(model) if model is not None else "none yet"))
    return rows
