"""Deterministic fuzzing of the trajectory readers: 3,562 mutated files in a few seconds.

* 1,000 CSV and 1,000 TRC files, mutations of a written synthetic file with gaps, of the
  first 80 rows of the horse CSV, of a CSV without time column (read with rate=60) and of
  the first 30 rows of the OpenSim TRC: truncations, byte flips and overwrites, inserted
  random bytes, deleted/duplicated/swapped/blank lines, deleted columns (all lines, header
  only, data only), garbage fields ("1.2.3", "1e999", "1_000", NUL, BOM, ...), edited
  header tokens and header values, extra fields, line-ending changes, dropped final line
  break, whole files of random bytes; a quarter of the cases stack two mutations.
* 562 NPZ files: 61 hand-made structural cases (missing keys, pickled object arrays, wrong
  shapes/dtypes, bad rates/units/masks/start times, inf, ...), 500 byte-level mutations of
  a compressed and an uncompressed archive, and a bare .npy file named .npz.
* 1,000 C3D files: byte flips in the header, parameter and data sections, extreme header
  words (frame counts, point counts, scale, rate, data block, processor type), corrupted
  parameter values (USED, SCALE, RATE, FRAMES, ACTUAL_START/END_FIELD, LABELS, UNITS, ...),
  truncations, random bytes.  They run in ONE subprocess that reports a JSON result per
  case, so an interpreter crash in the C3D library fails the test instead of killing
  pytest (warnings are errors there, as under pytest).

Each file must either load into a valid Trajectory (finite where the mask is True, NaN
elsewhere, consistent shapes, positive rate; for text formats the frame count equals the
number of data rows in the file and every header marker is kept) or raise InputError
whose message is one line naming the file.  Any other exception is a failure.  Each test
also checks that both outcomes occur often, so the fuzzer is not trivially rejected.
Seeds are fixed (numpy default_rng).
"""

from __future__ import annotations

import io
import json
import struct
import subprocess
import sys
import textwrap
import warnings
from pathlib import Path

import numpy as np
import pytest

from activebonds.data import Trajectory, read_trajectory, write_trajectory
from activebonds.data._common import FileWarning
from activebonds.data.readers import TruncatedRowWarning
from activebonds.errors import InputError

ROOT = Path(__file__).resolve().parents[1]
HORSE = ROOT / "src/activebonds/datasets/horse_vhdc/Horse1_M1_trot1_kinematics.csv"
HUMAN = ROOT / "tests/data/human_opensim/subject01_walk1.trc"

N_TEXT = 1000  # per text format
N_NPZ_BYTES = 500
N_C3D = 1000

pytestmark = pytest.mark.timeout(120)

# Shared by this process and the C3D subprocess (which gets this source verbatim).
VALIDATE_SRC = '''
import numpy as np


def invariant_problems(t):
    """Problems with a loaded trajectory (empty list = valid)."""
    problems = []
    p, m = np.asarray(t.positions), np.asarray(t.mask)
    if p.ndim != 3 or p.dtype != np.float64 or min(p.shape) < 1:
        return [f"positions shape/dtype {p.shape} {p.dtype}"]
    if m.shape != p.shape[:2] or m.dtype != np.bool_:
        problems.append(f"mask {m.shape} {m.dtype} for positions {p.shape}")
    elif not np.isfinite(p[m]).all() or not np.isnan(p[~m]).all():
        problems.append("positions not finite exactly where the mask is True")
    if len(t.markers) != p.shape[1] or len(set(t.markers)) != len(t.markers):
        problems.append("marker names do not match positions")
    if not (np.isfinite(t.rate) and t.rate > 0 and np.isfinite(t.start_time)):
        problems.append(f"bad rate {t.rate} or start {t.start_time}")
    return problems


def error_problems(message, path):
    """Problems with an InputError message (one line naming the file)."""
    problems = []
    if "\\n" in message or "\\r" in message:
        problems.append("message spans several lines")
    if path.name not in message:
        problems.append("message does not name the file")
    return problems
'''
_namespace: dict = {}
exec(VALIDATE_SRC, _namespace)
invariant_problems = _namespace["invariant_problems"]
error_problems = _namespace["error_problems"]


