"""Genes are structured: owner, kind, bonds, key, part and axis are fields, the name a derived
key equal to the historical strings; each parameter form writes its values back; no module
decodes a gene name with a regular expression."""

from __future__ import annotations

import dataclasses
import pathlib

import numpy as np
import pytest

import activebonds
from activebonds import bonds
from activebonds.identify.solvers.lsq import nonlinear_genes
from activebonds.model import Gene, loads_model
from activebonds.model.forms import FORMS, form_of
from activebonds.model.model import spec_with_params, with_values
from activebonds.model.names import parameter_label, parameter_labels

EVERYTHING = """
name = "everything"
dimension = 3
gravity = { value = 9.81, min = 5.0, max = 15.0, direction = [0.0, 0.0, -1.0] }

[drive]
frequency = { value = 1.5, min = 0.5, max = 3.0 }

[[particle]]
name = "A"
mass = { value = 1.0, min = 0.5, max = 2.0 }

[[particle]]
name = "B"
mass = 1.5

[[particle]]
name = "C"
mass = 2.0

[[particle]]
name = "D"
mass = 0.5

[[bond]]
kind = "binary"
particles = ["A", "B"]
stiffness = { value = 40.0, min = 1.0, max = 1000.0 }
rest_length = 0.5
damping = { value = 0.5, min = 0.01, max = 10.0 }

[[bond]]
kind = "binary"
particles = ["B", "C"]
neural = true
stiffness = 60.0
rest_length = 0.6
gain = { value = 5.0, min = 0.0, max = 100.0 }
weights = { length = [0.5, 0.0, -0.5, 0.25], rate = [0.0, 0.0, 0.1, 0.0], min = -10.0, max = 10.0 }
drive_weight = { value = 0.5, min = -5.0, max = 5.0 }
drive_phase = 0.25

[[bond]]
kind = "binary"
particles = ["A", "C"]
type = "diagonal"
stiffness = { value = 80.0, min = 1.0, max = 1000.0 }
rest_length = 0.45

[[bond]]
kind = "binary"
particles = ["B", "D"]
type = "diagonal"
stiffness = { value = 80.0, min = 1.0, max = 1000.0 }
rest_length = 0.55

[[bond]]
kind = "unary"
particles = ["C"]
stiffness = 5.0
anchor = { value = [0.0, 0.1, 0.2], min = -1.0, max = 1.0 }

[[bond]]
kind = "ternary"
particles = ["A", "B", "C"]
stiffness = { value = 3.0, min = 0.1, max = 30.0 }
rest_angle = 2.0

[[bond]]
kind = "contact"
particles = ["D"]
normal = [0.0, 0.0, 2.0]
stiffness = { value = 1e4, min = 1e2, max = 1e6 }
friction = { value = 0.8, min = 0.0, max = 2.0 }
surface_velocity = { value = [0.1, 0.0, 0.0], min = -1.0, max = 1.0 }

[[bond]]
kind = "periodic"
particles = ["A"]
sin2 = { value = [0.0, 1.0, 0.0], min = -5.0, max = 5.0 }
"""

