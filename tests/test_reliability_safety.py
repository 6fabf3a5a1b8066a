"""Safety: nothing is unpickled, run directories appear whole and are not overwritten, and
an output path through ``..`` is written where the system follows it.

* Planted checkpoints (``RUN/checkpoints/gen-000999999.npz`` a raw pickle, ``gen-000999998``
  an .npz holding a pickled object array, ``gen-000999997`` an .npy pickle), each armed to
  create a marker file when unpickled (checked on a twin): resume falls back to the real
  newest checkpoint, gives the uninterrupted result, and no marker ever appears.
* An .npz trajectory with an object array is refused by ``info`` and ``fit`` (one line,
  exit 2, no marker, no run directory).
* ``fit`` with bad data (2 frames, 2-D, gaps everywhere, other markers) leaves no RUN and no hidden ``.RUN.partial-*``; an existing run is
  never replaced without ``--overwrite`` (and with it, nothing is left behind).
* ``--out`` paths containing ``..`` are written where the system follows them (as ``fill`` and
  ``scaffold`` always did); tests/test_output_dotdot.py covers every writing command.
"""

from __future__ import annotations

import io
import json
import os
import pickle
import shutil
import zipfile
from pathlib import Path

import numpy as np
import pytest

import activebonds.identify.driver as driver
from activebonds.errors import InputError
from activebonds.identify import FitSettings
from activebonds.identify.rundir import RunDir
from reliability_runner import (
    EXAMPLES,
    FIT,
    checkpoint_arrays,
    cli,
    cli_many,
    complete_checkpoints,
    copy_run,
    one_line_error,
    reference,
    result_bytes,
    workspace,
)

pytestmark = pytest.mark.timeout(300)

LAST = f"gen-{FIT['generations']:09d}.npz"


class Armed:
    """Unpickling this calls os.mkdir(marker): the marker appears."""

    def __init__(self, marker: Path):
        self.marker = str(marker)

    def __reduce__(self):
        return (os.mkdir, (self.marker,))


def _armed_files(folder: Path, marker: Path, like: dict) -> dict[str, bytes]:
    """Three pickles dressed as checkpoints, all triggering ``marker``."""
    raw = pickle.dumps({"state_generation": 999999, "payload": Armed(marker)})
    arrays = dict(like)
    arrays["state_genes"] = np.array([Armed(marker)], dtype=object)
    arrays["state_generation"] = np.asarray(999998, np.int32)
    buf = io.BytesIO()
    np.savez(buf, **arrays)  # np.savez pickles object arrays
    npy = io.BytesIO()
    np.save(npy, np.array([Armed(marker)], dtype=object), allow_pickle=True)
    return {
        "gen-000999999.npz": raw,
        "gen-000999998.npz": buf.getvalue(),
        "gen-000999997.npz": npy.getvalue(),
    }


def _shapes(arrays: dict) -> dict:
    return {k: arrays[f"state_{k}"].shape for k in ("genes", "sigma", "cost", "local")}


@pytest.mark.slow  # integration scale: in `pytest -m slow` (every landing)
def test_planted_pickles_are_never_unpickled(tmp_path, tmp_path_factory):
    ref = reference(tmp_path_factory)
    older = f"gen-{FIT['generations'] - FIT['checkpoint_every']:09d}.npz"
    like = checkpoint_arrays(ref / "checkpoints" / older)

    # the planted files are armed: unpickling a twin does create its marker
    twin_marker = tmp_path / "twin-fired"
    twins = _armed_files(tmp_path, twin_marker, like)
    pickle.loads(twins["gen-000999999.npz"])
    assert twin_marker.exists()
    twin_marker.rmdir()
    with zipfile.ZipFile(io.BytesIO(twins["gen-000999998.npz"])) as z:
        np.load(io.BytesIO(z.read("state_genes.npy")), allow_pickle=True)
    assert twin_marker.exists()
    twin_marker.rmdir()
    np.load(io.BytesIO(twins["gen-000999997.npz"]), allow_pickle=True)
    assert twin_marker.exists()

    marker = tmp_path / "fired"
    run = copy_run(ref, tmp_path / "run")
    (run / "checkpoints" / LAST).unlink()  # the real newest is now generation 350
    planted = _armed_files(tmp_path, marker, like)
    for name, data in planted.items():
        (run / "checkpoints" / name).write_bytes(data)

    state, _, skipped = RunDir(run).load_checkpoint(_shapes(like))
    assert int(state["generation"]) == FIT["generations"] - FIT["checkpoint_every"]
    assert sorted(s.split(":")[0] for s in skipped) == sorted(planted)
    assert not marker.exists()

    proc = cli("resume", run, cache=workspace(tmp_path_factory)["cache"])
    assert proc.returncode == 0, proc.stderr
    assert result_bytes(run) == result_bytes(ref)
    assert not marker.exists()

    # only the planted files left: a one-line refusal, still nothing unpickled
    alone = tmp_path / "alone"
    shutil.copytree(run, alone)
    for p in (alone / "checkpoints").glob("gen-00000*.npz"):
        p.unlink()
    proc = cli("resume", alone)
    assert proc.returncode == 2 and "no complete checkpoint" in one_line_error(proc)
    assert not marker.exists()


