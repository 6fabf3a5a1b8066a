"""Free parameters named by their bond's kind and particles (or type) wherever people read
them, machine keys unchanged in the files; values at or near a search bound flagged in fit's
summary and in the report (within 1 % of the range, of the log range for log genes)."""

from __future__ import annotations

import csv
import dataclasses
import math
import re

import numpy as np
import pytest
from typer.testing import CliRunner

from activebonds.cli.main import app
from activebonds.data import write_trajectory
from activebonds.identify.judge.uncertainty import describe, from_jacobian
from activebonds.identify.stages import uncertainty as uncertainty_stage
from activebonds.model import Gene, loads_model
from activebonds.model.names import (
    LISTED,
    NEAR_BOUND,
    at_bound,
    bound_position,
    bounds_line,
    parameter_label,
    parameter_labels,
    parameter_rows,
)
from activebonds.report import load_run
from activebonds.report.html import parameters_table, searched_model
from activebonds.simulation import simulate

SMALL = """
name = "small"
dimension = 3

[[particle]]
name = "A"
mass = { value = 1.0, min = 0.5, max = 2.0 }

[[particle]]
name = "B"
mass = 1.5

[[particle]]
name = "C"
mass = 2.0

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
weights = { length = 0.0, rate = 0.0, min = -10.0, max = 10.0 }

[[bond]]
kind = "binary"
particles = ["A", "C"]
type = "diagonal"
stiffness = { value = 80.0, min = 1.0, max = 1000.0 }
rest_length = 0.45

[[bond]]
kind = "unary"
particles = ["C"]
stiffness = 5.0
anchor = { value = [0.0, 0.0, 0.0], min = -1.0, max = 1.0 }
"""


def test_every_parameter_is_named_by_its_bond_and_the_keys_are_unchanged():
    model = loads_model(SMALL)
    assert [g.name for g in model.layout.genes] == [
        "mass:A.mass",
        "bond[0].stiffness",
        "bond[0].damping",
        "bond[1].gain",
        "bond[1].weights.length[0]",
        "bond[1].weights.length[2]",
        "bond[1].weights.rate[0]",
        "bond[1].weights.rate[2]",
        "type:diagonal.stiffness",
        "bond[3].anchor[0]",
        "bond[3].anchor[1]",
        "bond[3].anchor[2]",
    ]
    assert parameter_labels(model) == [
        "particle A mass",
        "spring A-B stiffness",
        "spring A-B damping",
        "neural B-C gain",
        "neural B-C length weight from A-B",
        "neural B-C length weight from A-C",
        "neural B-C rate weight from A-B",
        "neural B-C rate weight from A-C",
        "spring type diagonal stiffness",
        "unary spring C anchor x",
        "unary spring C anchor y",
        "unary spring C anchor z",
    ]
    spec = model.spec
    assert parameter_label(spec, "bond[2]") == "spring A-C"
    assert parameter_label(spec, "type:diagonal") == "spring type diagonal"
    assert parameter_label(spec, "mass:A.weight") == "particle A mass weight"
    assert parameter_label(spec, "gravity.magnitude") == "gravity magnitude"
    assert parameter_label(spec, "drive.frequency") == "drive frequency"
    assert parameter_label(spec, "bond[9].stiffness") == "bond[9].stiffness"  # unknown: as is


def test_two_bonds_with_the_same_kind_and_particles_are_told_apart():
    text = SMALL.replace('particles = ["A", "C"]\ntype = "diagonal"', 'particles = ["A", "B"]')
    model = loads_model(text)
    labels = dict(zip((g.name for g in model.layout.genes), parameter_labels(model), strict=True))
    assert labels["bond[0].stiffness"] == "spring A-B #0 stiffness"
    assert labels["bond[2].stiffness"] == "spring A-B #2 stiffness"
    assert labels["bond[1].weights.length[2]"] == "neural B-C length weight from A-B #2"


def test_uncertainty_words_use_the_readable_names():
    model = loads_model(SMALL)
    spec = model.spec

    def show(name):
        return parameter_label(spec, name)

    names = ["bond[0].stiffness", "bond[0].damping", "type:diagonal.stiffness"]
    assert (
        describe(names, np.array([0.7, 0.7, 0.0]), set(), show)
        == "stiffness and damping of spring A-B trade off"
    )
    assert (
        describe(names, np.array([0.0, 0.0, 1.0]), set(), show)
        == "spring type diagonal stiffness does not change the residuals"
    )
    # without a label function, the keys as before
    assert describe(names, np.array([0.0, 0.0, 1.0]), set()) == (
        "type:diagonal.stiffness does not change the residuals"
    )
    jac = np.zeros((20, 3))
    jac[:, :2] = np.random.default_rng(0).normal(size=(20, 2))
    est, *_, dirs = from_jacobian(jac, np.ones(20), names, np.ones(3), np.ones(3), 17, label=show)
    assert [e.name for e in est] == names  # the keys stay
    assert set(dirs) == {"spring type diagonal stiffness does not change the residuals"}
    assert est[2].note == dirs[0]


