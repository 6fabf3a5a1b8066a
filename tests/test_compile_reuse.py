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


AUTO_CHILD = r"""
import json, sys
from pathlib import Path
from jax import monitoring
from activebonds import auto
from activebonds.data.bundled import dataset
from activebonds.identify.rundir import RunDir
from activebonds.model import load_model, save_model
from activebonds.simulation import simulate_to_file

misses = []
monitoring.register_event_listener(
    lambda name, **kw: misses.append(1) if name == "/jax/compilation_cache/cache_misses" else None
)
at = {}


class Restarted:
    '''The kept model's structure again, every free parameter started at twice its fitted
    value (inside its bounds): the same shapes and structure, other values.'''

    name = "restarted"

    def propose(self, ws, kept):
        at["propose"] = len(misses)
        spec = load_model(RunDir(kept.run).best_model_path).spec
        bonds = []
        for b in spec.bond:
            update = {}
            for key in ("stiffness", "damping"):
                p = getattr(b, key, None)
                if p is not None and hasattr(p, "value") and p.max is not None:
                    update[key] = p.model_copy(update={"value": min(2 * p.value, p.max)})
            bonds.append(b.model_copy(update=update))
        path = ws.folder.path / "restarted.toml"
        save_model(spec.model_copy(update={"bond": bonds}), path)
        return auto.Proposal(run="run-restarted", model=path, settings=ws.one_step(),
                             what="the kept structure, other start values")


def said(line):
    if line.startswith("[4/5]") and "end" not in at:
        at["end"] = len(misses)


out = Path(sys.argv[1])
recording = out.parent / "triangle.csv"
simulate_to_file(dataset("triangle.toml").path, 300, 60.0, recording, None, 1, "euler")
options = auto.Options(gravity=False, population=8, generations=5, ahead=5)
with auto.CANDIDATES.registered(Restarted()):
    outcome = auto.run(recording, out, options, say=said)
rows = {r["candidate"]: r for r in outcome.state["steps"]["fit"]["candidates"]}
print(json.dumps({"before": at["propose"], "restarted": at["end"] - at["propose"],
                  "rows": {k: v["one_step_mm"] for k, v in rows.items()},
                  "models": [(out / r / "best_model.toml").read_text()
                             for r in ("run", "run-restarted")]}))
"""


@pytest.mark.slow  # integration scale: in pytest -m slow (every landing)
def test_in_auto_a_candidate_of_the_same_shapes_as_an_earlier_one_compiles_nothing(tmp_path):
    """A candidate registered in ``auto`` that proposes the kept model's structure with other
    start values (the same shapes, the same structure, other numbers): its fit and its
    judging load every program from the earlier candidate's (JAX's own count of persistent
    cache misses: none), though they compile dozens first, and it is a fit of its own."""
    env = dict(os.environ, ACTIVEBONDS_CACHE=str(tmp_path / "cache"))
    env.pop("JAX_PERSISTENT_CACHE_MIN_COMPILE_TIME_SECS", None)
    out = subprocess.run(
        [sys.executable, "-c", AUTO_CHILD, str(tmp_path / "out")],
        cwd=ROOT, env=env, capture_output=True, text=True,
    )  # fmt: skip
    assert out.returncode == 0, out.stderr[-2000:]
    got = json.loads(out.stdout.strip().splitlines()[-1])
    assert got["before"] > 10  # the structure's fit and judge compiled their programs
    assert got["restarted"] == 0
    assert set(got["rows"]) >= {"structure", "restarted"}
    assert got["models"][0] != got["models"][1]  # other values: not the same fit again