def synthetic(frames=15, markers=("A", "B.2", "C_", "Z"), seed=1) -> Trajectory:
    rng = np.random.default_rng(seed)
    pos = rng.normal(scale=0.7, size=(frames, len(markers), 3))
    mask = rng.random((frames, len(markers))) > 0.15
    mask[0] = True
    pos[~mask] = np.nan
    return Trajectory(pos, mask, tuple(markers), 100.0, start_time=0.5)


# ----------------------------------------------------------------------------- text mutations
GARBAGE = [
    "abc", "1.2.3", "--1", "0x1F", "1_000", "inf", "-inf", "1e999", "NaN", "", " ", '"',
    "nan", "1,5", "\u00e9", "\t", "1e-400", "+", ".", "1e", "\x00", "\ufeff1", "\u0661",
]  # fmt: skip
HEADER_WORDS = ["", "X", "Frame#", "Time", "Foo", "AX", "DataRate", "Units", "#", "60", "m"]
HEADER_VALUES = ["0", "-5", "1e9", "abc", "", "60.5", "30", "nan", "inf", "furlong", "m", "1"]
PRINTABLE = b'0123456789.,-\t eE\n\r#"nax'


def _lines(data: bytes) -> list[bytes]:
    return data.split(b"\n")


def _join(lines: list[bytes]) -> bytes:
    return b"\n".join(lines)


def _pick(rng, n: int, low: int = 0) -> int:
    return int(rng.integers(min(low, max(n - 1, 0)), max(n, 1)))


def _edit_field(data, rng, sep, line_range, values):
    lines = _lines(data)
    lo, hi = line_range(len(lines))
    if hi <= lo:
        return data
    i = int(rng.integers(lo, hi))
    fields = lines[i].split(sep)
    k = _pick(rng, len(fields))
    fields[k] = str(rng.choice(values)).encode("utf-8")
    lines[i] = sep.join(fields)
    return _join(lines)


def _delete_column(data, rng, sep, header_lines):
    lines = _lines(data)
    width = max(len(line.split(sep)) for line in lines) if lines else 1
    k = _pick(rng, width)
    scope = rng.integers(3)  # 0 all lines, 1 header only, 2 data only
    for i, line in enumerate(lines):
        in_header = i < header_lines
        if scope == 0 or (scope == 1 and in_header) or (scope == 2 and not in_header):
            fields = line.split(sep)
            if k < len(fields):
                del fields[k]
            lines[i] = sep.join(fields)
    return _join(lines)


def mutate_text(data: bytes, rng, sep: bytes, header_lines: int) -> tuple[bytes, str]:
    """One random mutation of a text trajectory file; returns (bytes, description)."""
    n = len(data)
    if n == 0:
        return data, "empty"
    lines = _lines(data)
    op = str(
        rng.choice(
            [
                "truncate", "flip", "overwrite", "insert_bytes", "delete_line", "duplicate_line",
                "swap_lines", "blank_line", "delete_column", "garbage_field", "blank_field",
                "header_token", "header_value", "extra_field", "crlf", "random_file", "empty",
                "header_only", "no_final_newline",
            ]
        )
    )  # fmt: skip
    if op == "truncate":
        data = data[: int(rng.integers(0, n))]
    elif op == "flip":
        b = bytearray(data)
        for _ in range(int(rng.integers(1, 4))):
            b[_pick(rng, n)] ^= int(rng.integers(1, 256))
        data = bytes(b)
    elif op == "overwrite":
        b = bytearray(data)
        b[_pick(rng, n)] = PRINTABLE[int(rng.integers(len(PRINTABLE)))]
        data = bytes(b)
    elif op == "insert_bytes":
        pos = _pick(rng, n)
        data = data[:pos] + rng.bytes(int(rng.integers(1, 12))) + data[pos:]
    elif op == "delete_line":
        del lines[_pick(rng, len(lines))]
        data = _join(lines)
    elif op == "duplicate_line":
        i = _pick(rng, len(lines))
        lines.insert(i, lines[i])
        data = _join(lines)
    elif op == "swap_lines":
        i, j = _pick(rng, len(lines)), _pick(rng, len(lines))
        lines[i], lines[j] = lines[j], lines[i]
        data = _join(lines)
    elif op == "blank_line":
        lines.insert(_pick(rng, len(lines)), b"")
        data = _join(lines)
    elif op == "delete_column":
        data = _delete_column(data, rng, sep, header_lines)
    elif op == "garbage_field":
        data = _edit_field(data, rng, sep, lambda m: (header_lines, m), GARBAGE)
    elif op == "blank_field":
        data = _edit_field(data, rng, sep, lambda m: (header_lines, m), [""])
    elif op == "header_token":
        data = _edit_field(data, rng, sep, lambda m: (0, min(header_lines, m)), HEADER_WORDS)
    elif op == "header_value":
        data = _edit_field(data, rng, sep, lambda m: (0, min(header_lines, m)), HEADER_VALUES)
    elif op == "extra_field":
        i = _pick(rng, len(lines))
        lines[i] = lines[i] + sep + str(rng.choice(["1.0", "", "x"])).encode()
        data = _join(lines)
    elif op == "crlf":
        data = data.replace(b"\r\n", b"\n") if b"\r\n" in data else data.replace(b"\n", b"\r\n")
    elif op == "random_file":
        data = rng.bytes(int(rng.integers(0, 3000)))
    elif op == "empty":
        data = b""
    elif op == "header_only":
        data = _join(lines[:header_lines]) + b"\n"
    elif op == "no_final_newline":
        data = data.rstrip(b"\r\n")
    return data, op


