"""Real lab files (issue 15, items 1-3): OpenSim TRC with space or double-tab headers,
CSV and TRC files cut short by an interrupted export, and MATLAB .mat exports (Qualisys
QTM layout, v5 through scipy and v7.3 through h5py).

Every file is made by the tests in ``tmp_path`` from known arrays and read back; the
numbers are compared with those arrays (or with the same data in a plain tab TRC).
"""

from __future__ import annotations

import warnings

import h5py
import numpy as np
import pytest
import scipy.io

from activebonds.data import read_trajectory
from activebonds.data.readers import TruncatedRowWarning
from activebonds.errors import InputError
from helpers import cli

MARKERS = ("R.ASIS", "L.ASIS", "Head")


def recording(frames: int = 100, seed: int = 3) -> tuple[np.ndarray, np.ndarray]:
    """Positions in mm [frames, 3, 3] rounded to 5 decimals, and the presence mask."""
    rng = np.random.default_rng(seed)
    mm = np.round(rng.normal(500.0, 200.0, size=(frames, len(MARKERS), 3)), 5)
    mask = np.ones((frames, len(MARKERS)), dtype=bool)
    mask[3, 1] = mask[4, 1] = mask[frames - 2, 2] = False
    return mm, mask


def error_of(path, **kwargs) -> str:
    with pytest.raises(InputError) as info:
        read_trajectory(path, **kwargs)
    text = str(info.value)
    assert "\n" not in text and path.name in text
    return text


# ----------------------------------------------------------------------------- TRC layouts
def trc_text(
    mm, mask, header_sep="\t", data_sep="\t", num_frames=None, rate=100.0, names=MARKERS
) -> str:
    """An OpenSim TRC: header lines joined with ``header_sep``, data rows with ``data_sep``
    (a missing sample is blank fields with tabs, ``nan`` with spaces)."""
    frames = len(mm)
    h = header_sep
    keys = ["DataRate", "CameraRate", "NumFrames", "NumMarkers", "Units", "OrigDataRate"]
    values = [f"{rate:.2f}", f"{rate:.2f}", num_frames or str(frames), str(len(names)), "mm"]
    values.append(f"{rate:.2f}")
    name_fields = [f for n in names for f in (n, "", "")] if h == "\t" else list(names)
    axes = [f"{a}{k + 1}" for k in range(len(names)) for a in "XYZ"]
    lines = [
        h.join(["PathFileType", "4", "(X/Y/Z)", "walk.trc"]),
        h.join(keys),
        h.join(values),
        h.join(["Frame#", "Time", *name_fields]),
        h.join(["", "", *axes]) if h == "\t" else "            " + h.join(axes),
        "",
    ]
    blank = "" if "\t" in data_sep else "nan"
    for f in range(frames):
        fields = [str(f + 1), f"{f / rate:.6f}"]
        for m in range(len(names)):
            fields += [f"{v:.5f}" if mask[f, m] else blank for v in mm[f, m]]
        lines.append(data_sep.join(fields))
    return "\n".join(lines) + "\n"


def assert_same(a, b):
    assert a.markers == b.markers and a.positions.shape == b.positions.shape
    np.testing.assert_array_equal(a.mask, b.mask)
    np.testing.assert_array_equal(a.positions, b.positions)  # same numbers: same doubles
    assert a.rate == b.rate and a.start_time == b.start_time and a.source_units == "mm"


def test_trc_with_space_or_double_tab_headers_reads_like_the_tab_file(tmp_path):
    mm, mask = recording()
    tab = tmp_path / "tab.trc"
    tab.write_text(trc_text(mm, mask))
    reference = read_trajectory(tab)
    assert reference.markers == MARKERS and reference.n_frames == 100
    np.testing.assert_allclose(reference.positions[mask], mm[mask] / 1000, rtol=1e-15)
    assert not reference.mask[3, 1] and np.isnan(reference.positions[3, 1]).all()

    spaces = tmp_path / "spaces.trc"  # space separated headers and rows, gaps as nan
    spaces.write_text(trc_text(mm, mask, header_sep=" ", data_sep=" "))
    assert_same(read_trajectory(spaces), reference)

    doubled = tmp_path / "double_tab.trc"  # a common export: double tabs, NumFrames "100.0"
    doubled.write_text(trc_text(mm, mask, header_sep="\t\t", num_frames="100.0"))
    assert_same(read_trajectory(doubled), reference)

    mixed = tmp_path / "mixed.trc"  # keys double-tabbed, values single-tabbed
    lines = trc_text(mm, mask).split("\n")
    lines[1] = lines[1].replace("\t", "\t\t")
    mixed.write_text("\n".join(lines))
    assert_same(read_trajectory(mixed), reference)

    rows = tmp_path / "double_tab_rows.trc"  # data rows double-tabbed too (no blank gaps)
    full = np.ones_like(mask)
    rows.write_text(trc_text(mm, full, header_sep="\t\t", data_sep="\t\t", num_frames="100.0"))
    tab.write_text(trc_text(mm, full))
    assert_same(read_trajectory(rows), read_trajectory(tab))


