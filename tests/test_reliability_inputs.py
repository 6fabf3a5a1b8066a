"""Bad input files: fuzzed model files, and the command line's view of trajectory files.

* 1,200 mutated model files (400 from each of examples/{triangle,horse_limb,chain2d}.toml):
  deleted, duplicated, swapped, commented-out lines; swapped values between keys; random
  bytes written or inserted; truncations; values of the wrong type; huge, tiny, NaN and inf
  numbers; unknown and misspelt keys; unknown particle names; a quarter stack two mutations.
  Each either loads, and then dumps and reloads to the identical text, or raises InputError
  with ONE line containing the file's name. Anything else is a failure. Both outcomes must
  be common, so the fuzzer is not trivially rejected. Seeds are fixed.
* ``activebonds simulate BAD.toml --n-frames 5 --rate 60 --out x.csv`` on a sample of the
  refused files in subprocesses (8 by default, 30 with ``-m slow``): exit 2, one line on
  stderr naming the file, no traceback, no x.csv (nor any temporary file).
* ``activebonds info --json``: every missing-marker convention (blank CSV fields, "NaN" in
  CSV, blank TRC fields, NaN in .npz, an .npz mask, C3D residual -1)
  gives the same summary (gap counts per marker); a declared sample rate disagreeing with
  the time column is reported in one line with exit 2. The readers' own tests
  (test_trajectory_io.py) compare the masks themselves; this checks the command line.
"""

from __future__ import annotations

import json
import re
import warnings
from collections import Counter
from pathlib import Path

import numpy as np
import pytest

from activebonds.errors import InputError
from activebonds.model import dumps_model, load_model, loads_model
from reliability_runner import EXAMPLES, cli_many, one_line_error

pytestmark = pytest.mark.timeout(300)

SOURCES = ["triangle.toml", "horse_limb.toml", "chain2d.toml"]
PER_SOURCE = 400

WRONG_TYPES = [
    '"text"', "true", "[1, 2]", "{ a = 1 }", "1979-05-27T07:32:00Z", "[]", '""', '"1.0"',
    "[[1.0]]", '{ value = "x" }', "{ value = 1.0, min = 2.0, max = 0.5 }", "{}", "07:32:00",
    '["A", "A"]', "[1.0, 2.0, 3.0, 4.0]", "-1", "0", "2", "4",
]  # fmt: skip
NUMBERS = [
    "1e400", "-1e400", "nan", "+nan", "-nan", "inf", "+inf", "-inf", "1e308", "-1e308",
    "1.7976931348623157e308", "1e-320", "5e-324", "0.0", "-0.0", "-1.0",
    "99999999999999999999999999999", "-99999999999999999999", "1e16", "0x10", "0o7",
    "1_000", "3.141592653589793", "1e-300", "12345678901234567890.5",
]  # fmt: skip
KEYS = [
    "name", "dimension", "gravity", "mass", "marker", "position", "velocity", "kind",
    "particles", "type", "neural", "stiffness", "rest_length", "damping", "anchor",
    "rest_angle", "gain", "weights", "threshold", "value", "min", "max", "fixed", "log",
    "length", "rate",
]  # fmt: skip
ASSIGN = re.compile(r"^(\s*)([A-Za-z_][\w]*)\s*=\s*(.*)$")
NUMBER = re.compile(r"(?<![\w.])[-+]?\d+(?:\.\d+)?(?:[eE][-+]?\d+)?(?![\w.])")


def _assignments(lines):
    return [i for i, line in enumerate(lines) if ASSIGN.match(line)]


class _Nothing(Exception):
    """No place for this mutation in the file."""


def mutate(text: str, rng: np.random.Generator) -> tuple[str, bytes]:
    """One mutation of a model file: (its name, the new bytes)."""
    try:
        return _mutate(text, rng)
    except _Nothing:
        data = text.encode()
        return "truncate", data[: int(rng.integers(len(data) + 1))]


def _pick(rng, seq):
    if not len(seq):
        raise _Nothing
    return seq[int(rng.integers(len(seq)))]