def text_row_problems(t: Trajectory, data: bytes, fmt: str, dropped: int = 0) -> list[str]:
    """For a loaded text file: frames == data rows in the file (less a ``dropped``
    incomplete last row), and no marker dropped."""
    text = data.decode("utf-8-sig")
    lines = [ln[:-1] if ln.endswith("\r") else ln for ln in text.split("\n")]
    if fmt == "trc":
        header, body = lines[3], lines[5:]
        named = [f for f in header.split("\t")[2:] if f.strip()]
        expected_markers = len(named)
        markers_ok = t.n_markers == expected_markers and t.dimension == 3
    else:
        i = 0
        while i < len(lines) and (
            not lines[i].strip() or (lines[i].lstrip().startswith("#") and "," not in lines[i])
        ):
            i += 1
        header, body = lines[i], lines[i + 1 :]
        n_fields = len([f for f in header.split(",") if f.strip()])
        markers_ok = t.n_markers * t.dimension <= n_fields <= t.n_markers * t.dimension + 2
        markers_ok = markers_ok and all(name in header for name in t.markers)
    rows = sum(1 for line in body if line.strip())
    problems = []
    if rows - dropped != t.n_frames:
        problems.append(f"{t.n_frames} frames loaded from {rows} data rows, {dropped} dropped")
    if not markers_ok:
        problems.append(f"markers {t.markers} do not match header {header[:80]!r}")
    return problems


def run_case(path: Path, fmt: str, kwargs: dict) -> tuple[str, list[str]]:
    """Read one file in-process; return (outcome, problems)."""
    try:
        with warnings.catch_warnings(record=True) as caught:  # other warnings stay errors
            warnings.simplefilter("always", FileWarning)  # one-line doubts about the file
            t = read_trajectory(path, **kwargs)
    except InputError as exc:
        return "error", error_problems(str(exc), path)
    except Exception as exc:  # noqa: BLE001 - any other exception is the failure we look for
        return "crash", [f"{type(exc).__name__}: {exc}"]
    problems = invariant_problems(t)
    dropped = [w for w in caught if issubclass(w.category, TruncatedRowWarning)]
    if len(dropped) > 1:
        problems.append(f"{len(dropped)} truncation warnings for one file")
    for w in dropped:  # an incomplete last row dropped: one line naming the file
        problems += error_problems(str(w.message), path)
    for w in caught:  # any other doubt (units): one line naming the file too
        if issubclass(w.category, FileWarning) and w not in dropped:
            problems += error_problems(str(w.message), path)
    if fmt in ("csv", "trc") and not problems:
        problems += text_row_problems(t, path.read_bytes(), fmt, len(dropped))
    return "ok", problems


