"""The report's figure of identified parameters (report/plots.py): a labelled bar per
parameter up to plots.LABELLED of them; above, one figure of fixed size whose dots still say
which parameters sit on a bound (a 1,968-parameter walk model's bar chart was 550 inches
tall and half of its report's minute)."""

from __future__ import annotations

import numpy as np
from PIL import Image

from activebonds.model import loads_model
from activebonds.report import plots


def _model(n_springs: int):
    """A chain of ``n_springs`` + 1 particles, each spring's stiffness, rest length and
    damping free: 3 parameters a spring; the first spring's stiffness on its upper bound."""
    particles = "".join(f'[[particle]]\nname = "p{i}"\n' for i in range(n_springs + 1))
    springs = "".join(
        f'[[bond]]\nkind = "binary"\nparticles = ["p{i}", "p{i + 1}"]\n'
        f"stiffness = {{ value = {100.0 if i == 0 else 50.0}, min = 1.0, max = 100.0 }}\n"
        "rest_length = { value = 0.5, min = 0.1, max = 1.0 }\n"
        "damping = { value = 1.0, min = 0.0, max = 10.0 }\n"
        for i in range(n_springs)
    )
    return loads_model(f'name = "chain"\n{particles}{springs}', "<chain>")


def test_many_parameters_make_one_figure_of_fixed_size_that_marks_the_bounds(tmp_path):
    many = _model(60)  # 180 parameters
    assert many.layout.n_genes == 180 > plots.LABELLED
    png, svg = plots.parameters(many, tmp_path / "many")
    assert _height(png) <= 4.5 * plots.DPI + 2
    text = svg.read_text()
    assert "1 of 180 within 1 % of a bound" in text
    assert "stiffness" not in text  # no label per parameter

    few = _model(5)  # 15 parameters: a labelled bar each
    png, svg = plots.parameters(few, tmp_path / "few")
    text = svg.read_text()
    assert text.count("stiffness") >= 5
    assert _height(png) > 0.28 * 15 * plots.DPI


def _height(png) -> int:
    with Image.open(png) as image:
        return int(image.size[1])


def test_a_large_body_s_trajectories_show_the_markers_predicted_worst():
    """Above plots_large.SHOWN markers, the trajectories figure holds the SHOWN markers with
    the largest one-step RMS (in file order) and says so; at or below, every marker."""
    from types import SimpleNamespace

    from activebonds.report.plots_large import SHOWN, shown_particles

    rms = np.arange(30, dtype=float)[::-1].copy()  # marker 0 worst
    rms[[3, 7]] = [1e3, np.nan]  # marker 3 worst of all, marker 7 unscored
    pred = SimpleNamespace(recorded=np.zeros((5, 30, 3)), one_step_rms_mm=rms)
    shown = shown_particles(pred)
    assert len(shown) == SHOWN and shown == sorted(shown)
    assert 3 in shown and 7 not in shown
    assert shown == sorted([3, *[i for i in range(30) if i not in (3, 7)][: SHOWN - 1]])
    few = SimpleNamespace(recorded=np.zeros((5, SHOWN, 3)), one_step_rms_mm=np.ones(SHOWN))
    assert shown_particles(few) == list(range(SHOWN))


def test_a_large_body_s_gait_figure_shows_the_markers_whose_height_varies_most():
    from activebonds.report.gait_plots import most_moving
    from activebonds.report.plots_large import SHOWN

    phase = np.linspace(0, 1, 50, endpoint=False)[:, None]
    heights = np.sin(2 * np.pi * phase) * np.arange(20)[None, :]  # marker i: amplitude i
    heights[:, 19] = np.nan  # never seen: last
    assert most_moving(heights) == list(range(19 - SHOWN, 19))
    assert most_moving(heights[:, :SHOWN]) == list(range(SHOWN))