def _mutate(text: str, rng: np.random.Generator) -> tuple[str, bytes]:
    lines = text.split("\n")
    op = [
        "delete_line", "duplicate_line", "swap_lines", "comment_line", "swap_values",
        "random_bytes", "insert_bytes", "truncate", "wrong_type", "bad_number",
        "unknown_key", "misspelt_key", "unknown_particle", "unknown_inline_key",
        "drop_header", "tweak_number", "add_comment", "swap_adjacent_keys",
    ][int(rng.integers(18))]  # fmt: skip

    def pick(seq):
        return _pick(rng, seq)

    if op == "delete_line":
        del lines[int(rng.integers(len(lines)))]
    elif op == "duplicate_line":
        i = int(rng.integers(len(lines)))
        lines.insert(i, lines[i])
    elif op == "swap_lines":
        i, j = rng.integers(len(lines), size=2)
        lines[i], lines[j] = lines[j], lines[i]
    elif op == "comment_line":
        i = pick(_assignments(lines))
        lines[i] = "# " + lines[i]
    elif op == "swap_values":
        i, j = (pick(_assignments(lines)) for _ in range(2))
        a, b = ASSIGN.match(lines[i]), ASSIGN.match(lines[j])
        lines[i] = f"{a.group(1)}{a.group(2)} = {b.group(3)}"
        lines[j] = f"{b.group(1)}{b.group(2)} = {a.group(3)}"
    elif op in ("random_bytes", "insert_bytes", "truncate"):
        data = bytearray(text.encode())
        at = int(rng.integers(len(data) + 1))
        if op == "truncate":
            return op, bytes(data[:at])
        noise = rng.bytes(int(rng.integers(1, 9)))
        if op == "random_bytes":
            data[at : at + len(noise)] = noise
        else:
            data[at:at] = noise
        return op, bytes(data)
    elif op == "wrong_type":
        i = pick(_assignments(lines))
        m = ASSIGN.match(lines[i])
        lines[i] = f"{m.group(1)}{m.group(2)} = {pick(WRONG_TYPES)}"
    elif op == "bad_number":
        candidates = [(i, m) for i, line in enumerate(lines) for m in NUMBER.finditer(line)]
        i, m = pick(candidates)
        lines[i] = lines[i][: m.start()] + pick(NUMBERS) + lines[i][m.end() :]
    elif op == "unknown_key":
        headers = [i for i, line in enumerate(lines) if line.startswith("[[")] + [-1]
        lines.insert(pick(headers) + 1, f"{pick(['bogus', 'Mass', 'stifness', 'extra'])} = 1.0")
    elif op == "misspelt_key":
        i = pick(_assignments(lines))
        m = ASSIGN.match(lines[i])
        key = m.group(2)
        other = pick([k for k in KEYS if k != key] + [key[:-1], key.upper(), key + "s"])
        lines[i] = f"{m.group(1)}{other} = {m.group(3)}"
    elif op == "unknown_particle":
        refs = [i for i, line in enumerate(lines) if line.startswith("particles")]
        i = pick(refs)
        lines[i] = re.sub(r'"[^"]+"', '"nobody"', lines[i], count=1)
    elif op == "unknown_inline_key":
        inline = [i for i, line in enumerate(lines) if "{ value" in line or "{ length" in line]
        i = pick(inline)
        lines[i] = lines[i].replace("{ ", f"{{ {pick(['bogus', 'step', 'Value'])} = 1.0, ", 1)
    elif op == "tweak_number":  # usually still valid: exercises the round trip
        candidates = [(i, m) for i, line in enumerate(lines) for m in NUMBER.finditer(line)]
        i, m = pick(candidates)
        value = float(m.group()) * float(pick([1.0001, 0.9999, 1.0 + 1e-15, 1.5, 0.5]))
        lines[i] = lines[i][: m.start()] + repr(value) + lines[i][m.end() :]
    elif op == "add_comment":
        i = int(rng.integers(len(lines) + 1))
        lines.insert(i, pick(["# a comment", "", "   ", "# = [[bond]]", "#\t\u00e9\u2603"]))
    elif op == "swap_adjacent_keys":  # key order inside a table does not matter
        pairs = [i for i in _assignments(lines) if i + 1 in _assignments(lines)]
        i = pick(pairs)
        lines[i], lines[i + 1] = lines[i + 1], lines[i]
    elif op == "drop_header":
        headers = [i for i, line in enumerate(lines) if line.startswith("[[")]
        del lines[pick(headers)]
    return op, "\n".join(lines).encode()


def fuzz_cases(seed: int = 1234) -> list[tuple[str, bytes]]:
    rng = np.random.default_rng(seed)
    cases = []
    for source in SOURCES:
        text = (EXAMPLES / source).read_text()
        for _ in range(PER_SOURCE):
            op, data = mutate(text, rng)
            if rng.random() < 0.25:  # stack a second mutation
                try:
                    op2, data = mutate(data.decode(), rng)
                    op = f"{op}+{op2}"
                except UnicodeDecodeError:
                    pass
            cases.append((f"{Path(source).stem}-{op}", data))
    return cases