def text_bases(tmp: Path, fmt: str) -> list[tuple[bytes, int, dict]]:
    """(file bytes, number of header lines, read kwargs) for each base file."""
    synth = write_trajectory(synthetic(), tmp / f"base.{fmt}").read_bytes()
    if fmt == "csv":
        horse = b"\n".join(HORSE.read_bytes().split(b"\n")[:81]) + b"\n"
        notime = b"Frame,Head X,Head Y\n" + b"".join(
            b"%d,%d.5,%d\n" % (i + 1, 1000 + i, i) for i in range(20)
        )
        return [(synth, 3, {}), (horse, 1, {}), (notime, 1, {"rate": 60.0})]
    lines = HUMAN.read_bytes().split(b"\n")
    values = lines[2].split(b"\t")
    values[2] = values[7] = b"30"
    lines[2] = b"\t".join(values)
    human = b"\n".join(lines[:36]) + b"\n"
    return [(synth, 6, {}), (human, 6, {})]


def check_outcomes(outcomes: list[tuple[str, str, str, list[str]]], minimum_ok: int):
    failures = [o for o in outcomes if o[1] == "crash" or o[3]]
    summary = {k: sum(1 for o in outcomes if o[1] == k) for k in ("ok", "error", "crash")}
    assert not failures, f"{len(failures)} failures, e.g. {failures[:5]} ({summary})"
    # the fuzzer must exercise both paths
    assert summary["ok"] >= minimum_ok and summary["error"] >= len(outcomes) // 4, summary


