"""A second fit of the same model and window in one process compiles nothing: ``fit`` keeps
compiled programs (JAX's persistent cache, turned on where the process has none), so the
second loads the first's programs; the numbers are the same. The time it saves is measured by
``benchmarks/second_fit.py`` (docs/results/second_fit.json)."""

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]

CHILD = r"""
import json, sys
import jax
from jax import monitoring
from activebonds import fit

misses = []
monitoring.register_event_listener(
    lambda name, **kw: misses.append(1) if name == "/jax/compilation_cache/cache_misses" else None
)
runs = []
for _ in range(int(sys.argv[1])):
    misses.clear()
    result = fit(
        "src/activebonds/examples/horse_limb.toml",
        "src/activebonds/datasets/horse_vhdc/Horse1_M1_trot1_kinematics.csv",
        markers=("Head", "Withers", "HFL"), frames=(0, 20), bonds="neural",
        population=20, generations=4, seed=0,
    )
    runs.append({"compiled": len(misses), "rms_mm": result.rms_mm,
                 "genome": [float(g) for g in result.genome]})
print(json.dumps({"runs": runs, "cache": jax.config.jax_compilation_cache_dir}))
"""


def _fits(n: int, **env_changes) -> dict:
    env = dict(os.environ, **env_changes)
    env.pop("JAX_PERSISTENT_CACHE_MIN_COMPILE_TIME_SECS", None)
    out = subprocess.run(
        [sys.executable, "-c", CHILD, str(n)], cwd=ROOT, env=env, capture_output=True, text=True
    )
    assert out.returncode == 0, out.stderr[-2000:]
    return json.loads(out.stdout.strip().splitlines()[-1])


@pytest.mark.slow  # integration scale: in pytest -m slow (every landing)
def test_a_second_fit_of_the_same_shapes_compiles_nothing_and_gives_the_same_numbers(tmp_path):
    cache = tmp_path / "cache"
    got = _fits(2, ACTIVEBONDS_CACHE=str(cache))
    first, second = got["runs"]
    assert got["cache"] == str(cache)
    assert first["compiled"] > 10  # the ES, the refinement, the baselines
    assert second["compiled"] == 0
    assert second["rms_mm"] == first["rms_mm"]
    assert second["genome"] == first["genome"]
    assert len(list(cache.iterdir())) >= first["compiled"]


@pytest.mark.slow  # integration scale: in pytest -m slow (every landing)
def test_the_cache_can_be_switched_off():
    got = _fits(1, ACTIVEBONDS_CACHE="off")
    assert got["cache"] is None
    assert got["runs"][0]["compiled"] == 0  # no cache: none consulted, nothing written