def test_trc_header_messages_name_what_is_wrong(tmp_path):
    mm, mask = recording(frames=5)
    p = tmp_path / "h.trc"
    p.write_text(trc_text(mm, mask, header_sep=" ", num_frames="5.5"))
    assert "NumFrames '5.5' is not a whole number" in error_of(p)
    p.write_text(trc_text(mm, mask, header_sep=" ", num_frames="6.0"))
    assert "NumFrames 6 but the file has 5 data rows" in error_of(p)
    text = trc_text(mm, mask, header_sep=" ")
    p.write_text("Hello " + text)
    assert "expected 'PathFileType' first, found 'Hello'" in error_of(p)
    p.write_text(text.replace("Frame#", "Nr"))
    assert "line 4: expected the columns Frame#, Time" in error_of(p)
    p.write_text(text.replace("Head", "Head Top"))  # spaces without tabs: 4 words
    assert "line 4: line names 4 markers but NumMarkers is 3" in error_of(p)
    lines = text.split("\n")
    lines[2] = lines[2].rsplit(" ", 2)[0]  # Units and OrigDataRate have no value
    p.write_text("\n".join(lines))
    assert "line 3: header key Units has no value (line 2 has 6 keys, line 3 has 4" in error_of(p)
    # with tabs, a name may hold a space
    p.write_text(trc_text(mm, mask, names=("R.ASIS", "L.ASIS", "Head Top")))
    assert read_trajectory(p).markers == ("R.ASIS", "L.ASIS", "Head Top")


# ----------------------------------------------------------------------------- cut files
def csv_text(mm, mask, rate=100.0) -> str:
    header = ",".join(["Frame#", "Time"] + [f"{n}{a}" for n in MARKERS for a in "XYZ"])
    lines = [header]
    for f in range(len(mm)):
        fields = [str(f + 1), f"{f / rate:.3f}"]
        for m in range(len(MARKERS)):
            fields += [f"{v:.5f}" if mask[f, m] else "" for v in mm[f, m]]
        lines.append(",".join(fields))
    return "\n".join(lines) + "\n"


def read_warned(path, **kwargs):
    """Read a file that must give exactly one TruncatedRowWarning; (trajectory, message)."""
    with pytest.warns(TruncatedRowWarning) as record:
        traj = read_trajectory(path, **kwargs)
    assert len(record) == 1
    message = str(record[0].message)
    assert "\n" not in message and path.name in message
    return traj, message


def assert_first_frames(cut, full, n):
    assert cut.n_frames == n and cut.markers == full.markers and cut.rate == full.rate
    np.testing.assert_array_equal(cut.mask, full.mask[:n])
    np.testing.assert_array_equal(cut.positions, full.positions[:n])


