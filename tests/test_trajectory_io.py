"""Trajectory layer: readers, writers and the Trajectory operations, checked on numbers.

Reads only files inside the repository (the bundled horse CSVs and the OpenSim TRC) and
files the tests write into ``tmp_path``.
"""

from __future__ import annotations

import struct
import time
from pathlib import Path

import numpy as np
import pytest

from activebonds.data import Trajectory, describe, read_trajectory, write_trajectory
from activebonds.errors import InputError

ROOT = Path(__file__).resolve().parents[1]
HORSE = ROOT / "src/activebonds/datasets/horse_vhdc/Horse1_M1_trot1_kinematics.csv"
HORSE_WALK = ROOT / "src/activebonds/datasets/horse_vhdc/Horse1_M1_walk1_kinematics.csv"
HUMAN = ROOT / "tests/data/human_opensim/subject01_walk1.trc"


def synthetic(frames=12, markers=("A", "B.2", "C_"), dim=3, start=0.25, rate=60.0, seed=0):
    """Random positions (about a metre) with a few gaps."""
    rng = np.random.default_rng(seed)
    pos = rng.normal(scale=0.8, size=(frames, len(markers), dim))
    mask = np.ones((frames, len(markers)), dtype=bool)
    mask[2, 0] = mask[3, 0] = mask[5, 1] = mask[-1, 2] = False
    pos[~mask] = np.nan
    return Trajectory(pos, mask, tuple(markers), rate, start_time=start, source_units="m")


def assert_same(a: Trajectory, b: Trajectory, atol=0.0, rate_rtol=0.0):
    assert a.markers == b.markers
    assert a.positions.shape == b.positions.shape
    np.testing.assert_array_equal(a.mask, b.mask)
    np.testing.assert_allclose(a.positions, b.positions, rtol=0, atol=atol, equal_nan=True)
    assert a.rate == pytest.approx(b.rate, rel=rate_rtol, abs=0)
    assert a.start_time == pytest.approx(b.start_time, rel=1e-12, abs=1e-12)


def error_of(path, **kwargs) -> str:
    with pytest.raises(InputError) as info:
        read_trajectory(path, **kwargs)
    text = str(info.value)
    assert "\n" not in text and Path(path).name in text
    return text


# ----------------------------------------------------------------------------- real files
def test_horse_csv_numbers():
    t = read_trajectory(HORSE)
    assert t.markers == ("Head", "Withers", "Sacrum", "HFL", "HFR", "HHL", "HHR")
    assert (t.n_frames, t.n_markers, t.dimension) == (600, 7, 3)
    assert t.rate == 60.0 and t.dt == 1 / 60.0
    assert t.source_units == "mm" and t.start_time == 0.0 and t.n_gaps == 0
    np.testing.assert_allclose(t.positions[0, 0], [0.95540527, -0.08841407, 1.37253247], atol=1e-15)
    # HHR Z of the last row: 17.87613 mm
    assert t.positions[-1, 6, 2] == pytest.approx(0.01787613, abs=1e-15)
    # dt from the rate, not from the rounded time column (9.983 in the file)
    assert t.times[-1] == pytest.approx(599 / 60.0, abs=1e-12)
    assert read_trajectory(HORSE_WALK).rate == 60.0


def test_human_trc_numbers():
    t = read_trajectory(HUMAN)
    assert (t.n_frames, t.n_markers, t.dimension) == (151, 41, 3)
    assert t.rate == 60.0 and t.source_units == "mm"
    assert t.markers[0] == "R.ASIS" and t.markers[-1] == "Top.Head"
    np.testing.assert_allclose(t.positions[0, 0], [0.61724762, 1.05527502, 0.17078198], atol=1e-15)
    assert t.times[1] == 1 / 60.0  # not the file's 0.017
    assert t.n_gaps == 0


