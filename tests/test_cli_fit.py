"""The paper's horse command (§4.2) on the bundled VHDC trot, at a tiny scale."""

from __future__ import annotations

import json
import math
import re

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from activebonds.data import read_trajectory
from activebonds.identify.costs.windows import make_cost, make_windows, rms_mm
from activebonds.model import load_model
from helpers import HORSE_LIMB, HORSE_TROT, cli


@pytest.mark.slow  # integration scale: in `pytest -m slow` (every landing)
def test_fit_horse_limb_on_the_trot_tiny(tmp_path):
    run = tmp_path / "RUN"
    proc = cli(
        "fit", HORSE_LIMB, HORSE_TROT,
        "--markers", "Head,Withers,HFL", "--frames", "0:10", "--bonds", "neural",
        "--population", "50", "--generations", "300", "--out", run,
        "--cost", "restart",  # the one-step refinement from the ES's best (default: auto)
    )  # fmt: skip
    assert proc.returncode == 0, proc.stderr

    history = np.loadtxt(run / "history.csv", delimiter=",", skiprows=1, ndmin=2)
    assert history.shape[0] == 300
    np.testing.assert_array_equal(history[:, 0], np.arange(1, 301))
    best_rms = history[:, 4]
    assert np.all(np.isfinite(best_rms))
    assert np.all(np.diff(best_rms) <= 0)
    assert best_rms[-1] < best_rms[0]

    status = json.loads((run / "status.json").read_text())
    assert status["status"] == "completed" and status["generation"] == 300
    assert math.isfinite(status["best_rms_mm"])
    # the default refinement (--refine lm) starts from the ES's best and is kept only if
    # it lowers the cost: the final error is the refined one, never above the ES's
    stages = json.loads((run / "refine.json").read_text())["stages"]
    assert len(stages) == 1 and stages[0]["start_rms_mm"] == pytest.approx(best_rms[-1], rel=1e-9)
    final = stages[0]["end_rms_mm"] if stages[0]["accepted"] else best_rms[-1]
    assert final <= best_rms[-1]
    assert status["best_rms_mm"] == pytest.approx(final, rel=1e-12)
    printed = re.search(r"best RMS error ([0-9.eE+-]+) mm", proc.stdout)
    assert printed and float(printed.group(1)) == float(f"{final:.4g}")
    # beside the zero-force baseline on the same frames (the horse's frames 0-9: 5.62 mm)
    zero = re.search(r"zero-force baseline on the same frames ([0-9.eE+-]+) mm", proc.stdout)
    assert zero and float(zero.group(1)) == pytest.approx(5.6205, abs=1e-3)

    settings = json.loads((run / "run.json").read_text())["settings"]
    assert settings["markers"] == ["Head", "Withers", "HFL"]
    assert settings["frames"] == [0, 10] and settings["bonds"] == "neural"

    # the fitted window: 10 frames of the three markers, in the model's particle order
    window = read_trajectory(run / "data.npz")
    assert window.n_frames == 10 and window.markers == ("Head", "Withers", "HFL")
    full = read_trajectory(HORSE_TROT).select(["Head", "Withers", "HFL"])
    np.testing.assert_allclose(window.positions, full.positions[:10], rtol=1e-12, equal_nan=True)

    # the best model is neural and reproduces the reported error on that window
    best = load_model(run / "best_model.toml")
    assert best.topology.bonds["binary"]["neural"].all() and best.topology.count("binary") == 3
    windows = make_windows(window.positions, window.mask, window.dt, 1)
    cost, _ = jax.jit(make_cost(best, windows))(jnp.asarray(best.layout.initial()))
    assert float(rms_mm(cost, windows.n_terms)) == pytest.approx(final, rel=1e-6)