def check_case(path: Path) -> str:
    """'ok' or 'error'; raises AssertionError on a contract violation."""
    try:
        model = load_model(path)
    except InputError as e:
        text = str(e)
        assert "\n" not in text and "\r" not in text, f"{path.name}: multi-line: {text!r}"
        assert path.name in text, f"{path.name}: error does not name the file: {text}"
        return "error"
    text = dumps_model(model)
    again = loads_model(text, f"dump of {path.name}")
    assert dumps_model(again) == text, f"{path.name}: dump -> load -> dump changed the text"
    assert again.particle_names == model.particle_names
    np.testing.assert_array_equal(again.layout.lower, model.layout.lower)
    np.testing.assert_array_equal(again.layout.upper, model.layout.upper)
    np.testing.assert_array_equal(again.layout.initial(), model.layout.initial())
    return "ok"


@pytest.fixture(scope="module")
def fuzzed(tmp_path_factory):
    folder = tmp_path_factory.mktemp("fuzzed-models")
    paths = []
    for i, (name, data) in enumerate(fuzz_cases()):
        path = folder / f"case{i:04d}-{name}.toml"
        path.write_bytes(data)
        paths.append(path)
    return paths


def test_fuzzed_model_files_load_round_trip_or_fail_in_one_line(fuzzed):
    outcomes: Counter = Counter()
    by_op: Counter = Counter()
    failures = []
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        for path in fuzzed:
            try:
                outcome = check_case(path)
            except AssertionError as e:
                failures.append(str(e))
                continue
            except Exception as e:  # noqa: BLE001 - any other exception is a failure
                failures.append(f"{path.name}: {type(e).__name__}: {e}")
                continue
            outcomes[outcome] += 1
            by_op[(path.stem.split("-", 2)[-1], outcome)] += 1
    print(f"\n{len(fuzzed)} fuzzed model files: {dict(outcomes)}")
    assert not failures, f"{len(failures)} failures, e.g.:\n" + "\n".join(failures[:20])
    assert len(fuzzed) >= 1000
    assert outcomes["ok"] >= 0.15 * len(fuzzed) and outcomes["error"] >= 0.3 * len(fuzzed)


def test_loaded_models_have_finite_search_bounds(fuzzed):
    text = (EXAMPLES / "triangle.toml").read_text()
    huge = text.replace(
        "stiffness = { value = 40.0, min = 1.0, max = 1000.0 }", "stiffness = { value = 1e308 }"
    )
    where = r"huge.toml: line \d+ \(the 1st \[\[bond\]\]\): bond\[0\]\.stiffness"
    with pytest.raises(InputError, match=where + r".*finite search bounds"):
        loads_model(huge, "huge.toml")
    models = []
    for path in fuzzed:
        try:
            models.append(load_model(path))
        except InputError:
            pass
    bad = [
        m.name
        for m in models
        if not (np.isfinite(m.layout.lower).all() and np.isfinite(m.layout.upper).all())
    ]
    assert not bad, f"{len(bad)} of {len(models)} loaded models have infinite bounds"


def _cli_sample(fuzzed, tmp_path, n: int):
    refused = []
    for path in fuzzed:
        try:
            load_model(path)
        except InputError:
            refused.append(path)
    rng = np.random.default_rng(99)
    sample = [refused[i] for i in sorted(rng.choice(len(refused), size=n, replace=False))]
    commands = []
    for i, src in enumerate(sample):
        folder = tmp_path / f"c{i:02d}"
        folder.mkdir()
        bad = folder / src.name
        bad.write_bytes(src.read_bytes())
        commands.append(
            (
                "simulate",
                bad.name,
                "--n-frames",
                "5",
                "--rate",
                "60",
                "--out",
                "x.csv",
                {"cwd": folder},
            )
        )
    for (*_, opts), proc, src in zip(commands, cli_many(commands), sample, strict=True):
        assert proc.returncode == 2, (src.name, proc.returncode, proc.stderr)
        line = one_line_error(proc)
        assert src.name in line, line
        assert sorted(p.name for p in opts["cwd"].iterdir()) == [src.name], src.name


@pytest.mark.slow  # integration scale: in pytest -m slow (every landing)
def test_cli_refuses_fuzzed_model_files(fuzzed, tmp_path):
    _cli_sample(fuzzed, tmp_path, 4)


@pytest.mark.slow
def test_cli_refuses_fuzzed_model_files_30(fuzzed, tmp_path):
    _cli_sample(fuzzed, tmp_path, 30)


# ----------------------------------------------------------------------------- trajectories
MM = np.arange(5 * 3 * 3, dtype=float).reshape(5, 3, 3) * 7.25 + 100.0
MASK = np.ones((5, 3), dtype=bool)
MASK[2, 0] = False  # A: 1 gap
MASK[1, 1] = MASK[3, 1] = False  # B: 2 gaps; C: none
NAMES = ["A", "B", "C"]


