"""``write_trajectory``: save a :class:`Trajectory` as .csv, .trc, .c3d or .npz.

Every file is rendered in memory, written to a temporary file in the target folder and
moved into place with :func:`os.replace`, so a failed write never leaves a half-written
file.  The target folder must exist.  Formats (all read back by :func:`read_trajectory`):

* ``.csv``: ``# units: mm`` and ``# rate: <Hz>`` comment lines, then
  ``Frame#,Time,<Name>X,<Name>Y[,<Name>Z],...`` in millimetres, numbers written with
  ``repr`` (shortest exact form), missing samples as blank fields.  2-D or 3-D.
* ``.trc``: OpenSim layout (PathFileType, DataRate/CameraRate/NumFrames/NumMarkers/Units
  header, Frame#/Time/names, X1 Y1 Z1 labels, blank line, data) in mm; 3-D only.
* ``.c3d``: float32 points in mm via the ``c3d`` package; missing samples have residual -1
  and zero coordinates.  The start is stored as a frame number, so ``start_time`` is
  rounded to the nearest frame (and negative starts become 0).  3-D, ASCII names, at most
  255 markers.
* ``.npz``: ``positions`` (metres, float64, NaN where missing), ``mask``, ``markers``,
  ``rate``, ``units`` ("m"), ``start_time``; exact.
"""

from __future__ import annotations

import csv
import io
import warnings
from collections.abc import Callable
from pathlib import Path

import numpy as np

from activebonds.atomic import write_atomic
from activebonds.data._common import by_extension, check_output_path
from activebonds.data.read_csv import AXIS_SEPARATORS
from activebonds.data.trajectory import Trajectory
from activebonds.errors import InputError


def _mm_text(traj: Trajectory) -> list[list[str]]:
    """Per frame, the coordinate fields in mm (repr), blank where missing."""
    mm = traj.positions * 1000.0
    rows = []
    for f in range(traj.n_frames):
        fields = []
        for m in range(traj.n_markers):
            if traj.mask[f, m]:
                fields.extend(repr(float(v)) for v in mm[f, m])
            else:
                fields.extend([""] * traj.dimension)
        rows.append(fields)
    return rows


def _require_3d(traj: Trajectory, path: Path, fmt: str) -> None:
    if traj.dimension != 3:
        raise InputError(path, f"{fmt} files hold 3-D points; trajectory is {traj.dimension}-D")


def render_csv(traj: Trajectory, path: Path) -> bytes:
    """Wide CSV in mm with units and rate comments (see the module docstring)."""
    if traj.dimension not in (2, 3):
        raise InputError(
            path, f"CSV files hold 2-D or 3-D points; trajectory is {traj.dimension}-D"
        )
    header = ["Frame#", "Time"]
    for name in traj.markers:
        sep = " " if name[-1] in AXIS_SEPARATORS else ""
        header.extend(f"{name}{sep}{axis}" for axis in "XYZ"[: traj.dimension])
    out = io.StringIO()
    out.write(f"# units: mm\n# rate: {traj.rate!r}\n")
    csv.writer(out, lineterminator="\n").writerow(header)
    times = traj.times
    for f, fields in enumerate(_mm_text(traj)):
        out.write(",".join([str(f + 1), repr(float(times[f]))] + fields) + "\n")
    return out.getvalue().encode("utf-8")


def render_trc(traj: Trajectory, path: Path) -> bytes:
    """OpenSim TRC in mm (see the module docstring)."""
    _require_3d(traj, path, "TRC")
    n, m, rate = traj.n_frames, traj.n_markers, repr(traj.rate)
    lines = [
        f"PathFileType\t4\t(X/Y/Z)\t{path.name}",
        "DataRate\tCameraRate\tNumFrames\tNumMarkers\tUnits\tOrigDataRate\t"
        "OrigDataStartFrame\tOrigNumFrames",
        f"{rate}\t{rate}\t{n}\t{m}\tmm\t{rate}\t1\t{n}",
        "Frame#\tTime\t" + "\t".join(f"{name}\t\t" for name in traj.markers),
        "\t\t" + "\t".join(f"X{k}\tY{k}\tZ{k}" for k in range(1, m + 1)),
        "",
    ]
    times = traj.times
    for f, fields in enumerate(_mm_text(traj)):
        lines.append("\t".join([str(f + 1), repr(float(times[f]))] + fields))
    return ("\n".join(lines) + "\n").encode("utf-8")


def render_npz(traj: Trajectory, path: Path) -> bytes:
    """NumPy archive in metres (exact)."""
    buffer = io.BytesIO()
    np.savez_compressed(
        buffer,
        positions=np.asarray(traj.positions, dtype=np.float64),
        mask=np.asarray(traj.mask, dtype=bool),
        markers=np.array(traj.markers, dtype=str),
        rate=np.float64(traj.rate),
        units=np.array("m"),
        start_time=np.float64(traj.start_time),
    )
    return buffer.getvalue()


