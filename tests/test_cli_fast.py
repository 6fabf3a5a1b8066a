"""The command line answers at once: help, ``--version`` and usage errors never import JAX or
the numerics (benchmarks/cli_startup.py times them); a command that runs still gets the
process's JAX settings (XLA flags, compilation cache) before it computes."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from importlib import metadata

import pytest

# main() as the ``activebonds`` script calls it, then what it imported, as the last line
SCRIPT = r"""
import json, sys
sys.argv = ["activebonds", *sys.argv[1:]]
from activebonds.cli.main import main
try:
    main()
    code = 0
except SystemExit as e:
    code = e.code
heavy = ("jax", "jaxlib", "numpy", "scipy", "matplotlib", "optimistix", "evosax", "equinox")
state = {"code": code, "imported": sorted(m for m in heavy if m in sys.modules)}
if "jax" in sys.modules:
    import jax, os
    state["cache"] = jax.config.jax_compilation_cache_dir
    state["xla_flags"] = os.environ.get("XLA_FLAGS", "")
print("\n" + json.dumps(state))
"""


def run_main(*args: str, env: dict | None = None) -> tuple[dict, str, str]:
    """(state after main(), stdout before it, stderr) of ``activebonds ARGS`` in a fresh
    process."""
    proc = subprocess.run(
        [sys.executable, "-c", SCRIPT, *args],
        capture_output=True,
        text=True,
        env=env,
        timeout=300,
        check=False,
    )
    assert "Traceback" not in proc.stderr, proc.stderr
    shown, _, last = proc.stdout.rstrip("\n").rpartition("\n")
    return json.loads(last), shown, proc.stderr


@pytest.mark.parametrize(
    "args, code",
    [
        (("--help",), 0),
        (("-h",), 0),
        (("fit", "--help"), 0),
        (("fit", "-h"), 0),
        (("info", "--help"), 0),
        (("--version",), 0),
        (("fit", "--bogus"), 2),
        (("fit",), 2),
        (("info",), 2),
    ],
)
def test_help_version_and_usage_errors_import_no_numerics(args, code):
    state, shown, errors = run_main(*args)
    assert state["code"] == code, errors
    assert state["imported"] == [], f"activebonds {' '.join(args)} imported {state['imported']}"
    if code == 0 and args != ("--version",):
        usage = " ".join(["Usage: activebonds", *args[:-1], "[OPTIONS]"])
        assert usage in shown and "--help" in shown and "-h" in shown
    if code == 2:
        assert len(errors.strip().splitlines()) == 1 and errors.startswith("error: ")


def test_version_prints_the_installed_package_version():
    state, shown, _ = run_main("--version")
    assert state["code"] == 0
    assert shown.strip() == f"activebonds {metadata.version('activebonds')}"


def test_a_command_that_runs_gets_the_xla_flags_and_the_compilation_cache(tmp_path):
    env = {k: v for k, v in os.environ.items() if k != "XLA_FLAGS"}
    env["ACTIVEBONDS_CACHE"] = str(tmp_path / "cache")
    state, shown, errors = run_main("datasets", "triangle.toml", env=env)
    assert state["code"] == 0, errors
    assert shown.strip().endswith("triangle.toml")
    assert "jax" in state["imported"]
    assert state["cache"] == str(tmp_path / "cache") and (tmp_path / "cache").is_dir()
    assert "--xla_cpu_experimental_ynn_fusion_type=" in state["xla_flags"]