# name, then the fields: owner, kind, bonds, key, part, axis, source, particle, type
B = "binary"
EXPECTED = [
    ("mass:A.mass", "mass", None, (), "mass", None, None, None, "A", None),
    ("gravity.magnitude", "gravity", None, (), "magnitude", None, None, None, None, None),
    # shared by the neural bond and the periodic force (bond 7)
    ("drive.frequency", "shared", B, (1, 7), "drive.frequency", None, None, None, None, None),
    ("bond[0].stiffness", "bond", B, (0,), "stiffness", None, None, None, None, None),
    ("bond[0].damping", "bond", B, (0,), "damping", None, None, None, None, None),
    ("bond[1].gain", "bond", B, (1,), "gain", None, None, None, None, None),
    ("bond[1].weights.length[0]", "bond", B, (1,), "weights", "length", None, 0, None, None),
    ("bond[1].weights.length[2]", "bond", B, (1,), "weights", "length", None, 2, None, None),
    ("bond[1].weights.length[3]", "bond", B, (1,), "weights", "length", None, 3, None, None),
    ("bond[1].weights.rate[0]", "bond", B, (1,), "weights", "rate", None, 0, None, None),
    ("bond[1].weights.rate[2]", "bond", B, (1,), "weights", "rate", None, 2, None, None),
    ("bond[1].weights.rate[3]", "bond", B, (1,), "weights", "rate", None, 3, None, None),
    ("bond[1].drive_weight", "bond", B, (1,), "drive_weight", None, None, None, None, None),
    ("type:diagonal.stiffness", "bond", B, (2, 3), "stiffness", None, None, None, None, "diagonal"),
    ("bond[4].anchor[0]", "bond", "unary", (4,), "anchor", None, 0, None, None, None),
    ("bond[4].anchor[1]", "bond", "unary", (4,), "anchor", None, 1, None, None, None),
    ("bond[4].anchor[2]", "bond", "unary", (4,), "anchor", None, 2, None, None, None),
    ("bond[5].stiffness", "bond", "ternary", (5,), "stiffness", None, None, None, None, None),
    ("bond[6].stiffness", "bond", "contact", (6,), "stiffness", None, None, None, None, None),
    ("bond[6].friction", "bond", "contact", (6,), "friction", None, None, None, None, None),
    (
        "bond[6].surface_velocity[0]",
        "bond",
        "contact",
        (6,),
        "surface_velocity",
        None,
        0,
        None,
        None,
        None,
    ),  # fmt: skip
    (
        "bond[6].surface_velocity[1]",
        "bond",
        "contact",
        (6,),
        "surface_velocity",
        None,
        1,
        None,
        None,
        None,
    ),  # fmt: skip
    (
        "bond[6].surface_velocity[2]",
        "bond",
        "contact",
        (6,),
        "surface_velocity",
        None,
        2,
        None,
        None,
        None,
    ),  # fmt: skip
    ("bond[7].sin2[0]", "bond", "periodic", (7,), "sin2", None, 0, None, None, None),
    ("bond[7].sin2[1]", "bond", "periodic", (7,), "sin2", None, 1, None, None, None),
    ("bond[7].sin2[2]", "bond", "periodic", (7,), "sin2", None, 2, None, None, None),
]
FIELDS = ("owner", "kind", "bonds", "key", "part", "axis", "source", "particle", "type")


def test_every_gene_knows_its_owner_bonds_key_and_part_and_its_name_is_derived():
    model = loads_model(EVERYTHING)
    genes = model.layout.genes
    assert {g.kind for g in genes} >= set(bonds.names())  # every kind has genes here
    got = [(g.name, *(getattr(g, f) for f in FIELDS)) for g in genes]
    assert got == EXPECTED
    for g in genes:  # the name is a property of the fields, not a stored string
        assert "name" not in {f.name for f in dataclasses.fields(Gene)}
        assert dataclasses.replace(g, lower=-1.0, value=7.0).name == g.name
    # a gene's field is its array in params.bonds[kind]; its indices point back at it
    index = model.layout.index
    for i, g in enumerate(genes):
        if g.owner in ("bond", "shared"):
            assert (np.asarray(index.bonds[g.kind][g.field]) == i).any()
    assert [g.field for g in genes if g.part] == ["length_weights"] * 3 + ["rate_weights"] * 3
    # groups as before: one per bond (or type), mass and the field
    assert model.layout.groups == (
        "mass:A",
        "gravity",
        "drive",
        "bond[0]",
        "bond[1]",
        "type:diagonal",
        "bond[4]",
        "bond[5]",
        "bond[6]",
        "bond[7]",
    )
    assert [model.layout.groups[g.group] for g in genes] == [g.group_name for g in genes]


def test_labels_read_the_fields_and_match_the_names():
    model = loads_model(EVERYTHING)
    labels = parameter_labels(model)
    assert labels[:4] == [
        "particle A mass",
        "gravity magnitude",
        "drive frequency",
        "spring A-B stiffness",
    ]
    assert labels[8] == "neural B-C length weight from B-D"
    assert labels[13] == "spring type diagonal stiffness"
    assert labels[-4] == "contact D surface_velocity z"
    assert labels[-1] == "periodic force A sin2 z"
    # the same words from the machine key alone (names stored in files)
    assert [parameter_label(model.spec, g.name) for g in model.layout.genes] == labels
    assert parameter_label(model.spec, "bond[1].weights") == "neural B-C weights"


