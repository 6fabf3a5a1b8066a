"""Print the Markdown tables of docs/experiments/paper.md from the summary.json files written by
`activebonds reproduce` (usage: python scripts/experiments_table.py OUT/horse OUT/synthetic)."""

from __future__ import annotations

import json
import sys
from pathlib import Path


def fmt(x, digits=3):
    return "n/a" if x is None else f"{x:.{digits}g}"


def baselines(summary: dict) -> dict:
    """The baselines, recomputed from the bundled data if the summary predates them."""
    if "baselines" in summary:
        return summary["baselines"]
    from activebonds.experiments.paper import EXPERIMENTS
    from activebonds.experiments.paper import baselines as compute

    exp = EXPERIMENTS[summary["experiment"]]
    return compute(exp, exp.model(), exp.data())


def table(summary: dict) -> str:
    base = baselines(summary)
    a, b = base["test_frames"]
    lines = [
        f"**{summary['title']}** (scale `{summary['scale']}`, seeds {summary['seeds']}; "
        f"momentum floor of the fit error: {fmt(base['momentum_floor_mm'], 4)} mm)",
        "",
        "| configuration | series | fit RMS mm, median [IQR] | one-step RMS mm, next frames "
        "| free-run RMS mm, next frames | saturated neurons | near-zero weights | wall time |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for name, c in summary["configs"].items():
        for series in ("standard", "neural"):
            r = c["series"][series]
            a, b = r["test_frames"]
            lines.append(
                f"| {name} | {series} | {fmt(r['fit_rms_mm_median'], 4)} "
                f"[{fmt(r['fit_rms_mm_iqr'][0], 4)}, {fmt(r['fit_rms_mm_iqr'][1], 4)}] "
                f"| {fmt(r['one_step_rms_mm_median'])} (frames {a}-{b - 1}) "
                f"| {fmt(r['free_run_rms_mm_median'])} "
                f"| {fmt(r.get('saturated_share_median'), 2) if series == 'neural' else '-'} "
                f"| {fmt(r.get('near_zero_weight_share_median'), 2) if series == 'neural' else '-'} "
                f"| {r['seconds']:.0f} s |"
            )
    lines.append(
        f"| baseline | zero force (constant velocity) | {fmt(base['zero_force_fit_rms_mm'])} "
        f"| {fmt(base['zero_force_test_rms_mm'])} (frames {a}-{b - 1}) | - | - | - | - |"
    )
    lines.append(
        f"| baseline | exact least squares, standard bonds "
        f"| {fmt(base['lsq_standard_fit_rms_mm'], 5)} "
        f"| {fmt(base['lsq_standard_test_rms_mm'])} (frames {a}-{b - 1}) "
        f"| {fmt(base['lsq_standard_free_run_rms_mm'])} | - | - | - |"
    )
    return "\n".join(lines)


if __name__ == "__main__":
    for folder in sys.argv[1:]:
        print(table(json.loads((Path(folder) / "summary.json").read_text())))
        print()