def test_describe():
    d = describe(read_trajectory(HORSE).window(0, 53))
    assert d["frames"] == 53 and d["rate"] == 60.0 and d["dt"] == pytest.approx(1 / 60)
    assert d["duration"] == pytest.approx(52 / 60) and d["units"] == "mm"
    assert d["dimension"] == 3 and d["gaps"] == dict.fromkeys(d["markers"], 0)
    d = describe(synthetic())
    assert d["gaps"] == {"A": 2, "B.2": 1, "C_": 1} and d["total_gaps"] == 4


# ----------------------------------------------------------------------------- round trips
@pytest.mark.parametrize("ext", ["csv", "trc", "npz", "c3d", "mat"])
def test_round_trip_with_gaps(tmp_path, ext):
    t = synthetic()
    path = write_trajectory(t, tmp_path / f"t.{ext}")
    back = read_trajectory(path)
    if ext == "npz":
        assert_same(back, t)
        np.testing.assert_array_equal(back.positions, t.positions)
    elif ext == "c3d":
        assert_same(back, t, atol=1e-6 * np.nanmax(np.abs(t.positions)))
    else:
        assert_same(back, t, atol=1e-9)
    assert back.n_gaps == 4
    assert back.source == str(path)
    assert [p.name for p in tmp_path.iterdir()] == [f"t.{ext}"]  # no temp files left


@pytest.mark.parametrize("ext", ["csv", "trc", "npz", "c3d", "mat"])
def test_round_trip_real_data(tmp_path, ext):
    t = read_trajectory(HUMAN)
    back = read_trajectory(write_trajectory(t, tmp_path / f"h.{ext}"))
    assert_same(back, t, atol=1e-6 if ext == "c3d" else 1e-9)


@pytest.mark.parametrize("ext", ["csv", "npz"])
def test_round_trip_2d(tmp_path, ext):
    t = synthetic(dim=2, rate=59.94, start=-1.5)
    assert_same(read_trajectory(write_trajectory(t, tmp_path / f"t.{ext}")), t, atol=1e-9)


def test_c3d_odd_rate_and_start(tmp_path):
    t = synthetic(rate=59.94, start=10 / 59.94)
    back = read_trajectory(write_trajectory(t, tmp_path / "t.c3d"))
    assert back.rate == 59.94  # float32 rate rounded to its shortest decimal form
    assert back.start_time == pytest.approx(10 / 59.94)


def test_writer_errors_and_atomicity(tmp_path):
    t = synthetic(dim=2)
    with pytest.raises(InputError, match="does not exist"):
        write_trajectory(t, tmp_path / "missing" / "t.csv")
    with pytest.raises(InputError, match="unknown trajectory file extension"):
        write_trajectory(t, tmp_path / "t.txt")
    with pytest.raises(InputError, match="3-D"):
        write_trajectory(t, tmp_path / "t.trc")
    assert list(tmp_path.iterdir()) == []
    target = tmp_path / "keep.csv"
    target.write_text("old")
    with pytest.raises(InputError):
        write_trajectory(synthetic(dim=2), tmp_path / "keep.c3d")
    assert target.read_text() == "old"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["keep.csv"]


# ----------------------------------------------------------------------------- missing data
def _write_c3d_with_occlusion(path: Path, mm: np.ndarray, mask: np.ndarray, labels, rate=100.0):
    """Independent C3D writer call: occluded points zero-filled with residual -1."""
    import warnings

    import c3d

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        w = c3d.Writer(point_rate=rate, point_units="mm  ")
        for f in range(mm.shape[0]):
            pts = np.zeros((mm.shape[1], 5), np.float32)
            pts[:, :3] = np.where(mask[f][:, None], mm[f], 0.0)
            pts[~mask[f], 3] = -1
            w.add_frames([(pts, np.zeros((0, 0), np.float32))])
        w.set_point_labels(labels)
        with open(path, "wb") as handle:
            w.write(handle)