@pytest.mark.parametrize("fmt", ["csv", "trc"])
def test_truncated_last_row_is_dropped_with_one_warning(tmp_path, fmt):
    mm, mask = recording(frames=20)
    text = csv_text(mm, mask) if fmt == "csv" else trc_text(mm, mask)
    first_data_line = 2 if fmt == "csv" else 7  # the TRC has 5 header lines and a blank one
    last = first_data_line + 19  # line number of frame 20
    whole = tmp_path / f"whole.{fmt}"
    whole.write_text(text)
    full = read_trajectory(whole)  # no warning: warnings are errors here
    assert full.n_frames == 20

    cut = tmp_path / f"cut.{fmt}"
    row = text.rstrip("\n").rsplit("\n", 1)[1]
    cut.write_text(text.rstrip("\n")[: -len(row) // 2])  # cut inside frame 20
    traj, message = read_warned(cut)
    assert f"line {last}:" in message and "fields" in message and "read the 19 rows" in message
    assert_first_frames(traj, full, 19)  # TRC: NumFrames 20 = rows + 1 is accepted
    text_error = error_of(cut, strict=True)
    assert f"line {last}:" in text_error and "truncated" in text_error

    cut.write_text(text.rstrip("\n")[:-3])  # cut mid-number: "...123.45" for "...123.45678"
    traj, message = read_warned(cut)
    assert f"line {last}:" in message and "where the rows before write its column like" in message
    assert_first_frames(traj, full, 19)
    assert f"line {last}:" in error_of(cut, strict=True)

    cut.write_text(text.rstrip("\n"))  # complete, only the final line break is missing
    assert_first_frames(read_trajectory(cut), full, 20)

    lines = text.split("\n")
    lines[first_data_line + 4] = lines[first_data_line + 4][:30]  # a short row in the middle
    cut.write_text("\n".join(lines))
    message = error_of(cut)
    assert f"line {first_data_line + 5}:" in message and "truncated" in message


def test_truncated_trc_row_count_and_only_row(tmp_path):
    mm, mask = recording(frames=6)
    p = tmp_path / "cut.trc"
    text = trc_text(mm, mask, num_frames="9")
    p.write_text(text[:-40])
    assert (
        "NumFrames 9 but the file has 5 complete data rows and an incomplete last row (line 12"
        in (error_of(p))
    )
    p.write_text(trc_text(mm, mask, num_frames="5")[:-40])  # NumFrames = the complete rows
    assert read_warned(p)[0].n_frames == 5
    one = tmp_path / "one.csv"
    one.write_text(csv_text(mm[:1], mask[:1])[:-20])
    assert "line 2: the only data row has only" in error_of(one)


def test_cli_warns_in_one_line_and_strict_refuses(tmp_path):
    mm, mask = recording(frames=20)
    p = tmp_path / "cut.csv"
    p.write_text(csv_text(mm, mask)[:-50])
    proc = cli("info", p, "--json")
    assert proc.returncode == 0, proc.stderr
    assert proc.stderr.startswith("warning: ") and proc.stderr.count("\n") == 1
    assert f"{p}: line 21: last row has only" in proc.stderr
    assert '"frames": 19' in proc.stdout
    proc = cli("info", "--strict", p)
    assert proc.returncode == 2 and proc.stdout == ""
    assert proc.stderr.startswith(f"error: {p}: line 21: ") and proc.stderr.count("\n") == 1


# ----------------------------------------------------------------------------- MATLAB
def qtm_arrays(frames=7, seed=5):
    """QTM's Data [markers, 4, frames] in mm with a NaN gap and a negative residual."""
    rng = np.random.default_rng(seed)
    data = np.empty((len(MARKERS), 4, frames))
    data[:, :3, :] = rng.normal(300.0, 100.0, size=(len(MARKERS), 3, frames))
    data[:, 3, :] = rng.uniform(0.2, 2.0, size=(len(MARKERS), frames))
    data[1, :, 2:4] = np.nan  # a gap as QTM writes it
    data[2, 3, 5] = -1.0  # flagged invalid
    mask = np.ones((frames, len(MARKERS)), dtype=bool)
    mask[2:4, 1] = mask[5, 2] = False
    return data, mask


def qtm_struct(data, labels=MARKERS, rate=120.0, start=11):
    trajectories = {"Labeled": {"Count": float(len(labels)), "Labels": list(labels), "Data": data}}
    return {
        "File": "walk01.qtm",
        "FrameRate": rate,
        "StartFrame": start,
        "Trajectories": trajectories,
    }


def _cell(names):
    cell = np.empty((1, len(names)), dtype=object)
    cell[0, :] = [np.array([n]) for n in names]
    return cell


def write_v5(path, variables):
    def convert(value):
        if isinstance(value, dict):
            return {k: convert(v) for k, v in value.items()}
        return _cell(value) if isinstance(value, list) else value

    scipy.io.savemat(path, {k: convert(v) for k, v in variables.items()})


def _h5_write(group, name, value, refs):
    """One MATLAB value as MATLAB v7.3 stores it: transposed, strings as uint16 chars."""
    if isinstance(value, dict):
        sub = group.create_group(name)
        sub.attrs["MATLAB_class"] = np.bytes_("struct")
        for key, item in value.items():
            _h5_write(sub, key, item, refs)
        return
    if isinstance(value, str | list):
        strings = [value] if isinstance(value, str) else value
        targets = []
        for s in strings:
            codes = np.frombuffer(s.encode("utf-16-le"), dtype="<u2")
            char = refs.create_dataset(f"{len(refs)}", data=codes.reshape(-1, 1))  # 1 x L
            char.attrs["MATLAB_class"] = np.bytes_("char")
            char.attrs["MATLAB_int_decode"] = np.int32(2)
            targets.append(char)
        if isinstance(value, str):
            group.move(targets[0].name, f"{group.name}/{name}")
            return
        cell = np.empty((len(strings), 1), dtype=h5py.ref_dtype)  # a 1 x N cell, transposed
        for k, char in enumerate(targets):
            cell[k, 0] = char.ref
        dataset = group.create_dataset(name, data=cell)
        dataset.attrs["MATLAB_class"] = np.bytes_("cell")
        return
    array = np.asarray(value, dtype=np.float64)
    array = array.reshape(1, 1) if array.ndim == 0 else array
    dataset = group.create_dataset(name, data=array.T)  # column-major: reversed axes
    dataset.attrs["MATLAB_class"] = np.bytes_("double")


def write_v73(path, variables):
    """A MATLAB v7.3 MAT file: HDF5 behind MATLAB's 512-byte header (userblock)."""
    with h5py.File(path, "w", userblock_size=512) as f:
        refs = f.create_group("#refs#")
        for key, value in variables.items():
            _h5_write(f, key, value, refs)
    text = b"MATLAB 7.3 MAT-file, Platform: GLNXA64, Created on: Mon Jan  1 00:00:00 2024 "
    header = (text + b"HDF5 schema 1.00 .").ljust(116) + bytes(8) + b"\x00\x02IM"
    with open(path, "r+b") as handle:
        handle.write(header.ljust(512, b"\x00"))


WRITERS = {"v5": write_v5, "v7.3": write_v73}


@pytest.mark.parametrize("version", ["v5", "v7.3"])
def test_mat_qtm_export(tmp_path, version):
    data, mask = qtm_arrays()
    p = tmp_path / "walk01.mat"
    WRITERS[version](p, {"walk01": qtm_struct(data)})
    if version == "v7.3":
        with pytest.raises(NotImplementedError):
            scipy.io.loadmat(p)  # the reader switches to h5py
    t = read_trajectory(p)
    assert t.markers == MARKERS and t.rate == 120.0 and t.source_units == "mm"
    assert t.start_time == pytest.approx(10 / 120.0, abs=1e-15)  # StartFrame 11
    np.testing.assert_array_equal(t.mask, mask)
    expected = data[:, :3, :].transpose(2, 0, 1) / 1000.0
    np.testing.assert_array_equal(t.positions[mask], expected[mask])
    assert np.isnan(t.positions[~mask]).all()
    assert read_trajectory(p, units="m").positions[0, 0, 0] == data[0, 0, 0]
    assert read_trajectory(p, rate=120.5).rate == 120.5
    assert "sample rate 200 Hz disagrees with walk01.FrameRate (120 Hz)" in error_of(p, rate=200)

    top = tmp_path / "top.mat"  # the struct's fields as top-level variables
    WRITERS[version](top, qtm_struct(data[:1], labels=["Toe"], start=1))
    t = read_trajectory(top)
    assert t.markers == ("Toe",) and t.start_time == 0.0 and t.n_frames == 7
    np.testing.assert_array_equal(t.positions[:, 0], data[0, :3, :].T / 1000.0)


@pytest.mark.parametrize("version", ["v5", "v7.3"])
def test_mat_malformed_files_are_refused_naming_the_field(tmp_path, version):
    data, _ = qtm_arrays()
    write = WRITERS[version]
    p = tmp_path / "walk01.mat"
    field = "walk01.Trajectories.Labeled"

    write(p, {"walk01": {"FrameRate": 100.0, "Other": 1.0}})
    assert "no Trajectories struct (variables: walk01)" in error_of(p)
    write(p, {"walk01": qtm_struct(data[:, :, 0].reshape(3, 2, 2))})
    assert f"{field}.Data: expected [markers, 4, frames] (x, y, z, residual), got size 3x2x2" in (
        error_of(p)
    )
    write(p, {"walk01": qtm_struct(data, labels=["A", "B"])})
    assert f"{field}.Labels: has 2 names but {field}.Data has 3 markers" in error_of(p)
    write(p, {"walk01": qtm_struct(data, labels=["A", "B", "A"])})
    assert f"{field}.Labels: marker name 'A' appears twice" in error_of(p)
    bare = qtm_struct(data)
    del bare["Trajectories"]["Labeled"]["Labels"]
    write(p, {"walk01": bare})
    assert f"{field}.Labels: field is missing" in error_of(p)
    bare = qtm_struct(data)
    del bare["FrameRate"]
    write(p, {"walk01": bare})
    assert "no FrameRate in the file" in error_of(p)
    assert read_trajectory(p, rate=50.0).rate == 50.0
    write(p, {"walk01": qtm_struct(data, rate=-5.0)})
    assert "walk01.FrameRate -5.0 must be a positive finite rate" in error_of(p)
    write(p, {"walk01": qtm_struct(data, rate="fast")})
    assert "walk01.FrameRate: expected a" in error_of(p)
    write(p, {"a": qtm_struct(data), "b": qtm_struct(data)})
    assert "several variables hold a Trajectories struct (a, b)" in error_of(p)
    write(p, {"b": qtm_struct(data), "walk01": qtm_struct(data[:1], labels=["Toe"])})
    assert read_trajectory(p).markers == ("Toe",)  # the one named after the file

    write(p, {"walk01": qtm_struct(data)})
    whole = p.read_bytes()
    p.write_bytes(whole[: len(whole) // 2])  # a cut or corrupt file
    assert "MAT" in error_of(p)
    if version == "v7.3":
        corrupt = bytearray(whole)
        corrupt[512:600] = bytes(88)  # the HDF5 superblock zeroed
        p.write_bytes(bytes(corrupt))
        assert "not a readable MAT v7.3 (HDF5) file" in error_of(p)
    p.write_text("Time,AX,AY\n0,1,2\n")
    assert "not a readable MAT file" in error_of(p)
    p.write_bytes(b"")
    assert "not a readable MAT file" in error_of(p)


def test_mat_reading_raises_nothing_but_input_errors(tmp_path):
    """Byte flips and cuts of both versions: a Trajectory or one InputError, nothing else."""
    data, _ = qtm_arrays()
    rng = np.random.default_rng(11)
    outcomes = {"ok": 0, "error": 0}
    for version, write in WRITERS.items():
        base = tmp_path / f"base_{version}.mat"
        write(base, {"walk01": qtm_struct(data)})
        whole = base.read_bytes()
        for case in range(40):
            b = bytearray(whole)
            if case % 2:
                del b[int(rng.integers(0, len(b))) :]
            else:
                for _ in range(int(rng.integers(1, 6))):
                    b[int(rng.integers(0, len(b)))] = int(rng.integers(256))
            p = tmp_path / "walk01.mat"
            p.write_bytes(bytes(b))
            with warnings.catch_warnings():
                warnings.simplefilter("error")
                try:
                    read_trajectory(p)
                    outcomes["ok"] += 1
                except InputError as exc:
                    assert "\n" not in str(exc) and p.name in str(exc)
                    outcomes["error"] += 1
    assert outcomes["error"] >= 20, outcomes


def test_a_body_in_metres_without_a_units_line_is_doubted_in_one_line(tmp_path, capsys):
    from activebonds.data._common import UnitsWarning

    rows = [f"{i},{i / 100},{0.1 + 0.01 * i},0.2,1.0,0.5,0.3,1.2" for i in range(20)]
    body = "Frame#,Time,AX,AY,AZ,BX,BY,BZ\n" + "\n".join(rows) + "\n"
    doubted = tmp_path / "metres.csv"
    doubted.write_text(body)
    with pytest.warns(UnitsWarning) as record:
        traj = read_trajectory(doubted)
    assert len(record) == 1
    message = str(record[0].message)
    assert message.startswith(f"{doubted}: ") and "'# units: m'" in message
    assert "0.4 mm" in message  # A moves 0.19 units, B sits 0.4 from A: read as millimetres
    assert traj.source_units == "mm"  # still read as the format says
    declared = tmp_path / "declared.csv"
    declared.write_text("# units: mm\n" + body)  # said so: no doubt
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        read_trajectory(declared)
        metres = tmp_path / "m.csv"
        metres.write_text("# units: m\n" + body)
        assert np.nanmax(read_trajectory(metres).positions) == pytest.approx(1.2)
    # the command line prints it as one warning line and goes on
    proc = cli("info", doubted)
    assert proc.returncode == 0
    warned = [line for line in proc.stderr.splitlines() if line.startswith("warning: ")]
    assert len(warned) == 1 and "'# units: m'" in warned[0]
