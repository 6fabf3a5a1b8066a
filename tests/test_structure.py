"""Optional bonds and structure identification (BIC backward elimination on exact least squares)."""

from __future__ import annotations

import tomllib

import numpy as np
import pytest

from activebonds.data.trajectory import Trajectory
from activebonds.data.writers import write_trajectory
from activebonds.errors import InputError
from activebonds.experiments.springs import candidate_model_toml, dataset
from activebonds.experiments.springs_structure import recover_edges
from activebonds.identify.costs.windows import make_windows
from activebonds.identify.discover.structure import identify_structure
from activebonds.model import dumps_model, loads_model
from activebonds.physics import total_force
from helpers import TRIANGLE as TRIANGLE_FILE
from helpers import cli_in_process

# examples/triangle.toml's name, dimension and particles, with two bonds of this file's own
TRIANGLE = (
    TRIANGLE_FILE.read_text().split("[[bond]]")[0]
    + """
[[bond]]
kind = "binary"
particles = ["A", "B"]
stiffness = { value = 40.0, min = 1.0, max = 1000.0 }
rest_length = 0.5
damping = 0.5
[[bond]]
kind = "binary"
particles = ["B", "C"]
stiffness = { value = 60.0, min = 1.0, max = 1000.0 }
rest_length = 0.6
damping = 1.0
"""
)

EXTRA = """
[[bond]]
kind = "binary"
particles = ["A", "C"]
{flags}
stiffness = {{ value = 80.0, min = 1.0, max = 1000.0 }}
rest_length = 0.45
damping = 0.8
"""


def _with_third(flags: str) -> str:
    return TRIANGLE + EXTRA.format(flags=flags)


def test_an_absent_bond_exerts_no_force_and_has_no_genes():
    two = loads_model(TRIANGLE)
    absent = loads_model(_with_third("optional = true\npresent = false"))
    present = loads_model(_with_third("optional = true\npresent = true"))
    assert [g.name for g in absent.layout.genes] == [g.name for g in two.layout.genes]
    assert present.layout.n_genes == two.layout.n_genes + 1
    rng = np.random.default_rng(0)
    for _ in range(20):
        x = rng.normal(0.0, 0.4, (3, 3))
        v = rng.normal(0.0, 1.0, (3, 3))
        a = total_force(absent.layout.decode(absent.layout.initial()), absent.topology, x, v)
        b = total_force(two.layout.decode(two.layout.initial()), two.topology, x, v)
        np.testing.assert_array_equal(np.asarray(a), np.asarray(b))
    # written back as identified: every candidate kept, with its decision
    text = dumps_model(absent)
    bond = tomllib.loads(text)["bond"][2]
    assert bond["optional"] is True and bond["present"] is False
    assert dumps_model(loads_model(text)) == text


@pytest.mark.parametrize(
    "flags, message",
    [
        ("present = true", "present: only an optional bond has a presence"),
        ("optional = true\nneural = true\ngain = 1.0", "a neural bond cannot be optional"),
        ('optional = true\npresent = "yes"', "present: Input should be a valid boolean"),
        ('optional = "yes"', "optional: Input should be a valid boolean"),
    ],
)
def test_bad_presence_is_one_line(flags, message):
    with pytest.raises(InputError) as err:
        loads_model(_with_third(flags), "m.toml")
    assert message in err.value.line()
    assert "\n" not in err.value.line()


def test_a_model_with_neural_bonds_cannot_have_optional_bonds():
    """An absent bond's length would still feed the neurons: refused in one line."""
    text = _with_third("optional = true").replace(
        'particles = ["A", "B"]\n', 'particles = ["A", "B"]\nneural = true\ngain = 1.0\n', 1
    )
    with pytest.raises(InputError) as err:
        loads_model(text, "m.toml")
    assert (
        "bond[2].optional: a model with neural bonds cannot have optional bonds" in err.value.line()
    )


def test_a_contact_cannot_be_optional(tmp_path):
    text = (
        TRIANGLE
        + """
[[bond]]
kind = "contact"
particles = ["A"]
optional = true
normal = [0.0, 0.0, 1.0]
stiffness = 1e4
"""
    )
    path = tmp_path / "m.toml"
    path.write_text(text)
    r = cli_in_process("structure", path, tmp_path / "none.csv", "--out", tmp_path / "o.toml")
    assert r.returncode == 2
    assert "optional: a contact bond cannot be optional" in r.stderr
    assert len(r.stderr.strip().splitlines()) == 1
    assert not (tmp_path / "o.toml").exists()


def _springs_windows(x):
    mask = np.ones(x.shape[:2], bool)
    return make_windows(x, mask, 0.1, 1)