def test_blank_nan_and_residual_give_the_same_mask(tmp_path):
    mm = np.arange(4 * 2 * 3, dtype=float).reshape(4, 2, 3) * 10 + 100
    mask = np.array([[1, 1], [0, 1], [1, 0], [1, 1]], dtype=bool)

    def csv_text(missing: str) -> str:
        lines = ["Frame#,Time,AX,AY,AZ,BX,BY,BZ"]
        for f in range(4):
            cells = []
            for m in range(2):
                cells += [repr(float(v)) if mask[f, m] else missing for v in mm[f, m]]
            lines.append(",".join([str(f + 1), f"{f / 100:.3f}"] + cells))
        return "\r\n".join(lines) + "\r\n"

    (tmp_path / "blank.csv").write_text(csv_text(""))
    (tmp_path / "nan.csv").write_text(csv_text("NaN"))
    np.savez(
        tmp_path / "nan.npz",
        positions=np.where(mask[..., None], mm, np.nan),
        markers=np.array(["A", "B"]),
        rate=100.0,
        units="mm",
    )
    np.savez(
        tmp_path / "mask.npz",
        positions=np.where(mask[..., None], mm, 0.0),
        mask=mask,
        markers=np.array(["A", "B"]),
        rate=100.0,
        units="mm",
    )
    _write_c3d_with_occlusion(tmp_path / "occluded.c3d", mm, mask, ["A", "B"])
    trc = write_trajectory(read_trajectory(tmp_path / "blank.csv"), tmp_path / "blank.trc")
    assert "\t\t\t" in trc.read_text()  # blank TRC fields
    results = [
        read_trajectory(tmp_path / name)
        for name in ("blank.csv", "nan.csv", "nan.npz", "mask.npz", "occluded.c3d", "blank.trc")
    ]
    for t in results:
        np.testing.assert_array_equal(t.mask, mask)
        assert t.rate == 100.0 and t.markers == ("A", "B")
        np.testing.assert_allclose(t.positions[mask], mm[mask] / 1000, rtol=1e-7)
        assert np.isnan(t.positions[~mask]).all()


def test_partly_blank_sample_is_missing(tmp_path):
    p = tmp_path / "p.csv"
    p.write_text("Time,AX,AY,AZ\n0,1,2,3\n0.5,1,,3\n1.0,1,2,3\n")
    t = read_trajectory(p)
    assert t.mask.tolist() == [[True], [False], [True]] and t.rate == 2.0


# ----------------------------------------------------------------------------- rates
def test_rate_argument_disagrees_with_time_column():
    text = error_of(HORSE, rate=50)
    assert "sample rate 50 Hz disagrees with the time column (60 Hz)" in text
    assert read_trajectory(HORSE, rate=60.3).rate == 60.3  # within 1 %: the argument is used


def test_trc_rate_checks(tmp_path):
    assert "disagrees with DataRate" in error_of(HUMAN, rate=50)
    lines = HUMAN.read_text().split("\n")
    lines[2] = lines[2].replace("60.00", "50.00", 1)
    bad = tmp_path / "bad_rate.trc"
    bad.write_text("\n".join(lines))
    assert "DataRate 50 Hz disagrees with the time column (60 Hz)" in error_of(bad)


def test_csv_without_time_column_needs_a_rate(tmp_path):
    p = tmp_path / "notime.csv"
    p.write_text("Frame,Head X,Head Y\n1,1000,0\n2,1001,0\n3,1002,nan\n")
    assert "add a time column or a line '# rate: <Hz>' before the header" in error_of(p)
    t = read_trajectory(p, rate=120)
    assert t.rate == 120 and t.dimension == 2 and t.markers == ("Head",)
    assert t.positions[1, 0].tolist() == [1.001, 0.0] and t.n_gaps == 1


