"""The table of the candidates the fit step tried: one row each (its run, its scores on the
validation frames beside zero force's, kept or why not), as ``auto.json`` records it
(``steps.fit.candidates``) and as it is printed and put in the report, in fixed-width
columns."""

from __future__ import annotations

import math


def row(name: str, run: str, judged, fitted_mm: float, kept: bool, why: str) -> dict:
    """One candidate's row: its name, run, the judge's scores (:class:`~.judge.Judged`),
    its one-step RMS on every fitted frame (the fit's own), whether it is the model kept in
    the end, and its decision in words."""
    fitted = fitted_mm if math.isfinite(fitted_mm) else None
    return {"candidate": name, "run": run, **judged.record(), "fitted_mm": fitted,
            "kept": kept, "why": why}  # fmt: skip


def _mm(x) -> str:
    return "-" if x is None else f"{x:.4g}"


def lines(rows: list[dict]) -> list[str]:
    """The table in plain lines: a heading that names the validation frames and the rule,
    the columns' names, then one line per candidate."""
    if not rows:
        return []
    a, b = rows[0]["frames"]
    h = rows[0]["horizon"]
    head = (
        "candidate", "run", "one step mm", "zero force", "worse", f"{h} ahead mm",
        "zero force", "kept or why not",
    )  # fmt: skip
    body = [
        (
            r["candidate"],
            r["run"],
            _mm(r["one_step_mm"]),
            _mm(r["zero_force_one_step_mm"]),
            f"{r['worse']}/{r['markers']}",
            _mm(r["ahead_mm"]),
            _mm(r["zero_force_ahead_mm"]),
            r["why"],
        )  # fmt: skip
        for r in rows
    ]
    widths = [max(len(str(x[i])) for x in [head, *body]) for i in range(len(head) - 1)]
    right = {2, 3, 4, 5, 6}  # numbers

    def line(cells) -> str:
        out = [
            str(c).rjust(w) if i in right else str(c).ljust(w)
            for i, (c, w) in enumerate(zip(cells, widths, strict=False))
        ]
        return "  ".join([*out, str(cells[-1])])

    rule = (
        f"a lower RMS {h} frames ahead (the marker noise dominates one step)"
        if rows[0].get("noisy")
        else f"fewer markers worse than zero force one step ('worse'), then a lower RMS {h} "
        "frames ahead"
    )
    intro = (
        f"candidates on the validation frames {a}:{b} (the fitted frames' tail), the rule: {rule}"
    )
    return [intro, line(head), *(line(c) for c in body)]
