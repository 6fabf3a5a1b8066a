"""Golden results: three tiny reference fits must reproduce their stored results.

The cases, how they are computed and compared, live in scripts/record_golden.py (shared
with this test, so the two cannot drift apart); the stored results and the two simulated
recordings are in tests/golden/. A mismatch means results changed: if that is intended,
re-record with ``python scripts/record_golden.py`` and commit tests/golden/.
"""

from __future__ import annotations

import importlib.util
import json
from pathlib import Path

import numpy as np
import pytest

from activebonds.data import read_trajectory

pytestmark = pytest.mark.timeout(300)

ROOT = Path(__file__).resolve().parents[1]
_spec = importlib.util.spec_from_file_location(
    "record_golden", ROOT / "scripts" / "record_golden.py"
)
golden = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(golden)


@pytest.mark.parametrize("name", list(golden.CASES))
def test_golden_fit(name):
    path = golden.golden_file(name)
    assert path.is_file(), f"{path} is missing; record it with: {golden.COMMAND}"
    stored = json.loads(path.read_text())
    fresh = golden.compute(name)
    problems = golden.compare(stored, fresh)
    assert not problems, (
        f"golden result '{name}' changed: {'; '.join(problems)}. If this change is intended, "
        f"re-record with: {golden.COMMAND} (and commit tests/golden/)"
    )


def test_golden_recordings_are_the_simulated_ones(tmp_path):
    """The stored recordings are what the simulator produces today (to 1e-9 m: CSV in mm)."""
    from activebonds.model import load_model
    from activebonds.simulation import simulate

    for name, (model, frames, rate) in golden.RECORDINGS.items():
        stored = read_trajectory(golden.GOLDEN / name)
        fresh = simulate(load_model(golden.EXAMPLES / model), frames, rate)
        assert stored.markers == fresh.markers and stored.rate == fresh.rate
        np.testing.assert_allclose(stored.positions, fresh.positions, rtol=0, atol=1e-9)


def test_compare_reports_a_change():
    """The comparison is not vacuous: a 1e-10 relative change of one cost is reported."""
    stored = json.loads(golden.golden_file("chain2d").read_text())
    changed = json.loads(json.dumps(stored))
    changed["best_cost"][3] *= 1 + 1e-10
    assert golden.compare(stored, stored) == []
    assert "generation 40" in golden.compare(stored, changed)[0]