def test_rate_comment_and_units(tmp_path):
    p = tmp_path / "m.csv"
    p.write_text("# units: m\n# rate: 200\nTime,A_x,A_y,A_z\n1.0,1,2,3\n1.005,4,5,6\n")
    t = read_trajectory(p)
    assert t.rate == 200 and t.start_time == 1.0 and t.source_units == "m"
    assert t.positions[1, 0].tolist() == [4.0, 5.0, 6.0]
    assert read_trajectory(p, units="cm").positions[1, 0].tolist() == [0.04, 0.05, 0.06]
    assert "unknown length unit 'furlong'" in error_of(p, units="furlong")
    p.write_text("# rate: 100\nTime,AX,AY\n0,1,2\n0.005,1,2\n")
    assert "rate comment (line 1) 100 Hz disagrees with the time column (200 Hz)" in error_of(p)


def test_non_uniform_time_column(tmp_path):
    lines = HORSE.read_text().splitlines()
    del lines[300]  # a missing row in the middle
    p = tmp_path / "gap.csv"
    p.write_text("\n".join(lines) + "\n")
    assert "not uniformly sampled" in error_of(p)


# ----------------------------------------------------------------------------- bad rows
def test_truncated_last_row_reports_its_line(tmp_path):
    data = HORSE.read_bytes()
    p = tmp_path / "cut.csv"
    p.write_bytes(data[: len(data) - 60])
    text = error_of(p, strict=True)  # by default: dropped with a warning (test_lab_formats)
    assert "line 601" in text and "truncated" in text
    trc = HUMAN.read_text()
    q = tmp_path / "cut.trc"
    q.write_text(trc[: len(trc) - 500])
    assert "line 157" in error_of(q, strict=True)
    q.write_text(trc[: trc.rstrip("\n").rfind("\n") + 1])  # whole last row gone
    assert "NumFrames 151 but the file has 150 data rows" in error_of(q)


def test_non_number_names_line_and_column(tmp_path):
    lines = HORSE.read_text().splitlines()
    fields = lines[9].split(",")
    fields[3] = "12.3.4"
    lines[9] = ",".join(fields)
    p = tmp_path / "bad.csv"
    p.write_text("\n".join(lines))
    text = error_of(p)
    assert "line 10" in text and "HeadY" in text and "'12.3.4' is not a number" in text
    fields[3] = "inf"
    lines[9] = ",".join(fields)
    p.write_text("\n".join(lines))
    assert "not a finite number" in error_of(p)


@pytest.mark.parametrize(
    ("header_lines", "message"),
    [
        (2, "header key NumFrames is missing"),
        (0, "expected 'PathFileType'"),
        (3, "expected the columns Frame#, Time"),
    ],
)
def test_trc_header_errors(tmp_path, header_lines, message):
    lines = HUMAN.read_text().split("\n")
    if header_lines == 2:
        lines[1] = lines[1].replace("NumFrames", "Frames")
    elif header_lines == 0:
        lines[0] = "Hello"
    else:
        lines[3] = lines[3].replace("Frame#", "Nr")
    p = tmp_path / "h.trc"
    p.write_text("\n".join(lines))
    assert message in error_of(p)


def test_csv_header_errors(tmp_path):
    p = tmp_path / "h.csv"
    p.write_text("Time,AX,AY,AZ,Notes\n0,1,2,3,4\n")
    assert "'Notes' (column 5) is not a coordinate column" in error_of(p)
    p.write_text("Time,AX,AY,BX,BY,BZ\n0,1,2,3,4,5\n")
    assert "marker 'B' has columns for axes X, Y, Z; expected X, Y" in error_of(p)
    p.write_text("Time,AX,AY,AX,AY\n0,1,2,3,4\n")
    assert "appears twice" in error_of(p)
    p.write_text("Time,AX,AY\n")
    assert "no data rows" in error_of(p)
    p.write_bytes(b"Time,AX,AY\n0,\xff,1\n")
    assert "not a UTF-8 text file" in error_of(p)


