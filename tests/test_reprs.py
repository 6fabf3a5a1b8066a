"""In a notebook, a Trajectory, a Model and a FitResult print as one short line: sizes, rate,
kinds, error and status, never an array."""

from __future__ import annotations

from activebonds import fit, load_model, read_trajectory
from helpers import HORSE_LIMB, HORSE_TROT, ROOT, TRIANGLE


def _short(text: str, limit: int = 300) -> None:
    assert "\n" not in text and len(text) <= limit, text
    assert "array(" not in text and "[[" not in text, text


def test_trajectory_repr():
    text = repr(read_trajectory(HORSE_TROT))
    _short(text)
    assert text.startswith("Trajectory(600 frames x 7 markers [Head, Withers,")
    assert "60 Hz" in text and "0 missing marker-frames" in text


def test_model_repr():
    text = repr(load_model(HORSE_LIMB))
    _short(text)
    assert text == "Model('horse_limb', 3D, 3 particles, bonds: 3 binary, 27 free parameters)"


def test_fit_result_repr():
    result = fit(
        TRIANGLE,
        ROOT / "examples" / "triangle.csv",
        frames=(0, 30),
        population=8,
        generations=2,
        refine="none",
    )
    text = repr(result)
    _short(text, 400)
    assert text.startswith("FitResult(Model('triangle'")
    assert f"rms {result.rms_mm:.4g} mm" in text and "es 8 x 2" in text