def test_noiseless_springs_every_edge_right():
    """NRI springs, no noise: every pair decided right, stiffness 0.1 within 0.5 %."""
    for x, edges in dataset(8, seed=11):
        r = recover_edges(x, edges)
        assert r.found == r.truth, (r.found, r.truth)
        assert all(abs(k - 0.1) < 5e-4 for k in r.stiffness), r.stiffness


def test_smoothing_recovers_every_edge_with_noise():
    """NRI springs with observation noise 0.01 (a spring moves a particle 1e-3 per frame,
    the noise's second difference is 0.025): raw, no spring is seen; smoothed over 31
    frames (structure --smooth 31), every pair of 6 trajectories is decided right, and the
    identified model predicts below the zero-force baseline."""
    from activebonds.data.smoothing import smooth_positions

    for x, edges in dataset(6, seed=21, noise=0.01):
        assert sum(recover_edges(x, edges).found) == 0
        r = recover_edges(x, edges, smooth=31)
        assert r.found == r.truth, (r.found, r.truth)
        assert all(abs(k - 0.1) < 0.04 for k in r.stiffness), r.stiffness  # within 40 %
    smooth = smooth_positions(x, np.ones(x.shape[:2], bool), 31)
    found = identify_structure(loads_model(candidate_model_toml()), _springs_windows(smooth))
    assert found.rms_mm < found.zero_force_rms_mm


def test_evidence_agrees_with_the_decisions():
    x, edges = dataset(1, seed=3)[0]
    model = loads_model(candidate_model_toml())
    result = identify_structure(model, _springs_windows(x))
    for d in result.decisions:
        assert (d.delta_bic > 0) == d.present
        if d.present:  # a true spring: the fit is far worse without it
            assert d.cost_change > 1e3
    assert result.rms_mm >= result.full_rms_mm
    ident = loads_model(dumps_model(result.spec))
    assert sum(b.present for b in ident.spec.bond) == sum(d.present for d in result.decisions)


def _springs_file(path, seed: int = 3):
    """One NRI springs trajectory (markers p0..p4, 10 Hz) written to ``path``; its edges."""
    x, edges = dataset(1, seed=seed)[0]
    markers = tuple(f"p{i}" for i in range(5))
    write_trajectory(Trajectory(x, np.ones(x.shape[:2], bool), markers, 10.0), path)
    return edges


def test_structure_errors_name_the_model_file(tmp_path):
    _springs_file(tmp_path / "s.npz")
    model = tmp_path / "plain.toml"
    model.write_text(candidate_model_toml().replace("optional = true\n", ""))
    r = cli_in_process("structure", model, tmp_path / "s.npz", "--out", tmp_path / "o.toml")
    assert r.returncode == 2
    assert (
        r.stderr.strip()
        == f"error: {model}: no bond is optional (add optional = true to candidates)"
    )
    assert not (tmp_path / "o.toml").exists()


def test_no_optional_bond_is_refused():
    model = loads_model(TRIANGLE)
    with pytest.raises(InputError, match="no bond is optional"):
        identify_structure(model, _springs_windows(np.zeros((5, 3, 3))))


@pytest.mark.slow  # integration scale: in `pytest -m slow` (every landing)
def test_structure_command(tmp_path):
    edges = _springs_file(tmp_path / "s.npz")
    (tmp_path / "m.toml").write_text(candidate_model_toml())
    out = tmp_path / "found.toml"
    r = cli_in_process("structure", tmp_path / "m.toml", tmp_path / "s.npz", "--out", out)
    assert r.returncode == 0, r.stderr
    found = loads_model(out.read_text())
    for b in found.spec.bond:
        i, j = (int(p[1:]) for p in b.particles)
        assert b.present == bool(edges[i, j])
    again = cli_in_process("structure", tmp_path / "m.toml", tmp_path / "s.npz", "--out", out)
    assert again.returncode == 2 and "exists" in again.stderr
    # fit takes the identified model (absent bonds carry no genes) and, on the undecided
    # candidates, says they were fitted as present
    run = cli_in_process("fit", out, tmp_path / "s.npz", "--population", "8", "--generations", "2",
              "--refine", "none", "--out", tmp_path / "run")  # fmt: skip
    assert run.returncode == 0, run.stderr
    assert "optional bond" not in run.stdout
    genes = sum(bool(edges[i, j]) for i in range(5) for j in range(i + 1, 5))
    rows = (tmp_path / "run" / "uncertainty.csv").read_text().strip().splitlines()
    assert len(rows) == 1 + genes
    run = cli_in_process("fit", tmp_path / "m.toml", tmp_path / "s.npz", "--population", "8",
              "--generations", "2", "--refine", "none", "--out", tmp_path / "run2")  # fmt: skip
    assert run.returncode == 0, run.stderr
    assert "note: 10 optional bond(s) without a decision were fitted as present" in run.stdout