def render_c3d(traj: Trajectory, path: Path) -> bytes:
    """C3D with float32 points in mm; missing samples flagged with residual -1."""
    import c3d

    _require_3d(traj, path, "C3D")
    if traj.n_markers > 255:
        raise InputError(
            path, f"C3D files written here hold at most 255 markers, not {traj.n_markers}"
        )
    for name in traj.markers:
        if not name.isascii() or len(name) > 255:
            raise InputError(path, f"marker name {name!r} must be ASCII and at most 255 characters")
    mm = np.where(traj.mask[..., None], traj.positions * 1000.0, 0.0).astype(np.float32)
    if not np.all(np.isfinite(mm)):
        raise InputError(path, "coordinates too large for float32 millimetres")
    first = max(1, int(round(traj.start_time * traj.rate)) + 1)
    empty_analog = np.zeros((0, 0), dtype=np.float32)
    buffer = io.BytesIO()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # the library warns about "no analog data"
        writer = c3d.Writer(point_rate=traj.rate, point_units="mm  ")
        frames = []
        for f in range(traj.n_frames):
            points = np.zeros((traj.n_markers, 5), dtype=np.float32)
            points[:, :3] = mm[f]
            points[~traj.mask[f], 3] = -1.0
            frames.append((points, empty_analog))
        writer.add_frames(frames)
        writer.set_point_labels(list(traj.markers))
        writer.set_start_frame(first)
        writer.write(buffer)
        data_start = (int(writer.header.data_block) - 1) * 512
    # The library leaves the previous frame's coordinates under a residual of -1; zero-fill
    # them as the C3D convention for occluded points says.
    data = bytearray(buffer.getvalue())
    size = traj.n_frames * traj.n_markers * 4
    words = np.frombuffer(data, dtype="<f4", count=size, offset=data_start).copy()
    words = words.reshape(traj.n_frames, traj.n_markers, 4)
    words[~traj.mask, :3] = 0.0
    data[data_start : data_start + 4 * size] = words.tobytes()
    return bytes(data)


def render_mat(traj: Trajectory, path: Path) -> bytes:
    """MATLAB v5 in Qualisys QTM's layout (what :mod:`.read_mat` reads): one struct named
    after the file with ``FrameRate``, ``StartFrame`` and ``Trajectories.Labeled`` (``Data``
    [markers, 4, frames] in mm, NaN and a residual of -1 where missing; ``Labels``)."""
    from scipy.io import savemat

    _require_3d(traj, path, "MAT")
    mm = np.where(traj.mask[..., None], traj.positions * 1000.0, np.nan)  # [F, M, 3]
    data = np.concatenate([mm, np.where(traj.mask, 0.0, -1.0)[..., None]], axis=2)
    labels = np.empty((1, traj.n_markers), dtype=object)
    labels[0, :] = list(traj.markers)
    name = "".join(c if c.isalnum() else "_" for c in path.stem) or "recording"
    if not name[0].isalpha():
        name = "r" + name
    struct = {
        "FrameRate": float(traj.rate),
        "StartFrame": float(round(traj.start_time * traj.rate) + 1),
        "Frames": float(traj.n_frames),
        "Trajectories": {"Labeled": {"Count": float(traj.n_markers), "Labels": labels,
                                     "Data": np.transpose(data, (1, 2, 0))}},
    }  # fmt: skip
    buffer = io.BytesIO()
    savemat(buffer, {name[:63]: struct}, do_compression=True)
    return buffer.getvalue()


WRITERS: dict[str, Callable[[Trajectory, Path], bytes]] = {
    ".csv": render_csv,
    ".trc": render_trc,
    ".c3d": render_c3d,
    ".npz": render_npz,
    ".mat": render_mat,
}


def atomic_write(path: Path, data: bytes) -> None:
    """Write ``data`` atomically (:func:`activebonds.atomic.write_atomic`); OS errors become
    one-line input errors and leave the target untouched."""
    try:
        write_atomic(path, lambda handle: handle.write(data))
    except OSError as exc:
        raise InputError(path, f"cannot write file ({exc.strerror or exc})") from None


def write_trajectory(traj: Trajectory, path: str | Path) -> Path:
    """Write ``traj`` to ``path`` in the format given by its extension; return the path.

    Raises:
        InputError: unknown extension, missing folder, data the format cannot hold, or an
            OS error while writing (the target is then left untouched).
    """
    path = Path(path)
    render = by_extension(WRITERS, path)
    check_output_path(path)
    atomic_write(path, render(traj, path))
    return path