@pytest.mark.slow  # integration scale: in `pytest -m slow` (every landing)
def test_foreign_checkpoint_files_do_not_evict_real_ones(tmp_path, tmp_path_factory):
    ref = reference(tmp_path_factory)
    run = copy_run(ref, tmp_path / "run")
    arrays = checkpoint_arrays(ref / "checkpoints" / LAST)
    for name, data in _armed_files(tmp_path, tmp_path / "fired", arrays).items():
        (run / "checkpoints" / name).write_bytes(data)
    state = {k[6:]: v for k, v in arrays.items() if k.startswith("state_")}
    history = {k[8:]: v for k, v in arrays.items() if k.startswith("history_")}
    RunDir(run).save_checkpoint(state, history)
    assert FIT["generations"] in complete_checkpoints(run)


def test_npz_trajectory_with_an_object_array_is_refused(tmp_path, tmp_path_factory):
    marker = tmp_path / "fired"
    evil = tmp_path / "evil.npz"
    np.savez(
        evil,
        positions=np.array([[[Armed(marker), 0.0, 0.0]]] * 3, dtype=object),
        markers=np.array(["A"], dtype=object),
        rate=60.0,
    )
    with zipfile.ZipFile(evil) as z:  # armed: the archive really holds a pickle
        assert b"mkdir" in z.read("positions.npy")
    run = tmp_path / "RUN"
    info, fit = cli_many(
        [
            ("info", evil),
            ("fit", EXAMPLES / "triangle.toml", evil, "--out", run, "--generations", "2"),
        ],
        workspace(tmp_path_factory)["cache"],
    )
    for proc in (info, fit):
        assert proc.returncode == 2, proc.stderr
        line = one_line_error(proc)
        assert "evil.npz" in line and "pickled" in line, line
    assert not marker.exists()
    assert sorted(p.name for p in tmp_path.iterdir()) == ["evil.npz"]


def _bad_data(tmp_path: Path) -> dict[str, Path]:
    # in metres, said so: each file is refused for its own fault, not doubted for its units
    ws_csv = "# units: m\nFrame#,Time,AX,AY,AZ,BX,BY,BZ,CX,CY,CZ\n"
    files = {
        "two_frames.csv": (ws_csv + "1,0.0,0,0,0,1,0,0,0,1,0\n2,0.1,0,0,0,1,0,0,0,1,0\n").encode(),
        "flat_2d.csv": b"# units: m\nFrame#,Time,AX,AY,BX,BY,CX,CY\n"
        + b"".join(f"{i + 1},{i / 10:.1f},0,0,1,0,0,1\n".encode() for i in range(6)),
        "all_gaps.csv": (
            ws_csv + "".join(f"{i + 1},{i / 10:.1f},,,,,,,,,\n" for i in range(6))
        ).encode(),
        "other_markers.csv": (
            "Frame#,Time,XX,XY,XZ\n" + "".join(f"{i + 1},{i / 10:.1f},0,0,0\n" for i in range(6))
        ).encode(),
    }
    out = {}
    for name, data in files.items():
        path = tmp_path / name
        path.write_bytes(data)
        out[name] = path
    return out


@pytest.mark.slow  # integration scale: in `pytest -m slow` (every landing)
def test_fit_with_bad_data_leaves_no_run_directory(tmp_path, tmp_path_factory):
    files = _bad_data(tmp_path)
    model = tmp_path / "triangle.toml"
    shutil.copyfile(EXAMPLES / "triangle.toml", model)
    before = sorted(p.name for p in tmp_path.iterdir())
    procs = cli_many(
        [
            ("fit", model, path, "--out", tmp_path / f"RUN-{path.stem}", "--generations", "2")
            for path in files.values()
        ],
        workspace(tmp_path_factory)["cache"],
    )
    for name, proc in zip(files, procs, strict=True):
        assert proc.returncode == 2, (name, proc.stdout, proc.stderr)
        line = one_line_error(proc)
        assert name in line or "--frames" in line or "markers" in line, line
    after = sorted(p.name for p in tmp_path.iterdir())
    assert after == before, "a failed fit left something behind"


