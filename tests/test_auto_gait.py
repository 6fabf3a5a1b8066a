"""``activebonds auto`` on a rhythmic recording it never saw (a simulated quadruped,
:mod:`activebonds.experiments.quadruped`: its own marker names, rate and period) proposes the
gait family, which the one rule keeps, and the kept model beats zero force at every marker held
out."""

from __future__ import annotations

import json
from html import unescape

import pytest

from activebonds import auto
from activebonds.data.writers import write_trajectory
from activebonds.experiments.quadruped import quadruped


@pytest.mark.slow
def test_auto_finds_and_keeps_a_gait_on_a_simulated_quadruped(tmp_path):
    path = tmp_path / "quad.trc"
    write_trajectory(quadruped("trot", rate=90.0, seconds=10.0, stride_hz=1.3, seed=4), path)
    said = []
    outcome = auto.run(
        path, tmp_path / "out", auto.Options(held_out=0.5), say=said.append, verbose=False
    )
    state = json.loads((tmp_path / "out" / "auto.json").read_text())
    rows = {r["candidate"]: r for r in state["steps"]["fit"]["candidates"]}
    assert "gait" in rows and state["steps"]["fit"]["run"] == "run-gait"
    assert any("gait: stride period" in line and "rhythmic" in line for line in said)
    one = outcome.held_out.comparisons[0]
    assert not one.worse_markers()
    assert one.model_mm < one.zero_force_mm
    far = outcome.held_out.comparisons[-1]
    assert far.model_mm < 0.8 * far.zero_force_mm
    # the report says how: the rhythm, the variants judged and the one chosen
    gait = state["steps"]["fit"]["gait"]
    assert gait["chosen"] in [line.split(": one step")[0] for line in gait["variants"]]
    html = unescape((tmp_path / "out" / "report.html").read_text())
    assert "gait: stride period" in html and f"gait chosen: {gait['chosen']}" in html