def test_npz_errors(tmp_path):
    p = tmp_path / "o.npz"
    np.savez(p, positions=np.zeros((2, 1, 3)), markers=np.array(["A"], dtype=object), rate=60.0)
    assert "pickled" in error_of(p) and "markers" in error_of(p)
    np.savez(p, positions=np.zeros((2, 1, 3)), markers=np.array(["A"]))
    assert "key 'rate' is missing" in error_of(p)
    np.savez(
        p,
        positions=np.zeros((2, 1, 3)),
        markers=np.array(["A"]),
        rate=60.0,
        units="mm",
        start_time=0.5,
    )
    t = read_trajectory(p)
    assert t.source_units == "mm" and t.start_time == 0.5 and t.positions.max() == 0
    assert "disagrees" in error_of(p, rate=30)
    p.write_bytes(b"not a zip file")
    assert "not a readable .npz archive" in error_of(p)


def test_c3d_corrupt_frame_count_fails_fast(tmp_path):
    p = tmp_path / "big.c3d"
    write_trajectory(synthetic(), p)
    data = bytearray(p.read_bytes())
    # header last_frame (word 5) and TRIAL:ACTUAL_END_FIELD -> declare billions of frames
    struct.pack_into("<H", data, 8, 65535)
    idx = data.find(b"ACTUAL_END_FIELD")
    assert idx > 0
    value_at = idx + len(b"ACTUAL_END_FIELD") + 2 + 1 + 1 + 1  # offset, bpe, ndims, dim
    struct.pack_into("<HH", data, value_at, 65535, 65535)
    p.write_bytes(bytes(data))
    start = time.perf_counter()
    text = error_of(p)
    assert time.perf_counter() - start < 2
    assert "truncated or corrupt" in text


def test_misc_read_errors(tmp_path):
    assert "unknown trajectory file extension '.txt'" in error_of(tmp_path / "x.txt")
    assert "file not found" in error_of(tmp_path / "none.csv")
    assert "file not found" in error_of(tmp_path / "none.npz")
    (tmp_path / "empty.c3d").write_bytes(b"")
    assert "only 0 bytes" in error_of(tmp_path / "empty.c3d")
    (tmp_path / "text.c3d").write_text("hello" * 200)
    assert "not a C3D file" in error_of(tmp_path / "text.c3d")


# ----------------------------------------------------------------------------- operations
def test_validation():
    pos = np.zeros((3, 1, 3))
    mask = np.ones((3, 1), bool)
    with pytest.raises(InputError, match="NaN wherever"):
        Trajectory(pos, ~mask, ("A",), 60.0)
    with pytest.raises(InputError, match="finite wherever"):
        Trajectory(np.full((3, 1, 3), np.nan), mask, ("A",), 60.0)
    with pytest.raises(InputError, match="positive finite"):
        Trajectory(pos, mask, ("A",), 0.0)
    with pytest.raises(InputError, match="does not match"):
        Trajectory(pos, mask[:2], ("A",), 60.0)
    with pytest.raises(InputError, match="marker names"):
        Trajectory(pos, mask, ("A", "B"), 60.0)
    with pytest.raises(InputError, match="appears twice"):
        Trajectory(np.zeros((3, 2, 3)), np.ones((3, 2), bool), ("A", "A"), 60.0)
    t = Trajectory(pos, mask, ["A"], 60)
    assert not t.positions.flags.writeable and t.markers == ("A",) and t.rate == 60.0


def test_select():
    t = read_trajectory(HORSE)
    s = t.select(["HFL", "Head"])
    assert s.markers == ("HFL", "Head")
    np.testing.assert_array_equal(s.positions[:, 1], t.positions[:, 0])
    with pytest.raises(InputError) as info:
        t.select(["Head", "Tail"])
    assert "'Tail' not found; available: Head, Withers, Sacrum, HFL, HFR, HHL, HHR" in str(
        info.value
    )


