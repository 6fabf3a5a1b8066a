"""examples/horse_trot_ground.toml is written the way the bundled recording says it must be."""

from __future__ import annotations

import importlib.util
from pathlib import Path

import numpy as np
import pytest

from activebonds import load_model, read_trajectory
from activebonds.data.orientation import guess_ground

ROOT = Path(__file__).resolve().parents[1]
MODEL = ROOT / "src" / "activebonds" / "examples" / "horse_trot_ground.toml"
TROT = ROOT / "src" / "activebonds" / "datasets" / "horse_vhdc" / "Horse1_M1_trot1_kinematics.csv"
_spec = importlib.util.spec_from_file_location("horse_ground", ROOT / "scripts" / "horse_ground.py")
script = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(script)


def test_the_ground_model_follows_every_marker_of_the_recording():
    model = load_model(MODEL)
    traj = read_trajectory(TROT)
    assert sorted(model.markers) == sorted(traj.markers) and len(model.markers) == 7
    assert model.spec.total_mass == 500.0
    assert np.allclose(np.asarray(model.params.mass).sum(), 500.0, rtol=1e-12)


def test_its_ground_is_the_recordings_ground():
    model, traj = load_model(MODEL), read_trajectory(TROT)
    ground = guess_ground(traj)
    contacts = [b for b in model.spec.bond if b.kind == "contact"]
    assert sorted(b.particles[0] for b in contacts) == ["HFL", "HFR", "HHL", "HHR"]
    belt = script.belt_velocity(traj)
    for b in contacts:
        assert np.allclose(b.normal, ground.normal)
        assert b.height.min < ground.plane_height < b.height.max
        assert b.height.value == pytest.approx(ground.plane_height, abs=0.005)
        assert b.surface_velocity == pytest.approx([belt, 0.0, 0.0], abs=0.01)
    assert np.allclose(np.asarray(model.params.gravity), [0.0, 0.0, -9.81])
    assert belt == pytest.approx(-2.88, abs=0.03)  # the treadmill belt, m/s


def test_the_internal_variant_has_only_internal_forces():
    internal = script.models(-2.89)["internal"]
    assert {b.kind for b in internal.spec.bond} == {"binary"}
    assert internal.spec.gravity is None