def test_run_directory_appears_only_when_complete(tmp_path, monkeypatch, tmp_path_factory):
    ws = workspace(tmp_path_factory)

    def failing_render(traj, path):
        raise OSError(28, "No space left on device")

    monkeypatch.setattr(driver, "render_npz", failing_render)
    with pytest.raises(OSError):
        driver.fit(
            ws["base"] / "triangle.toml",
            ws["base"] / "triangle.csv",
            FitSettings(population=8, generations=2),
            out=tmp_path / "RUN",
        )
    assert sorted(p.name for p in tmp_path.iterdir()) == []


def _tree(folder: Path) -> list:
    return sorted(
        (str(p.relative_to(folder)), p.read_bytes()) for p in folder.rglob("*") if p.is_file()
    )


@pytest.mark.slow  # integration scale: in `pytest -m slow` (every landing)
def test_an_existing_run_is_only_replaced_with_overwrite(tmp_path, tmp_path_factory):
    ws = workspace(tmp_path_factory)
    run = copy_run(reference(tmp_path_factory), tmp_path / "RUN")
    before = _tree(run)
    args = ("fit", ws["base"] / "triangle.toml", ws["base"] / "triangle.csv", "--out", run)
    args += ("--population", "30", "--generations", "3", "--seed", "5")  # compiled already
    proc = cli(*args, cache=ws["cache"])
    assert proc.returncode == 2 and "--overwrite" in one_line_error(proc)
    assert _tree(run) == before
    proc = cli(*args, "--overwrite", cache=ws["cache"])
    assert proc.returncode == 0, proc.stderr
    meta = json.loads((run / "run.json").read_text())
    assert meta["settings"]["generations"] == 3 and meta["seed"] == 5
    assert sorted(p.name for p in tmp_path.iterdir()) == ["RUN"]  # no .RUN.old-*/.partial-*


@pytest.mark.parametrize("kind", ["folder", "file"])
def test_overwrite_only_replaces_a_run_directory(tmp_path, kind):
    target = tmp_path / "thesis"
    if kind == "folder":
        target.mkdir()
        (target / "chapter1.tex").write_text("precious")
    else:
        target.write_text("precious")
    meta = {"format": RunDir.FORMAT}
    with pytest.raises(InputError):
        RunDir.create(target, {"model.toml": b""}, meta, overwrite=True)
    assert (target / "chapter1.tex" if kind == "folder" else target).read_text() == "precious"


@pytest.mark.slow  # a fit in a fresh process (23 s); tests/test_output_dotdot.py fits in-process
def test_fit_out_with_dotdot_is_written_where_the_system_follows_it(tmp_path, tmp_path_factory):
    ws = workspace(tmp_path_factory)
    (tmp_path / "sub").mkdir()
    (fit,) = cli_many(
        [
            (
                *("fit", ws["base"] / "triangle.toml", ws["base"] / "triangle.csv"),
                *("--out", "sub/../RUN", "--generations", "2", {"cwd": tmp_path}),
            )
        ],
        ws["cache"],
    )
    assert fit.returncode == 0, fit.stderr
    assert sorted(p.name for p in tmp_path.iterdir()) == ["RUN", "sub"]
    assert (tmp_path / "RUN" / "run.json").is_file()
    assert list((tmp_path / "sub").iterdir()) == []


def test_simulate_out_with_dotdot_is_written_where_the_system_follows_it(
    tmp_path, tmp_path_factory
):
    (tmp_path / "sub").mkdir()
    (proc,) = cli_many(
        [
            (
                *("simulate", EXAMPLES / "triangle.toml", "--n-frames", "3", "--rate", "60"),
                *("--out", "sub/../x.csv", {"cwd": tmp_path}),
            )
        ],
        workspace(tmp_path_factory)["cache"],
    )
    assert proc.returncode == 0, proc.stderr
    assert sorted(p.name for p in tmp_path.iterdir()) == ["sub", "x.csv"]


@pytest.mark.slow  # integration scale: in `pytest -m slow` (every landing)
def test_best_model_has_the_permissions_of_the_other_run_files(tmp_path_factory):
    run = reference(tmp_path_factory)
    modes = {p.name: p.stat().st_mode & 0o777 for p in run.iterdir() if p.is_file()}
    assert modes["best_model.toml"] == modes["history.csv"], modes