@pytest.mark.parametrize("fmt", ["csv", "trc"])
def test_fuzz_text_formats(tmp_path, fmt):
    rng = np.random.default_rng(20240601 if fmt == "csv" else 20240602)
    bases = text_bases(tmp_path, fmt)
    sep = b"," if fmt == "csv" else b"\t"
    outcomes = []
    for case in range(N_TEXT):
        data, header_lines, kwargs = bases[case % len(bases)]
        data, op = mutate_text(data, rng, sep, header_lines)
        if rng.random() < 0.25:
            data, op2 = mutate_text(data, rng, sep, header_lines)
            op = f"{op}+{op2}"
        path = tmp_path / f"case{case:04d}_{op.replace('+', '-')}.{fmt}"
        path.write_bytes(data)
        outcome, problems = run_case(path, fmt, kwargs)
        outcomes.append((path.name, outcome, op, problems))
    assert len(outcomes) == N_TEXT
    check_outcomes(outcomes, minimum_ok=N_TEXT // 10)


# ----------------------------------------------------------------------------- NPZ
def npz_structural_cases() -> list[tuple[str, dict]]:
    """Hand-made archives: (name, arrays for np.savez)."""
    good = {
        "positions": np.arange(24, dtype=float).reshape(4, 2, 3),
        "markers": np.array(["A", "B"]),
        "rate": np.float64(50.0),
    }
    cases = [("good", dict(good))]
    for key in good:
        cases.append((f"missing_{key}", {k: v for k, v in good.items() if k != key}))
        cases.append((f"object_{key}", {**good, key: np.array([good[key], None], dtype=object)}))
    bad_values = {
        "positions": [
            np.zeros((4, 2)), np.zeros((0, 2, 3)), np.zeros((4, 2, 3), complex),
            np.full((4, 2, 3), "1"), np.zeros((4, 2, 3), bool), np.full((4, 2, 3), np.inf),
            np.zeros((4, 3, 3)), np.full((4, 2, 3), np.nan), np.full((4, 2, 3), 1e308),
            np.zeros((4, 2, 3, 1)), np.zeros((4, 2, 3), np.float32), np.ones((4, 2, 2), int),
            np.zeros((4, 2, 3), "V8"),
        ],
        "markers": [
            np.array(["A", "A"]), np.array(["A", ""]), np.array([" A", "B"]), np.array([1, 2]),
            np.array(["A"]), np.array([b"A", b"\xff"]), np.array([["A", "B"]]),
            np.array(["A", "B\tC"]), np.array("AB"), np.array(["A", "B", "C"]),
            np.array([b"A", b"B"]),
        ],
        "rate": [
            np.float64(0), np.float64(-60), np.float64(np.nan), np.float64(np.inf),
            np.array([50.0, 60.0]), np.array("fast"), np.array(True), np.int64(60),
        ],
        "mask": [
            np.ones((4, 2), bool), np.ones((4, 3), bool), np.full((4, 2), 2),
            np.ones((4, 2)), np.array([[1, 0]] * 4), np.ones((4, 2), "U1"),
        ],
        "units": [
            np.array("mm"), np.array("furlong"), np.array(["m", "m"]), np.array(1.0),
            np.array(b"cm"), np.array(b"\xff"), np.array("Metres"), np.array(" MM "),
        ],
        "start_time": [
            np.float64(1.5), np.float64(np.nan), np.array("0"), np.zeros(3), np.float64(-np.inf),
            np.int8(-3),
        ],
    }  # fmt: skip
    for key, values in bad_values.items():
        for k, value in enumerate(values):
            cases.append((f"{key}_{k}", {**good, key: value}))
    cases.append(("extra_key", {**good, "comment": np.array("hello")}))
    cases.append(
        ("units_mm_huge", {**good, "units": np.array("mm"), "positions": np.full((4, 2, 3), 1e308)})
    )
    return cases


def npz_byte_bases() -> list[bytes]:
    t = synthetic()
    compressed, plain = io.BytesIO(), io.BytesIO()
    arrays = {
        "positions": t.positions,
        "mask": t.mask,
        "markers": np.array(t.markers),
        "rate": t.rate,
    }
    np.savez_compressed(compressed, **arrays)
    np.savez(plain, **arrays)
    return [compressed.getvalue(), plain.getvalue()]


def mutate_bytes(data: bytes, rng) -> tuple[bytes, str]:
    """Byte-level mutation of a binary file."""
    op = str(rng.choice(["flip", "flips", "truncate", "insert", "zero_run", "random", "append"]))
    b = bytearray(data)
    n = len(b)
    if n == 0:
        return data, "empty"
    if op == "flip":
        b[_pick(rng, n)] ^= int(rng.integers(1, 256))
    elif op == "flips":
        for _ in range(int(rng.integers(2, 20))):
            b[_pick(rng, n)] = int(rng.integers(256))
    elif op == "truncate":
        del b[int(rng.integers(0, n)) :]
    elif op == "insert":
        pos = _pick(rng, n)
        b[pos:pos] = rng.bytes(int(rng.integers(1, 64)))
    elif op == "zero_run":
        pos = _pick(rng, n)
        end = min(n, pos + int(rng.integers(1, 200)))
        b[pos:end] = bytes(end - pos)
    elif op == "random":
        b = bytearray(rng.bytes(int(rng.integers(0, 4000))))
    elif op == "append":
        b += rng.bytes(int(rng.integers(1, 600)))
    return bytes(b), op


def test_fuzz_npz(tmp_path):
    outcomes = []
    for name, arrays in npz_structural_cases():
        path = tmp_path / f"struct_{name}.npz"
        np.savez(path, **arrays)
        outcome, problems = run_case(path, "npz", {})
        outcomes.append((path.name, outcome, name, problems))
    n_struct = len(outcomes)
    assert n_struct >= 60
    rng = np.random.default_rng(7)
    bases = npz_byte_bases()
    for case in range(N_NPZ_BYTES):
        data, op = mutate_bytes(bases[case % 2], rng)
        path = tmp_path / f"bytes{case:04d}_{op}.npz"
        path.write_bytes(data)
        outcome, problems = run_case(path, "npz", {})
        outcomes.append((path.name, outcome, op, problems))
    # a .npy file with the .npz extension
    path = tmp_path / "single_array.npz"
    with open(path, "wb") as handle:
        np.save(handle, np.zeros((3, 1, 3)))
    outcome, problems = run_case(path, "npz", {})
    outcomes.append((path.name, outcome, "npy", problems))
    check_outcomes(outcomes, minimum_ok=5)
    by_name = {o[0]: o[1] for o in outcomes}
    assert by_name["struct_good.npz"] == "ok" and by_name["struct_object_rate.npz"] == "error"


# ----------------------------------------------------------------------------- C3D
C3D_CHILD = textwrap.dedent(
    """
    import faulthandler, json, sys, warnings
    from pathlib import Path
    faulthandler.enable()
    warnings.simplefilter("error")
    from activebonds.data import read_trajectory
    from activebonds.errors import InputError
    results = []
    for name in json.loads(Path(sys.argv[1]).read_text()):
        path = Path(name)
        try:
            t = read_trajectory(path)
        except InputError as exc:
            results.append([path.name, "error", error_problems(str(exc), path)])
        except Exception as exc:
            results.append([path.name, "crash", [type(exc).__name__ + ": " + str(exc)[:200]]])
        else:
            results.append([path.name, "ok", invariant_problems(t)])
    print(json.dumps(results))
    """
)


def _param_value_offset(data: bytes, name: bytes) -> int | None:
    """Offset of the first data byte of a C3D parameter (None if absent)."""
    idx = data.find(name)
    if idx < 0:
        return None
    pos = idx + len(name) + 2  # offset-to-next word
    ndims = data[pos + 1]
    return pos + 2 + ndims


def mutate_c3d(data: bytes, rng) -> tuple[bytes, str]:
    """C3D-aware mutations (header words, parameters, sections) plus byte-level ones."""
    b = bytearray(data)
    data_start = (struct.unpack_from("<H", data, 16)[0] - 1) * 512
    op = str(
        rng.choice(
            ["header_word", "header_float", "param_value", "processor", "section_flip", "bytes"]
        )
    )
    if op == "header_word":  # point count, analog count, first/last frame, gap, data block, ...
        offset = int(rng.choice([2, 4, 6, 8, 10, 16, 18]))
        value = int(rng.choice([0, 1, 2, 255, 65535, int(rng.integers(65536))]))
        struct.pack_into("<H", b, offset, value)
        op = f"header_word{offset}"
    elif op == "header_float":  # scale factor or frame rate
        offset = int(rng.choice([12, 20]))
        value = float(rng.choice([0.0, -1.0, 1.0, np.nan, np.inf, -np.inf, 1e30, 1e-30, 59.0]))
        struct.pack_into("<f", b, offset, value)
        op = f"header_float{offset}"
    elif op == "param_value":
        names = [b"USED", b"SCALE", b"RATE", b"FRAMES", b"ACTUAL_END_FIELD",
                 b"ACTUAL_START_FIELD", b"LABELS", b"UNITS", b"DATA_START"]  # fmt: skip
        name = names[int(rng.integers(len(names)))]
        offset = _param_value_offset(data, name)
        if offset is not None:
            for k in range(int(rng.integers(1, 5))):
                if offset + k < len(b):
                    b[offset + k] = int(rng.integers(256))
        op = f"param_{name.decode()}"
    elif op == "processor":
        b[512 + 3] = int(rng.choice([83, 84, 85, 86, 0, 255]))
    elif op == "section_flip":
        section = int(rng.integers(3))
        lo, hi = [(0, 512), (512, data_start), (data_start, len(b))][section]
        lo, hi = max(0, lo), min(hi, len(b))
        if lo >= hi:  # a header word moved the data section off the file
            lo, hi = 0, len(b)
        for _ in range(int(rng.integers(1, 6))):
            b[int(rng.integers(lo, hi))] ^= int(rng.integers(1, 256))
        op = f"flip_section{section}"
    else:
        return mutate_bytes(data, rng)
    return bytes(b), op


def test_fuzz_c3d_in_subprocess(tmp_path):
    bases = [
        write_trajectory(synthetic(), tmp_path / "base_synth.c3d").read_bytes(),
        write_trajectory(
            read_trajectory(HUMAN).window(0, 20), tmp_path / "base_human.c3d"
        ).read_bytes(),
    ]
    rng = np.random.default_rng(3141)
    names, ops = [], {}
    for case in range(N_C3D):
        data, op = mutate_c3d(bases[case % 2], rng)
        if rng.random() < 0.2:
            data, op2 = mutate_c3d(data, rng) if len(data) >= 520 else (data, "")
            op = f"{op}-{op2}"
        path = tmp_path / f"case{case:04d}_{op}.c3d"
        path.write_bytes(data)
        names.append(str(path))
        ops[path.name] = op
    manifest = tmp_path / "manifest.json"
    manifest.write_text(json.dumps(names))
    proc = subprocess.run(
        [sys.executable, "-c", VALIDATE_SRC + C3D_CHILD, str(manifest)],
        capture_output=True,
        text=True,
        timeout=90,
        cwd=tmp_path,
    )
    assert proc.returncode == 0, (
        f"reader subprocess died ({proc.returncode}): {proc.stderr[-2000:]}"
    )
    results = json.loads(proc.stdout)
    assert len(results) == N_C3D
    outcomes = [(name, outcome, ops[name], problems) for name, outcome, problems in results]
    check_outcomes(outcomes, minimum_ok=10)
