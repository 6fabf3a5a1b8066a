"""The bond-kind registry: a kind added from outside the package, and kinds switched off.

``drag`` is a kind defined in this file only (no package file knows it): a unary viscous drag
F_p = -c v_p. Registered for the tests that use it, it is loaded from a model file, checked
against its own NumPy oracle and identified back from simulated data with ``fit``.
"""

from __future__ import annotations

from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import reference_numpy as ref
from activebonds import bonds, fit
from activebonds.bonds.accumulate import accumulate
from activebonds.errors import InputError
from activebonds.model import build, dumps_model, load_model, loads_model
from activebonds.physics import total_force
from activebonds.simulation import simulate

EXAMPLES = Path(__file__).resolve().parents[1] / "src" / "activebonds" / "examples"

# --------------------------------------------------------------------------------------------
# The toy kind: a module's worth of declaration, its oracle, and its registration
# --------------------------------------------------------------------------------------------


def drag_forces(params, topology, x, v):
    idx = topology["particles"][:, 0]
    return accumulate(x.shape[0], [(idx, 1, -params["damping"][:, None] * v[idx])])


DRAG = bonds.BondKind(
    name="drag",
    arity=1,
    parameters=(
        bonds.Parameter(
            "damping", "damping", None, bonds.spread(100, (0.0, 10.0)), check=bonds.NON_NEGATIVE
        ),
    ),
    forces=drag_forces,
    internal=False,  # a drag is an external force: no momentum floor
    what="drags",
)


def drag_oracle(p, t, x, v):
    """F_p = -c v_p, a loop over the drag bonds."""
    f = np.zeros_like(np.asarray(x, np.float64))
    for b, (q,) in enumerate(np.asarray(t["particles"]).reshape(-1, 1)):
        f[q] -= float(p["damping"][b]) * np.asarray(v, np.float64)[q]
    return f


@pytest.fixture
def drag(monkeypatch):
    monkeypatch.setitem(ref.KIND_FORCES, "drag", drag_oracle)
    with bonds.registered(DRAG) as kind:
        yield kind
    assert "drag" not in bonds.names()


DRAG_MODEL = """
name = "dragged"
dimension = 3
gravity = [0.0, 0.0, -9.81]

[[particle]]
name = "a"
mass = 1.0
position = [0.0, 0.0, 1.0]
velocity = [1.5, 0.0, 2.0]

[[particle]]
name = "b"
mass = 2.0
position = [0.6, 0.1, 1.0]
velocity = [-0.5, 1.0, 3.0]

[[bond]]
kind = "binary"
particles = ["a", "b"]
stiffness = 30.0
rest_length = 0.5
damping = 0.2

[[bond]]
kind = "drag"
particles = ["a"]
damping = { value = 0.8, min = 0.01, max = 10.0 }

[[bond]]
kind = "drag"
particles = ["b"]
type = "air"
damping = { value = 2.5, min = 0.01, max = 10.0 }
"""


# --------------------------------------------------------------------------------------------
# The registry
# --------------------------------------------------------------------------------------------


def test_registry_lists_the_kinds_in_order():
    assert bonds.names()[:5] == ("unary", "binary", "ternary", "contact", "periodic")
    assert bonds.get("binary").flags == ("neural",)
    with pytest.raises(ValueError, match="already registered"):
        bonds.register(bonds.get("unary"))


def test_unknown_kind_message_lists_the_registered_kinds(drag):
    text = DRAG_MODEL.replace(
        'kind = "drag"\nparticles = ["a"]', 'kind = "spring"\nparticles = ["a"]'
    )
    with pytest.raises(InputError, match="bond\\[1\\].kind: Input should be 'unary', 'binary', "
                       "'ternary', 'contact', 'periodic' or 'drag'"):  # fmt: skip
        loads_model(text)


def test_a_kind_unknown_once_unregistered():
    with pytest.raises(
        InputError, match="Input should be 'unary', 'binary', 'ternary', 'contact' or 'periodic'"
    ):
        loads_model(DRAG_MODEL)


def test_the_toy_kind_is_checked_like_the_others(drag):
    with pytest.raises(InputError, match="bond\\[1\\].damping: a drag bond needs damping"):
        loads_model(DRAG_MODEL.replace("damping = { value = 0.8, min = 0.01, max = 10.0 }", ""))
    with pytest.raises(InputError, match="bond\\[1\\].damping: must be >= 0, got -1.0"):
        loads_model(DRAG_MODEL.replace("value = 0.8, min = 0.01", "value = -1.0"))
    with pytest.raises(InputError, match="bond\\[1\\].rest_length: not a parameter of a drag"):
        loads_model(
            DRAG_MODEL.replace("value = 0.8,", "value = 0.8 }\nrest_length = { value = 1.0,")
        )
    with pytest.raises(InputError, match="bond\\[1\\].neural: only binary bonds can be neural"):
        loads_model(DRAG_MODEL.replace('particles = ["a"]', 'particles = ["a"]\nneural = true'))


# --------------------------------------------------------------------------------------------
# A kind defined outside the package, end to end
# --------------------------------------------------------------------------------------------


