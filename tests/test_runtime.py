"""Importing the package and calling its functions leave the process as it was: XLA_FLAGS,
JAX's x64 mode and matplotlib's backend are the entry points' choice (activebonds.runtime)."""

from __future__ import annotations

import json
import os
import subprocess
import sys

import pytest

from helpers import HORSE_LIMB, HORSE_TROT, TRIANGLE

SCRIPT = r"""
import json, os, sys
from pathlib import Path

def state():
    import jax, matplotlib
    return [os.environ.get("XLA_FLAGS"), bool(jax.config.jax_enable_x64), matplotlib.get_backend()]

before = state()
import activebonds, activebonds.report, activebonds.report.html, activebonds.identify
import activebonds.experiments.paper, activebonds.simulation
imported = state()
from activebonds.identify import fit
from activebonds.report.html import write_report
run = Path(sys.argv[3]) / "run"
result = fit(sys.argv[1], sys.argv[2], markers=("Head", "Withers", "HFL"), frames=(0, 10),
             population=8, generations=3, out=run)
write_report(run)
called = state()
x64_inside = json.loads((run / "run.json").read_text())["backend"]["x64"]
print(json.dumps({"before": before, "imported": imported, "called": called,
                  "x64_inside": x64_inside, "dtype": str(result.genome.dtype)}))
"""


@pytest.mark.slow  # integration scale: in `pytest -m slow` (every landing)
def test_import_and_calls_leave_the_process_as_it_was(tmp_path):
    env = {k: v for k, v in os.environ.items() if k not in ("XLA_FLAGS", "JAX_ENABLE_X64")}
    env["MPLBACKEND"] = "svg"  # any backend but Agg: switching to Agg would show
    proc = subprocess.run(
        [sys.executable, "-c", SCRIPT, str(HORSE_LIMB), str(HORSE_TROT), str(tmp_path)],
        capture_output=True,
        text=True,
        env=env,
        timeout=600,
        check=False,
    )
    assert proc.returncode == 0, proc.stderr
    got = json.loads(proc.stdout.strip().splitlines()[-1])
    assert got["before"] == [None, False, "svg"]
    assert got["imported"] == got["before"]
    assert got["called"] == got["before"]
    # ... while the fit itself ran in float64 (the default precision), scoped to the call
    assert got["x64_inside"] is True and got["dtype"] == "float64"


def test_the_public_face_is_importable_from_the_top_level():
    import activebonds
    from activebonds import (
        FitSettings,
        fit,
        load_model,
        read_trajectory,
        resume,
        save_model,
        simulate,
        write_report,
    )

    assert callable(fit) and callable(resume) and callable(write_report)
    assert FitSettings().population == 100
    model = load_model(TRIANGLE)
    traj = simulate(model, 5, 60.0)
    assert traj.n_frames == 5 and read_trajectory(HORSE_TROT).n_markers == 7
    assert save_model.__module__ == "activebonds.model.io"
    import activebonds.simulation  # noqa: F401  (the module does not shadow the function)

    assert activebonds.simulate is simulate
    assert set(activebonds.__all__) == {
        "fit", "resume", "FitResult", "FitSettings", "load_model", "save_model",
        "read_trajectory", "write_trajectory", "simulate", "write_report",
        "fill_file", "FillSettings", "FilledFile",
    }  # fmt: skip