# ----------------------------------------------------------------------------- bounds


def _gene(lower, upper, log, owner="bond", key="stiffness", **fields):
    fields = {"kind": "binary", "bonds": (0,)} if owner == "bond" else fields
    return Gene(owner, key, **fields, lower=lower, upper=upper, log=log, value=lower)


def test_near_means_within_one_percent_of_the_range_or_of_the_log_range():
    assert NEAR_BOUND == 0.01
    lin = _gene(1.0, 1000.0, False)
    log = _gene(1.0, 1000.0, True)
    assert at_bound(lin, 1000.0) == "max" and at_bound(log, 1000.0) == "max"
    assert at_bound(lin, 1.0) == "min" and at_bound(log, 1.0) == "min"
    assert at_bound(lin, 990.5) == "max" and at_bound(lin, 989.0) is None
    # log range: 1000 ** 0.99 = 933.3; 940 is near max there, not on a linear range
    assert at_bound(log, 940.0) == "max" and at_bound(lin, 940.0) is None
    assert at_bound(log, 920.0) is None
    assert at_bound(log, 1000**0.0099) == "min" and at_bound(log, 1000**0.011) is None
    assert bound_position(log, math.sqrt(1000.0)) == pytest.approx(0.5)
    assert at_bound(lin, 500.0) is None
    assert at_bound(_gene(-10.0, 10.0, False), -9.9) == "min"
    assert at_bound(_gene(-10.0, 10.0, False), 0.0) is None
    assert at_bound(_gene(2.0, 2.0, False), 2.0) is None  # an empty range: nothing to say
    weight = _gene(0.5, 5.0, True, "mass", "weight", particle="A")
    assert weight.name == "mass:A.weight"
    assert at_bound(weight, 5.0) is None  # a gauge, never


def test_rows_flag_by_the_searched_bounds():
    model = loads_model(SMALL)
    n = model.layout.n_genes
    values = [g.value for g in model.layout.genes]
    values[1] = 1000.0  # spring A-B stiffness at its max
    rows = parameter_rows(model, values)
    assert [r.bound for r in rows] == [None, "max"] + [None] * (n - 2)
    assert rows[1].name == "spring A-B stiffness" and rows[1].key == "bond[0].stiffness"
    assert rows[1].bound_text() == "near max 1000"
    line = bounds_line(rows)
    assert line.startswith(f"1 of {n} parameters at or near a search bound (within 1 % ")
    assert line.endswith("spring A-B stiffness = 1000 (near max 1000)")
    assert bounds_line(parameter_rows(model)) is None
    # the same value under wider searched bounds is mid-range
    wider = loads_model(
        SMALL.replace("max = 1000.0 }\nrest_length = 0.5", "max = 1e6 }\nrest_length = 0.5")
    )
    assert parameter_rows(model, values, bounds=wider)[1].bound is None


PAIR = """
name = "pair"
dimension = 3

[[particle]]
name = "A"
mass = 1.0
position = [0.0, 0.0, 0.0]
velocity = [0.0, 0.3, 0.1]

[[particle]]
name = "B"
mass = 1.5
position = [0.6, 0.0, 0.05]
velocity = [0.0, -0.2, 0.0]

[[bond]]
kind = "binary"
particles = ["A", "B"]
stiffness = { value = STIFFNESS, min = 1.0, max = MAX }
rest_length = { value = 0.5, min = 0.25, max = 0.75 }
damping = { value = 0.5, min = 0.01, max = 10.0 }
"""


