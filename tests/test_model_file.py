"""The model file: round trips through TOML and every error path of the loader."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from activebonds.errors import InputError
from activebonds.model import dumps_model, load_model, loads_model, save_model

EXAMPLES = Path(__file__).resolve().parents[1] / "examples"
EXAMPLE_NAMES = ["triangle", "horse_limb", "chain2d"]


def leaves(params) -> dict:
    """'mass', 'binary.stiffness', ... -> array."""
    flat, _ = jax.tree_util.tree_flatten_with_path(params)
    return {jax.tree_util.keystr(path): leaf for path, leaf in flat}


def assert_params_equal(a, b):
    a, b = leaves(a), leaves(b)
    assert a.keys() == b.keys()
    for name in a:
        np.testing.assert_array_equal(np.asarray(a[name]), np.asarray(b[name]), err_msg=name)


def assert_same_model(a, b):
    assert a.spec == b.spec
    assert_params_equal(a.params, b.params)
    assert a.topology.bonds.keys() == b.topology.bonds.keys()
    for kind, arrays in a.topology.bonds.items():
        assert arrays.keys() == b.topology.bonds[kind].keys()
        for name, x in arrays.items():
            np.testing.assert_array_equal(x, b.topology.bonds[kind][name])
    assert a.layout.genes == b.layout.genes
    assert a.layout.groups == b.layout.groups
    assert_params_equal(a.layout.index, b.layout.index)
    for x, y in zip(a.initial_state(), b.initial_state(), strict=True):
        np.testing.assert_array_equal(x, y)


# --------------------------------------------------------------------------------------------
# Round trips
# --------------------------------------------------------------------------------------------


@pytest.mark.parametrize("name", EXAMPLE_NAMES)
def test_example_load_dump_load(name):
    model = load_model(EXAMPLES / f"{name}.toml")
    assert model.name == name
    text = dumps_model(model)
    again = loads_model(text, "<dumped>")
    assert_same_model(model, again)
    assert dumps_model(again) == text  # the dump is a fixed point after one round


@pytest.mark.parametrize("name", EXAMPLE_NAMES)
def test_example_save_load(name, tmp_path):
    model = load_model(EXAMPLES / f"{name}.toml")
    path = tmp_path / f"{name}.toml"
    save_model(model, path)
    assert_same_model(model, load_model(path))
    assert [p.name for p in tmp_path.iterdir()] == [path.name]  # no temporary file left


def test_example_shapes():
    """What the examples contain, so a broken loader cannot pass the round trips vacuously."""
    tri = load_model(EXAMPLES / "triangle.toml")
    assert (tri.dimension, tri.topology.n_particles, tri.topology.count("binary")) == (3, 3, 3)
    np.testing.assert_array_equal(tri.params.mass, [1.0, 1.5, 2.0])
    binary = tri.params.bonds["binary"]
    np.testing.assert_array_equal(binary["stiffness"], [40.0, 60.0, 80.0])
    np.testing.assert_array_equal(binary["rest_length"], [0.5, 0.6, 0.45])
    np.testing.assert_array_equal(binary["damping"], [0.5, 1.0, 0.8])
    assert tri.layout.n_genes == 9
    horse = load_model(EXAMPLES / "horse_limb.toml")
    assert horse.topology.bonds["binary"]["neural"].all() and horse.markers == (
        "Head",
        "Withers",
        "HFL",
    )
    assert horse.layout.n_genes == 3 * (5 + 4)  # k, l0, c, gain, threshold + 2x2 weights
    chain = load_model(EXAMPLES / "chain2d.toml")
    assert chain.dimension == 2 and chain.topology.count("ternary") == 3
    np.testing.assert_array_equal(chain.params.gravity, [0.0, -9.81])
    np.testing.assert_array_equal(
        chain.topology.particles("binary"), [[0, 1], [1, 2], [2, 3], [3, 4]]
    )
    # the four "link" bonds share one set of genes, the three "joint" bonds another
    assert chain.layout.n_genes == 2 + 3 + 1


@pytest.mark.parametrize("seed", [0, 1])
@pytest.mark.parametrize("name", EXAMPLE_NAMES)
def test_with_genome_dump_load_keeps_values(name, seed):
    model = load_model(EXAMPLES / f"{name}.toml")
    layout = model.layout
    rng = np.random.default_rng(seed)
    genome = rng.uniform(layout.lower, layout.upper)
    changed = model.with_genome(genome)
    decoded = layout.decode(jnp.asarray(genome))
    # the new model's values are the genome's (up to exp/log rounding of log-scaled genes) ...
    new, dec = leaves(changed.params), leaves(decoded)
    assert new.keys() == dec.keys()
    for field in new:
        np.testing.assert_allclose(new[field], np.asarray(dec[field]), 1e-14, 0, err_msg=field)
    np.testing.assert_allclose(changed.layout.initial(), genome, rtol=1e-13, atol=1e-15)
    assert [(g.name, g.lower, g.upper, g.log) for g in changed.layout.genes] == [
        (g.name, g.lower, g.upper, g.log) for g in layout.genes
    ]
    # ... and survive a dump and load exactly
    again = loads_model(dumps_model(changed), "<dumped>")
    assert_same_model(changed, again)
    assert not np.array_equal(
        changed.params.bonds["binary"]["stiffness"], model.params.bonds["binary"]["stiffness"]
    )


def test_with_genome_weights_become_per_bond_lists():
    model = load_model(EXAMPLES / "horse_limb.toml")
    genome = np.linspace(-1.0, 1.0, model.layout.n_genes) + model.layout.initial()
    genome = np.clip(genome, model.layout.lower, model.layout.upper)
    changed = loads_model(dumps_model(model.with_genome(genome)))
    decoded = model.layout.decode(jnp.asarray(genome))
    new, dec = changed.params.bonds["binary"], decoded.bonds["binary"]
    for b in range(3):
        np.testing.assert_allclose(
            new["length_weights"][b], np.asarray(dec["length_weights"][b]), 1e-14
        )
        assert new["length_weights"][b, b] == 0.0 and new["rate_weights"][b, b] == 0.0
        assert isinstance(changed.spec.bond[b].weights.length, list)


ANCHORED = """
dimension = 2
[[particle]]
name = "a"
mass = 1.0
[[bond]]
kind = "unary"
particles = ["a"]
stiffness = 3.0
anchor = { value = [0.5, 0.5], min = [-0.00107999, 0.0], max = [1.0, 1.0] }
"""


def test_a_vector_rounded_past_its_bound_is_written_within_it():
    """A solver's value a rounding below an anchor's min (as a least-squares optimum at its
    bound can be) is written at the bound, so the file loads again."""
    model = loads_model(ANCHORED)
    below = np.nextafter(-0.00107999, -1.0)
    genome = model.layout.initial()
    genome[0] = below
    changed = model.with_genome(genome)
    assert changed.spec.bond[0].anchor.value == [-0.00107999, 0.5]
    again = loads_model(dumps_model(changed), "<dumped>")
    assert again.spec.bond[0].anchor.value == [-0.00107999, 0.5]


MODEL_WITHOUT_FREE_PARAMETERS = """
dimension = 2
[[particle]]
name = "a"
position = [0.0, 0.0]
[[particle]]
name = "b"
position = [1.0, 0.0]
[[bond]]
kind = "binary"
particles = ["a", "b"]
stiffness = 3.0
rest_length = 1.0
"""


def test_with_genome_on_a_model_without_free_parameters():
    model = loads_model(MODEL_WITHOUT_FREE_PARAMETERS)
    assert model.layout.n_genes == 0
    same = model.with_genome(np.zeros(0))
    assert_params_equal(same.params, model.params)


# --------------------------------------------------------------------------------------------
# Error paths: one line, naming the file and the field
# --------------------------------------------------------------------------------------------

H_WEIGHTS = "weights = { length = 0.0, rate = 0.0, min = -10.0, max = 10.0 }"
T_STIFFNESS = "stiffness = { value = 40.0, min = 1.0, max = 1000.0 }"


@dataclass(frozen=True)
class Case:
    id: str
    example: str  # file to mutate; "<bytes>" (non-UTF-8) or "<missing>" for no file
    old: str
    new: str
    owner: str  # what the message must name now (the field or its bond/particle)
    field: str  # the exact field path a good message names ("{line}": the line of `new`)
    keyword: str  # the problem, in the message's words


CASES = [
    Case(
        "unknown top-level key",
        "triangle",
        'name = "triangle"\n',
        'name = "triangle"\ncolour = "red"\n',
        "colour",
        "colour",
        "unknown key",
    ),
    Case(
        "unknown bond key",
        "triangle",
        'particles = ["A", "B"]\n',
        'particles = ["A", "B"]\nspring = 3.0\n',
        "bond[0].spring",
        "bond[0].spring",
        "unknown key",
    ),
    Case(
        "unknown key in a parameter table",
        "triangle",
        "value = 40.0,",
        "value = 40.0, step = 2.0,",
        "bond[0].stiffness",
        "bond[0].stiffness.step",
        "unknown key",
    ),
    Case(
        "unknown particle in a bond",
        "triangle",
        'particles = ["A", "B"]',
        'particles = ["A", "Z"]',
        "bond[0]",
        "bond[0].particles",
        "'Z'",
    ),
    Case(
        "duplicate particle names",
        "triangle",
        'name = "C"',
        'name = "B"',
        "particle[2]",
        "particle[2].name",
        "duplicate",
    ),
    Case(
        "duplicate markers",
        "horse_limb",
        'marker = "HFL"',
        'marker = "Head"',
        "",
        "particle[2].marker",
        "marker",
    ),
    Case(
        "nan parameter value",
        "triangle",
        "value = 40.0",
        "value = nan",
        "bond[0].stiffness",
        "bond[0].stiffness.value",
        "finite",
    ),
    Case(
        "-inf parameter bound",
        "triangle",
        "value = 40.0, min = 1.0",
        "value = 40.0, min = -inf",
        "bond[0].stiffness",
        "bond[0].stiffness.min",
        "finite",
    ),
    Case(
        "nan plain stiffness",
        "triangle",
        T_STIFFNESS,
        "stiffness = nan",
        "bond[0].stiffness",
        "bond[0].stiffness",
        "finite",
    ),
    Case(
        "inf plain rest_length",
        "triangle",
        "rest_length = { value = 0.5, min = 0.25, max = 0.75 }",
        "rest_length = inf",
        "bond[0].rest_length",
        "bond[0].rest_length",
        "finite",
    ),
    Case(
        "inf plain damping",
        "triangle",
        "damping = { value = 0.5, min = 0.01, max = 10.0 }",
        "damping = inf",
        "bond[0].damping",
        "bond[0].damping",
        "finite",
    ),
    Case(
        "nan plain threshold",
        "horse_limb",
        "threshold = { value = 0.0, min = -5.0, max = 5.0 }",
        "threshold = nan",
        "bond[0].threshold",
        "bond[0].threshold",
        "finite",
    ),
    Case(
        "inf mass",
        "triangle",
        "mass = 1.5",
        "mass = inf",
        "particle[1].mass",
        "particle[1].mass",
        "finite",
    ),
    Case(
        "nan position",
        "triangle",
        "[0.55, 0.0, 0.05]",
        "[nan, 0.0, 0.05]",
        "particle[1].position",
        "particle[1].position",
        "finite",
    ),
    Case(
        "nan gravity",
        "triangle",
        "dimension = 3\n",
        "dimension = 3\ngravity = [0.0, nan, 0.0]\n",
        "gravity",
        "gravity",
        "finite",
    ),
    Case(
        "nan anchor",
        "chain2d",
        "anchor = [0.0, 0.0]",
        "anchor = [nan, 0.0]",
        "bond[0].anchor",
        "bond[0].anchor",
        "finite",
    ),
    Case(
        "inf anchor bound",
        "chain2d",
        "anchor = [0.0, 0.0]",
        "anchor = { value = [0.0, 0.0], min = -inf, max = 1.0 }",
        "bond[0].anchor",
        "bond[0].anchor.min",
        "finite",
    ),
    Case(
        "nan weight",
        "horse_limb",
        H_WEIGHTS,
        "weights = { length = nan, rate = 0.0 }",
        "bond[0].weights",
        "bond[0].weights.length",
        "finite",
    ),
    Case(
        "inf weight bound",
        "horse_limb",
        H_WEIGHTS,
        "weights = { length = 0.0, rate = 0.0, min = -inf }",
        "bond[0].weights",
        "bond[0].weights.min",
        "finite",
    ),
    Case(
        "negative mass",
        "triangle",
        "mass = 1.5",
        "mass = -1.5",
        "particle[1].mass",
        "particle[1].mass",
        "> 0",
    ),
    Case(
        "zero mass",
        "triangle",
        "mass = 1.5",
        "mass = 0.0",
        "particle[1].mass",
        "particle[1].mass",
        "> 0",
    ),
    Case(
        "min >= max",
        "triangle",
        "min = 1.0, max = 1000.0",
        "min = 1000.0, max = 1.0",
        "bond[0].stiffness",
        "bond[0].stiffness",
        "must be below max",
    ),
    Case(
        "min >= max in weights",
        "horse_limb",
        H_WEIGHTS,
        "weights = { length = 0.0, rate = 0.0, min = 10.0, max = -10.0 }",
        "bond[0].weights",
        "bond[0].weights",
        "must be below max",
    ),
    Case(
        "min >= max in an anchor",
        "chain2d",
        "anchor = [0.0, 0.0]",
        "anchor = { value = [0.0, 0.0], min = 1.0, max = -1.0 }",
        "bond[0].anchor",
        "bond[0].anchor",
        "must be below max",
    ),
    Case(
        "value above max",
        "triangle",
        "value = 40.0",
        "value = 4000.0",
        "bond[0].stiffness",
        "bond[0].stiffness",
        "above max",
    ),
    Case(
        "value below min",
        "triangle",
        "mass = 1.5",
        "mass = { value = 0.5, min = 1.0, max = 2.0 }",
        "particle[1].mass",
        "particle[1].mass",
        "below min",
    ),
    Case(
        "weight outside bounds",
        "horse_limb",
        H_WEIGHTS,
        "weights = { length = 20.0, rate = 0.0, min = -10.0, max = 10.0 }",
        "bond[0].weights",
        "bond[0].weights.length",
        "outside",
    ),
    Case(
        "anchor outside bounds",
        "chain2d",
        "anchor = [0.0, 0.0]",
        "anchor = { value = [5.0, 0.0], min = -1.0, max = 1.0 }",
        "bond[0].anchor",
        "bond[0].anchor",
        "above max",
    ),
    Case(
        "gravity of the wrong length",
        "triangle",
        "dimension = 3\n",
        "dimension = 3\ngravity = [0.0, -9.81]\n",
        "gravity",
        "gravity",
        "expected 3 components",
    ),
    Case(
        "anchor of the wrong length",
        "chain2d",
        "anchor = [0.0, 0.0]",
        "anchor = [0.0, 0.0, 0.0]",
        "bond[0].anchor",
        "bond[0].anchor",
        "expected 2 components",
    ),
    Case(
        "position of the wrong length",
        "triangle",
        "[0.55, 0.0, 0.05]",
        "[0.55, 0.0]",
        "particle[1].position",
        "particle[1].position",
        "expected 3 components",
    ),
    Case(
        "velocity of the wrong length",
        "triangle",
        "velocity = [0.0, -0.2, 0.0]",
        "velocity = [0.0, -0.2]",
        "particle[1].velocity",
        "particle[1].velocity",
        "expected 3 components",
    ),
    Case(
        "ternary bond with a repeated particle",
        "chain2d",
        'particles = ["p1", "p2", "p3"]',
        'particles = ["p1", "p2", "p1"]',
        "bond[6]",
        "bond[6].particles",
        "distinct",
    ),
    Case(
        "binary bond with three particles",
        "triangle",
        'particles = ["B", "C"]',
        'particles = ["A", "B", "C"]',
        "bond[1]",
        "bond[1].particles",
        "got 3",
    ),
    Case(
        "neural ternary bond",
        "chain2d",
        'particles = ["p1", "p2", "p3"]\n',
        'particles = ["p1", "p2", "p3"]\nneural = true\n',
        "bond[6]",
        "bond[6].neural",
        "only binary bonds",
    ),
    Case(
        "gain without neural",
        "triangle",
        'particles = ["B", "C"]\n',
        'particles = ["B", "C"]\ngain = 2.0\n',
        "bond[1]",
        "bond[1].gain",
        "neural = true",
    ),
    Case(
        "weights list of the wrong length",
        "horse_limb",
        H_WEIGHTS,
        "weights = { length = [0.0, 1.0], rate = 0.0 }",
        "bond[0].weights.length",
        "bond[0].weights.length",
        "expected 3 entries",
    ),
    Case(
        "rate list of the wrong length",
        "horse_limb",
        H_WEIGHTS,
        "weights = { length = 0.0, rate = [0.0, 1.0, 2.0, 3.0] }",
        "bond[0].weights.rate",
        "bond[0].weights.rate",
        "expected 3 entries",
    ),
    Case(
        "binary bond without rest_length",
        "triangle",
        "rest_length = { value = 0.5, min = 0.25, max = 0.75 }\n",
        "",
        "bond[0]",
        "bond[0].rest_length",
        "needs rest_length",
    ),
    Case(
        "unknown bond kind",
        "triangle",
        'kind = "binary"\nparticles = ["A", "B"]',
        'kind = "spring"\nparticles = ["A", "B"]',
        "bond[0].kind",
        "bond[0].kind",
        "'unary', 'binary', 'ternary', 'contact' or 'periodic'",
    ),
    Case(
        "invalid TOML syntax",
        "triangle",
        "mass = 1.5",
        "mass = = 1.5",
        "line {line}",
        "line {line}",
        "not valid TOML",
    ),
    Case("non-UTF-8 bytes", "<bytes>", "", "", "", "", "UTF-8"),
    Case("missing file", "<missing>", "", "", "", "", "no such model file"),
    Case(
        "dimension 4",
        "triangle",
        "dimension = 3",
        "dimension = 4",
        "dimension",
        "dimension",
        "2 or 3",
    ),
]


def write_case(case: Case, tmp_path: Path) -> tuple[Path, int]:
    path = tmp_path / "model.toml"
    if case.example == "<bytes>":
        path.write_bytes(b'name = "caf\xe9"\ndimension = 3\n')
        return path, 0
    if case.example == "<missing>":
        return path, 0
    text = (EXAMPLES / f"{case.example}.toml").read_text(encoding="utf-8")
    assert text.count(case.old) >= 1, f"mutation of {case.id} no longer applies"
    start = text.index(case.old)
    text = text.replace(case.old, case.new, 1)
    path.write_text(text, encoding="utf-8")
    return path, text[:start].count("\n") + 1


def load_error(case: Case, tmp_path: Path) -> tuple[str, int, Path]:
    path, line = write_case(case, tmp_path)
    with pytest.raises(InputError) as info:
        load_model(path)
    return str(info.value), line, path


@pytest.mark.parametrize("case", [pytest.param(c, id=c.id) for c in CASES])
def test_model_error_is_one_line_naming_file_and_place(case, tmp_path):
    message, line, path = load_error(case, tmp_path)
    assert "\n" not in message and "\r" not in message
    assert message.startswith(f"{path}: ")
    assert case.owner.format(line=line) in message


@pytest.mark.parametrize("case", [pytest.param(c, id=c.id) for c in CASES])
def test_model_error_names_field_and_problem(case, tmp_path):
    message, line, path = load_error(case, tmp_path)
    assert case.field.format(line=line) in message
    assert case.keyword in message
    assert "Input should be a valid number" not in message
    assert "Input should be a valid list" not in message


def test_model_error_for_a_toml_overflow(tmp_path):
    """1e400 parses as inf in TOML: it must be reported as a non-finite bound."""
    text = (EXAMPLES / "triangle.toml").read_text()
    path = tmp_path / "overflow.toml"
    path.write_text(text.replace("max = 1000.0", "max = 1e400"))
    with pytest.raises(InputError) as info:
        load_model(path)
    message = str(info.value)
    assert "\n" not in message and message.startswith(str(path))
    assert "bond[0].stiffness.max: value must be a finite number, got inf" in message


def test_loads_model_names_its_source():
    with pytest.raises(InputError) as info:
        loads_model("dimension = 3\n", "inline.toml")
    assert str(info.value) == "inline.toml: particle: required key is missing"


def test_model_error_is_not_swallowed_for_a_directory(tmp_path):
    with pytest.raises(InputError) as info:
        load_model(tmp_path)
    assert str(info.value).startswith(str(tmp_path)) and "\n" not in str(info.value)