def test_toy_kind_loads_with_its_genes_and_writes_back(drag):
    model = loads_model(DRAG_MODEL)
    assert [g.name for g in model.layout.genes] == ["bond[1].damping", "type:air.damping"]
    assert model.topology.count("drag") == 2
    np.testing.assert_array_equal(model.topology.particles("drag"), [[0], [1]])
    np.testing.assert_array_equal(model.params.bonds["drag"]["damping"], [0.8, 2.5])
    changed = model.with_genome(np.log([1.25, 4.0]))
    again = loads_model(dumps_model(changed))
    np.testing.assert_allclose(again.params.bonds["drag"]["damping"], [1.25, 4.0], rtol=1e-14)


def test_toy_kind_forces_match_its_oracle(drag):
    model = loads_model(DRAG_MODEL)
    rng = np.random.default_rng(3)
    genomes = rng.uniform(model.layout.lower, model.layout.upper, (5, model.layout.n_genes))
    x = rng.normal(0.0, 1.0, (2, 3))
    v = rng.normal(0.0, 1.0, (2, 3))
    batched = jax.jit(jax.vmap(lambda g: total_force(model.layout.decode(g), model.topology, x, v)))
    forces = np.asarray(batched(jnp.asarray(genomes)))
    for g, f in zip(genomes, forces, strict=True):
        params = jax.tree_util.tree_map(np.asarray, model.layout.decode(jnp.asarray(g)))
        expected = ref.total_force(params, model.topology, x, v)
        np.testing.assert_allclose(f, expected, rtol=1e-13, atol=1e-13)
        drag_only = ref.kind_force("drag", params, model.topology, x, v)
        assert np.abs(drag_only).max() > 1e-2  # the drag is part of the comparison


def test_toy_kind_is_identified_by_fit(drag):
    truth = loads_model(DRAG_MODEL)
    data = simulate(truth, n_frames=40, rate=60.0)
    assert np.ptp(data.positions[:, 0, 2]) > 0.1  # it moved
    # start the search away from the truth: the file's values are 1.0 and 1.0
    start = loads_model(DRAG_MODEL.replace("value = 0.8", "value = 1.0").replace("2.5", "1.0"))
    result = fit(start, data, population=24, generations=150, seed=1, refine="none")
    found = result.model.params.bonds["drag"]["damping"]
    np.testing.assert_allclose(found, [0.8, 2.5], rtol=1e-3)


# --------------------------------------------------------------------------------------------
# Switching a kind off (ablations)
# --------------------------------------------------------------------------------------------


def _without_bonds(model, kind):
    bonds_left = [b for b in model.spec.bond if b.kind != kind]
    return build(model.spec.model_copy(update={"bond": bonds_left}))


@pytest.mark.parametrize("kind", ["ternary", "unary", "binary"])
def test_a_disabled_kind_exerts_no_force_and_has_no_genes(kind):
    model = load_model(EXAMPLES / "chain2d.toml")
    off = model.without({kind})
    assert off.disabled == frozenset({kind}) and off.topology.active() == tuple(
        k for k in model.topology.active() if k != kind
    )
    deleted = _without_bonds(model, kind)
    assert off.layout.n_genes == deleted.layout.n_genes < model.layout.n_genes
    assert [g.name for g in off.layout.genes] == [g.name for g in deleted.layout.genes]
    assert off.layout.groups == deleted.layout.groups
    rng = np.random.default_rng(0)
    x = rng.normal(0.0, 1.0, (5, 2))
    v = rng.normal(0.0, 1.0, (5, 2))
    for genome in rng.uniform(off.layout.lower, off.layout.upper, (3, off.layout.n_genes)):
        g = jnp.asarray(genome)
        a = total_force(off.layout.decode(g), off.topology, x, v)
        b = total_force(deleted.layout.decode(g), deleted.topology, x, v)
        np.testing.assert_array_equal(np.asarray(a), np.asarray(b))
        np.testing.assert_allclose(
            np.asarray(a), ref.total_force(off.layout.decode(g), off.topology, x, v), 1e-12, 1e-12
        )


def test_a_disabled_kind_keeps_its_file_values_and_survives_with_genome():
    model = load_model(EXAMPLES / "chain2d.toml")
    off = build(model.spec, disable={"ternary"})
    rng = np.random.default_rng(1)
    changed = off.with_genome(rng.uniform(off.layout.lower, off.layout.upper))
    assert changed.disabled == frozenset({"ternary"})
    ternary = [b for b in model.spec.bond if b.kind == "ternary"]
    assert [b for b in changed.spec.bond if b.kind == "ternary"] == ternary
    assert changed.spec.bond != model.spec.bond  # the others did change
    back = loads_model(dumps_model(changed))
    np.testing.assert_array_equal(
        back.params.bonds["ternary"]["stiffness"], model.params.bonds["ternary"]["stiffness"]
    )
    assert changed.without(set()).layout.n_genes == model.layout.n_genes
    with pytest.raises(ValueError, match="unknown bond kind"):
        build(model.spec, disable={"spring"})