def test_total_mass_makes_the_mass_genes_weights():
    text = EVERYTHING.replace('name = "everything"', 'name = "w"\ntotal_mass = 5.0')
    genes = loads_model(text).layout.genes
    assert genes[0].name == "mass:A.weight" and (genes[0].owner, genes[0].key) == ("mass", "weight")


def test_writing_values_back_round_trips_the_parameters():
    model = loads_model(EVERYTHING)
    layout = model.layout
    lo, hi = layout.lower, layout.upper
    genome = lo + (hi - lo) * np.linspace(0.2, 0.8, layout.n_genes)
    natural = layout.natural(genome)
    decoded = layout.decode(genome)
    again = build_from(with_values(model, natural), model)
    np.testing.assert_allclose([g.value for g in again.layout.genes], natural, rtol=1e-12)
    for name in ("mass", "gravity"):
        np.testing.assert_allclose(getattr(again.params, name), getattr(decoded, name), rtol=1e-6)
    for kind, fields in decoded.bonds.items():
        for field, values in fields.items():
            np.testing.assert_allclose(
                again.params.bonds[kind][field], values, rtol=1e-6, err_msg=f"{kind}.{field}"
            )
    # the file's own numbers round-trip exactly, through every form (the constant as given)
    same = spec_with_params(model.spec, model.params)
    assert same == model.spec
    assert same.bond[6].normal == [0.0, 0.0, 2.0]
    assert np.array_equal(model.params.bonds["contact"]["normal"][0], [0.0, 0.0, 1.0])


def build_from(spec, model):
    from activebonds.model import build

    return build(spec, disable=model.disabled)


def test_each_form_knows_its_shape_and_schema_type():
    shapes = {name: form.shape(4, 3) for name, form in FORMS.items()}
    assert shapes == {"scalar": (4,), "vector": (4, 3), "weights": (4, 4), "constant": (4, 3)}
    for kind in bonds.kinds():
        for par in kind.parameters:
            assert form_of(par) is FORMS[par.form]
    weights = next(p for p in bonds.get("binary").parameters if p.form == "weights")
    assert [g["source"] for g in form_of(weights).genes(weights, 3, 3)] == [0, 1, 2]
    assert FORMS["constant"].genes(weights, 3, 3) == []  # never a gene


def test_least_squares_asks_the_kinds_which_genes_are_linear():
    model = loads_model(EVERYTHING)
    names = [model.layout.genes[g].name for g in nonlinear_genes(model)]
    linear = {"gravity.magnitude", "bond[0].stiffness", "bond[0].damping"}
    linear |= {"type:diagonal.stiffness"} | {f"bond[4].anchor[{a}]" for a in range(3)}
    linear |= {f"bond[7].sin2[{a}]" for a in range(3)}  # a periodic force's coefficients
    assert set(names) == {g.name for g in model.layout.genes} - linear


SOURCE = pathlib.Path(activebonds.__file__).parent
NAME_READERS = [
    "model/genes.py",
    "model/genome.py",
    "model/forms.py",
    "model/model.py",
    "model/layout.py",
    "model/names.py",
    "identify/solvers/lsq.py",
    "identify/judge/uncertainty.py",
    "report/html.py",
    "report/tables.py",
    "report/plots.py",
]


@pytest.mark.parametrize("path", NAME_READERS)
def test_no_regular_expression_decodes_a_gene_name(path):
    text = (SOURCE / path).read_text()
    assert "import re\n" not in text and "from re import" not in text
    for call in ("re.compile", "re.match", "re.fullmatch", "re.search", '.endswith((".gain'):
        assert call not in text


def test_no_module_matches_gene_name_patterns():
    for path in SOURCE.rglob("*.py"):
        for line in path.read_text().splitlines():
            if "re." in line and ("bond\\[" in line or "type:" in line or "mass:" in line):
                pytest.fail(f"{path.relative_to(SOURCE)}: {line.strip()}")
