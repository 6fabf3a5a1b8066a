"""Shared helpers of the identification tests: paths, small models, and running the CLI."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
EXAMPLES = ROOT / "examples"
TRIANGLE = EXAMPLES / "triangle.toml"
HORSE_LIMB = EXAMPLES / "horse_limb.toml"
HORSE_TROT = (
    ROOT / "src" / "activebonds" / "datasets" / "horse_vhdc" / "Horse1_M1_trot1_kinematics.csv"
)

# Headless Debian Chromium for the report's browser tests (through Playwright)
CHROMIUM = Path("/usr/bin/chromium")
BROWSER_ARGS = [
    "--no-sandbox",
    "--disable-gpu",
    "--disable-background-networking",
    "--disable-component-update",
    "--disable-sync",
    "--no-first-run",
]

# The command installed next to the interpreter running the tests (the venv's console script).
ACTIVEBONDS = Path(sys.executable).with_name("activebonds")


def browser_or_skip():
    """(Playwright's ``sync_playwright``, the Chromium executable), or the test skipped."""
    import shutil

    import pytest

    try:
        from playwright.sync_api import sync_playwright
    except ImportError:
        pytest.skip("playwright is not installed (pip install '.[test]')")
    if not CHROMIUM.is_file() and shutil.which("chromium") is None:
        pytest.skip("Debian's chromium is not installed (apt-get install chromium)")
    return sync_playwright, str(CHROMIUM if CHROMIUM.is_file() else shutil.which("chromium"))


def cli(*args, cwd: Path | None = None, timeout: float = 300) -> subprocess.CompletedProcess:
    """Run ``activebonds ARGS`` in a fresh process; text stdout/stderr captured."""
    env = dict(os.environ, COLUMNS="200", NO_COLOR="1")
    return subprocess.run(
        [str(ACTIVEBONDS), *map(str, args)],
        cwd=cwd,
        env=env,
        capture_output=True,
        text=True,
        timeout=timeout,
        check=False,
    )


def cli_in_process(*args) -> subprocess.CompletedProcess:
    """Run ``activebonds ARGS`` in this process (Typer's CliRunner), for tests of what a
    command does rather than of its process; the same fields as :func:`cli`'s result."""
    from typer.testing import CliRunner

    from activebonds.cli.main import app

    argv = list(map(str, args))
    res = CliRunner().invoke(app, argv, env={"COLUMNS": "200", "NO_COLOR": "1"})
    if res.exception is not None and not isinstance(res.exception, SystemExit):
        raise res.exception
    return subprocess.CompletedProcess(argv, res.exit_code, res.stdout, res.stderr)


def each_case_both_ways(argnames: str, cases, ids=None) -> tuple[str, list]:
    """``pytest.mark.parametrize`` arguments running each refusal case two ways, the runner
    (:func:`cli_in_process` or :func:`cli`) first: every case in this process in the default
    run, and in a fresh process (nothing else on its stderr: no import or shutdown noise) the
    first case in the default run, the others in ``pytest -m slow`` (3 s of imports each)."""
    import pytest

    params = []
    for i, case in enumerate(cases):
        name = ids[i] if ids else str(i)
        params.append(pytest.param(cli_in_process, *case, id=f"{name}-in-process"))
        slow = () if i == 0 else pytest.mark.slow
        params.append(pytest.param(cli, *case, id=f"{name}-fresh-process", marks=slow))
    return f"run,{argnames}", params


def both_ways_fresh_in_slow() -> tuple[str, list]:
    """``pytest.mark.parametrize`` arguments for a ``run`` runner: :func:`cli_in_process` in
    the default run, :func:`cli` (a fresh process, 3 s of imports) in ``pytest -m slow``; for a
    check of what a command does, where a fresh process's own output (nothing else on stderr)
    is checked in the default run by other tests (:func:`each_case_both_ways`)."""
    import pytest

    fresh = pytest.param(cli, id="fresh-process", marks=pytest.mark.slow)
    return "run", [pytest.param(cli_in_process, id="in-process"), fresh]


def cli_popen(*args, cwd: Path | None = None, log: Path | None = None) -> subprocess.Popen:
    """Start ``activebonds ARGS`` in the background (output to ``log`` or discarded)."""
    env = dict(os.environ, COLUMNS="200", NO_COLOR="1")
    out = open(log, "wb") if log is not None else subprocess.DEVNULL  # noqa: SIM115
    try:
        return subprocess.Popen(
            [str(ACTIVEBONDS), *map(str, args)], cwd=cwd, env=env, stdout=out, stderr=out
        )
    finally:
        if log is not None:
            out.close()


# A 3-particle triangle like examples/triangle.toml, every bond mechanical-neural with known,
# non-zero gains, thresholds and weights (the ground truth of the neural recovery test).
NEURAL_TRIANGLE = """
name = "neural_triangle"
dimension = 3

[[particle]]
name = "A"
mass = 1.0
position = [0.0, 0.0, 0.0]
velocity = [0.0, 0.3, 0.1]

[[particle]]
name = "B"
mass = 1.5
position = [0.55, 0.0, 0.05]
velocity = [0.0, -0.2, 0.0]

[[particle]]
name = "C"
mass = 2.0
position = [0.2, 0.45, 0.0]
velocity = [0.1, 0.0, -0.15]

[[bond]]
kind = "binary"
particles = ["A", "B"]
neural = true
stiffness = { value = 40.0, min = 1.0, max = 1000.0 }
rest_length = { value = 0.5, min = 0.25, max = 0.75 }
damping = { value = 0.5, min = 0.01, max = 10.0 }
gain = { value = 3.0, min = 0.0, max = 20.0 }
threshold = { value = 0.1, min = -1.0, max = 1.0 }
weights = { length = [0.0, 2.0, -1.5], rate = [0.0, 0.5, 0.3], min = -5.0, max = 5.0 }

[[bond]]
kind = "binary"
particles = ["B", "C"]
neural = true
stiffness = { value = 60.0, min = 1.0, max = 1000.0 }
rest_length = { value = 0.6, min = 0.3, max = 0.9 }
damping = { value = 1.0, min = 0.01, max = 10.0 }
gain = { value = 4.0, min = 0.0, max = 20.0 }
threshold = { value = -0.2, min = -1.0, max = 1.0 }
weights = { length = [1.0, 0.0, 2.5], rate = [-0.4, 0.0, 0.2], min = -5.0, max = 5.0 }

[[bond]]
kind = "binary"
particles = ["A", "C"]
neural = true
stiffness = { value = 80.0, min = 1.0, max = 1000.0 }
rest_length = { value = 0.45, min = 0.2, max = 0.7 }
damping = { value = 0.8, min = 0.01, max = 10.0 }
gain = { value = 2.0, min = 0.0, max = 20.0 }
threshold = { value = 0.3, min = -1.0, max = 1.0 }
weights = { length = [-2.0, 1.5, 0.0], rate = [0.3, -0.5, 0.0], min = -5.0, max = 5.0 }
"""


def bowl_problem(n_genes: int = 3):
    """A strategy Problem whose cost is the squared distance to (0.2 ... 0.8) in [0, 1]^n,
    each gene its own group and local cost."""
    import jax.numpy as jnp
    import numpy as np

    from activebonds.identify.search.strategy import Problem

    target = jnp.linspace(0.2, 0.8, n_genes)

    def evaluate(g):
        local = (g - target) ** 2
        return jnp.sum(local), local

    return Problem(
        evaluate=evaluate,
        lower=np.zeros(n_genes),
        upper=np.ones(n_genes),
        gene_group=np.arange(n_genes, dtype=np.int32),
        group_slots=np.arange(n_genes, dtype=np.int32)[:, None],
    )


def figure_texts(svg: Path) -> list[str]:
    """Every text a report figure's SVG shows (titles, tick labels, legend, annotations): the
    figures are saved with ``svg.fonttype = none``, so each is a ``<text>`` element."""
    import xml.etree.ElementTree as ET

    root = ET.parse(svg).getroot()
    return ["".join(t.itertext()) for t in root.iter("{http://www.w3.org/2000/svg}text")]


def figure_size_px(svg: Path, dpi: float) -> tuple[float, float]:
    """The pixel size at ``dpi`` of the figure an SVG holds (its width and height in points)."""
    import xml.etree.ElementTree as ET

    root = ET.parse(svg).getroot()
    w, h = (float(root.attrib[k].removesuffix("pt")) for k in ("width", "height"))
    return w / 72 * dpi, h / 72 * dpi


def assert_periodic_coefficients(got, want, harmonics: int = 3) -> None:
    """A periodic force's cos/sin coefficients of the first ``harmonics`` equal (rtol 1e-5):
    the gait and walk families' recovery tests."""
    import numpy as np

    for h in range(1, harmonics + 1):
        for wave in ("cos", "sin"):
            np.testing.assert_allclose(
                getattr(got, f"{wave}{h}").value,
                getattr(want, f"{wave}{h}").value,
                rtol=1e-5,
                atol=1e-6,
            )