def _csv(missing: str) -> str:
    lines = ["Frame#,Time," + ",".join(f"{n}{a}" for n in NAMES for a in "XYZ")]
    for f in range(5):
        cells = [repr(float(v)) if MASK[f, m] else missing for m in range(3) for v in MM[f, m]]
        lines.append(",".join([str(f + 1), f"{f / 100:.2f}", *cells]))
    return "\n".join(lines) + "\n"


def _trc(missing: str, rate: str = "100.00") -> str:
    head = [
        "PathFileType\t4\t(X/Y/Z)\tx.trc",
        "DataRate\tCameraRate\tNumFrames\tNumMarkers\tUnits\tOrigDataRate\tOrigDataStartFrame\tOrigNumFrames",
        f"{rate}\t{rate}\t5\t3\tmm\t{rate}\t1\t5",
        "Frame#\tTime\t" + "\t".join(f"{n}\t\t" for n in NAMES),
        "\t\t" + "\t".join(f"X{k}\tY{k}\tZ{k}" for k in range(1, 4)),
        "",
    ]
    rows = []
    for f in range(5):
        cells = [repr(float(v)) if MASK[f, m] else missing for m in range(3) for v in MM[f, m]]
        rows.append("\t".join([str(f + 1), f"{f / 100:.3f}", *cells]))
    return "\n".join(head + rows) + "\n"


def _c3d(path: Path) -> None:
    """Occluded points: residual -1, coordinates zero (written with the c3d package)."""
    import c3d

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        w = c3d.Writer(point_rate=100.0, point_units="mm  ")
        for f in range(5):
            pts = np.zeros((3, 5), np.float32)
            pts[:, :3] = np.where(MASK[f][:, None], MM[f], 0.0)
            pts[~MASK[f], 3] = -1.0
            w.add_frames([(pts, np.zeros((0, 0), np.float32))])
        w.set_point_labels(NAMES)
        with open(path, "wb") as fh:
            w.write(fh)


@pytest.mark.slow  # integration scale: in `pytest -m slow` (every landing)
def test_info_json_same_gaps_for_every_missing_marker_convention(tmp_path):
    files = {
        "blank.csv": _csv(""),
        "NaN.csv": _csv("NaN"),
        "blank.trc": _trc(""),
        # declared rates disagreeing with the time column (100 Hz)
        "rate_comment.csv": "# rate: 50\n" + _csv(""),
        "rate_header.trc": _trc("", rate="120.00"),
    }
    for name, text in files.items():
        (tmp_path / name).write_text(text)
    np.savez(
        tmp_path / "nan.npz",
        positions=np.where(MASK[..., None], MM, np.nan),
        markers=np.array(NAMES),
        rate=100.0,
        units="mm",
    )
    np.savez(
        tmp_path / "mask.npz",
        positions=np.where(MASK[..., None], MM, -1.0),
        mask=MASK,
        markers=np.array(NAMES),
        rate=100.0,
        units="mm",
    )
    _c3d(tmp_path / "residual.c3d")
    names = ["blank.csv", "NaN.csv", "blank.trc", "nan.npz", "mask.npz"]
    names += ["residual.c3d", "rate_comment.csv", "rate_header.trc"]
    procs = dict(
        zip(names, cli_many([("info", tmp_path / n, "--json") for n in names]), strict=True)
    )

    summaries = {}
    for name in names[:-2]:
        proc = procs[name]
        assert proc.returncode == 0, (name, proc.stderr)
        d = json.loads(proc.stdout)
        assert d.pop("source").endswith(name)
        summaries[name] = d
    first = summaries["blank.csv"]
    assert first["gaps"] == {"A": 1, "B": 2, "C": 0} and first["total_gaps"] == 3
    assert first["frames"] == 5 and first["rate"] == 100.0 and first["units"] == "mm"
    for name, d in summaries.items():
        if name.endswith(".c3d"):  # a C3D file has no time column: start is frame-based
            d["start_time"] = first["start_time"]
        assert d == first, (name, d, first)

    for name, declared, label in (
        ("rate_comment.csv", "50", "rate comment"),
        ("rate_header.trc", "120", "DataRate"),
    ):
        proc = procs[name]
        assert proc.returncode == 2, (name, proc.stdout, proc.stderr)
        line = one_line_error(proc)
        assert name in line and label in line and f"{declared} Hz" in line, line
        assert "disagrees with the time column (100 Hz)" in line, line