@pytest.mark.slow  # integration scale: in pytest -m slow (every landing)
def test_fit_summary_and_report_flag_a_value_at_its_bound(tmp_path):
    """The truth's stiffness (40) lies beyond the searched max (20): the fit ends there and
    says so; the rest length, mid-range, is not flagged. The report's table names both."""
    truth = loads_model(PAIR.replace("STIFFNESS", "40.0").replace("MAX", "100.0"))
    data = tmp_path / "pair.csv"
    write_trajectory(simulate(truth, 80, 100.0), data)
    model = tmp_path / "pair.toml"
    model.write_text(PAIR.replace("STIFFNESS", "10.0").replace("MAX", "20.0"))
    run = tmp_path / "run"
    args = ["fit", model, data, "--population", "16", "--generations", "5", "--init", "lsq"]
    res = CliRunner().invoke(app, [str(a) for a in args] + ["--out", str(run)])
    assert res.exit_code == 0, res.output
    lines = [ln for ln in res.output.splitlines() if "at or near a search bound" in ln]
    # the value printed to 6 digits: the refinement's bounded steps (sin transform) end at the
    # bound or a few 1e-5 of it short, as the platform's rounding has it (20 or 19.9996)
    (line,) = lines
    found = re.fullmatch(
        r"1 of 3 parameters at or near a search bound \(within 1 % of the range; widen it and "
        r"fit again\): spring A-B stiffness = ([0-9.]+) \(near max 20\)",
        line,
    )
    assert found, line
    assert float(found.group(1)) == pytest.approx(20.0, rel=1e-4)
    record = load_run(run)
    table = parameters_table(record, searched_model(record))
    rows = {row[0]: row for row in table.rows}
    assert list(rows) == ["spring A-B stiffness", "spring A-B rest_length", "spring A-B damping"]
    assert rows["spring A-B stiffness"][5] == "near max 20"
    assert rows["spring A-B rest_length"][5] == ""
    assert [row[6] for row in table.rows] == [g.name for g in record.model.layout.genes]
    # uncertainty: the keys in the files, the readable names beside them and in the report
    with open(run / "uncertainty.csv", newline="") as f:
        found = list(csv.DictReader(f))
    assert [r["parameter"] for r in found] == [g.name for g in record.model.layout.genes]
    assert [r["label"] for r in found] == list(rows)
    section = uncertainty_stage.section(record.records["uncertainty"], record.model.spec)
    assert [row[0] for row in section.tables[0].rows] == list(rows)


def test_a_mass_under_total_mass_at_its_bound_is_flagged_in_kg():
    """Three free masses under total_mass = 10 kg, each with bounds 3 ... 10 (kg up to a
    common scale): the ratios are held within [0.3, 3.33]. A fit that puts p0 at 0.62 kg
    beside p1 at 6.6 kg has pushed the ratio p1/p0 to its largest value (10/3 once scaled):
    p0 is flagged near its min and p1 near its max, both shown in kg with bounds in kg
    (the weights' bounds times the factor best_model.toml writes); a fit inside the
    ratios' range flags nothing, whatever the weights' common scale."""
    from activebonds.model import loads_model
    from activebonds.model.names import bounds_line
    from test_gravity_masses import chain

    free = "{ value = 5.0, min = 3.0, max = 10.0 }"
    model = loads_model(chain("total_mass = 10.0", masses=(free,) * 3))
    rest = model.layout.mass_rest
    assert rest == pytest.approx(10.0)
    # weights: p1 / p0 = 10 / 3 exactly (at the bound), p2 in between
    for scale in (1.0, 7.0):
        weights = scale * np.array([3.0, 10.0, 5.0])
        rows = parameter_rows(model, weights)
        kg = [r.value for r in rows]
        assert kg == pytest.approx(10.0 * weights / weights.sum(), rel=1e-12)
        assert [r.bound for r in rows] == ["min", "max", None]
        assert [r.unit for r in rows] == ["kg"] * 3
        assert rows[0].name == "particle p0 mass (share of total_mass)"
        assert rows[0].lower == pytest.approx(kg[0]) and rows[1].upper == pytest.approx(kg[1])
        assert rows[0].bound_text() == f"near min {kg[0]:.6g} kg"
        assert rows[0].lower <= kg[0] <= rows[0].upper and 0.0 <= rows[2].position <= 1.0
        line = bounds_line(rows)
        assert line.startswith("2 of 3 parameters at or near a search bound")
        assert f"particle p0 mass (share of total_mass) = {kg[0]:.6g} (near min" in line
    inside = parameter_rows(model, np.array([3.2, 3.5, 3.3]))  # kg, each within 3 ... 10
    assert [r.bound for r in inside] == [None, None, None]
    # the common factor nearest 1 keeps the file's bounds: kg bounds are 3 ... 10
    assert (inside[0].lower, inside[0].upper) == pytest.approx((3.0, 10.0))
    # just inside the 1 % band of the ratio's log range (2 log(10/3)): still flagged
    near = np.array([3.0, 10.0 * np.exp(-0.009 * 2 * np.log(10 / 3)), 5.0])
    assert [r.bound for r in parameter_rows(model, near)][:2] == ["min", "max"]


def test_a_long_bounds_line_names_the_first_parameters_and_counts_the_rest():
    model = loads_model(SMALL)
    rows = parameter_rows(model, [g.value for g in model.layout.genes])
    flagged_row = dataclasses.replace(rows[1], value=1000.0, bound="max")
    many = [dataclasses.replace(flagged_row, name=f"p{i}") for i in range(12)]
    line = bounds_line(many)
    assert line.startswith("12 of 12 parameters at or near a search bound")
    assert [f"p{i} = 1000" in line for i in range(12)] == [True] * LISTED + [False] * 4
    assert line.endswith(", and 4 more (the best model file holds every value)")