def test_window():
    t = read_trajectory(HORSE)
    w = t.window(60, 113)
    assert w.n_frames == 53 and w.start_time == pytest.approx(1.0)
    np.testing.assert_array_equal(w.positions, t.positions[60:113])
    assert t.window(-10).n_frames == 10 and t.window(None, 5).n_frames == 5
    assert t.window(-10).times[0] == pytest.approx(590 / 60)
    for bad in [(10, 10), (700, None), (0, 601), (5, 2)]:
        with pytest.raises(InputError):
            t.window(*bad)


def test_resample_linear_motion_is_exact_and_keeps_gaps():
    rate, n = 60.0, 61
    times = np.arange(n) / rate
    pos = np.stack([times * 2.0 + 1.0, -3.0 * times, np.full(n, 0.5)], axis=-1)[:, None, :]
    mask = np.ones((n, 1), bool)
    mask[30] = False
    pos = np.where(mask[..., None], pos, np.nan)
    t = Trajectory(pos, mask, ("A",), rate, start_time=2.0)
    for new_rate in (120.0, 100.0, 25.0, 7.0):
        r = t.resample(new_rate)
        assert r.rate == new_rate and r.start_time == 2.0
        assert r.n_frames == int(np.floor(1.0 * new_rate + 1e-9)) + 1
        s = r.times - 2.0
        expected = np.stack([s * 2.0 + 1.0, -3.0 * s, np.full(len(s), 0.5)], axis=-1)
        near_gap = np.abs(s - 0.5) < 1 / rate - 1e-12  # within one old step of the gap
        np.testing.assert_array_equal(r.mask[:, 0], ~near_gap)
        np.testing.assert_allclose(r.positions[~near_gap, 0], expected[~near_gap], atol=1e-12)
    up = t.resample(120.0)
    assert up.mask[:, 0].tolist().count(False) == 3  # the gap frame and both half-steps
    assert t.resample(60.0).positions.tobytes() == t.positions.tobytes()
    with pytest.raises(InputError):
        t.resample(-1)


def test_with_positions():
    t = synthetic()
    moved = t.with_positions(t.positions + 1.0)
    np.testing.assert_array_equal(moved.mask, t.mask)
    assert moved.rate == t.rate and moved.markers == t.markers


def test_cut_after_a_separator_is_reported(tmp_path):
    p = tmp_path / "cut.csv"
    p.write_text("Time,AX,AY\n0,1,2\n0.5,1,")  # no line break: the file was cut
    assert "line 3" in error_of(p, strict=True) and "truncated" in error_of(p, strict=True)
    p.write_text("Time,AX,AY\n0,1,2\n0.5,1,\n")  # complete row with a blank field: a gap
    assert read_trajectory(p).mask.tolist() == [[True], [False]]


def test_failed_write_leaves_nothing_behind(tmp_path, monkeypatch):
    import activebonds.atomic as atomic

    target = tmp_path / "t.npz"
    target.write_bytes(b"previous")

    def broken_replace(src, dst):
        raise OSError(28, "No space left on device")

    monkeypatch.setattr(atomic.os, "replace", broken_replace)
    with pytest.raises(InputError, match="No space left on device"):
        write_trajectory(synthetic(), target)
    assert target.read_bytes() == b"previous"
    assert [p.name for p in tmp_path.iterdir()] == ["t.npz"]


def test_c3d_occluded_points_are_zero_filled(tmp_path):
    import warnings

    import c3d

    t = synthetic()
    path = write_trajectory(t, tmp_path / "z.c3d")
    with open(path, "rb") as handle, warnings.catch_warnings():
        warnings.simplefilter("ignore")
        frames = [p.copy() for _, p, _ in c3d.Reader(handle).read_frames()]
    points = np.stack(frames)
    assert (points[~t.mask][:, 3] == -1).all() and (points[~t.mask][:, :3] == 0).all()
    assert (points[t.mask][:, 3] == 0).all()
