"""``activebonds scaffold``: a candidate model written from a recording, for ``structure``."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer

from ..errors import InputError
from .app import app, fail, out, parse_option_frames
from .shared_options import AllMarkers, Frames, Gravity, Overwrite, Recording, TotalMass, Up


@app.command()
def scaffold(
    traj: Recording,
    out_file: Annotated[
        Path, typer.Option("--out", help="The candidate model file to write (TOML).")
    ] = Path("model.toml"),
    markers: AllMarkers = None,
    frames: Frames = "0:",
    total_mass: TotalMass = None,
    up: Up = None,
    gravity: Gravity = None,
    neighbours: Annotated[
        int | None,
        typer.Option(help="Nearest neighbours bonded per marker (default 4 in 3D, 3 in 2D)."),
    ] = None,
    neural: Annotated[
        Path | None,
        typer.Option(
            help="Instead: the present bonds of this structure result (FOUND.toml) as "
            "mechanical-neural bonds, the absent ones dropped."
        ),
    ] = None,
    overwrite: Overwrite = False,
):
    """Write a candidate model of a recording: a particle per marker, candidate springs
    (near-rigid pairs, nearest neighbours, Delaunay edges; every one optional for 'structure'), gravity and
    ground contacts where the vertical is confident; every number with a comment saying
    where it came from."""
    from ..atomic import write_text_atomic
    from ..data import read_trajectory
    from ..identify.discover.scaffold import neural_text, scaffold
    from ..identify.settings import parse_frames, parse_markers
    from ..model import loads_model

    try:
        if out_file.exists() and not overwrite:
            raise InputError(out_file, "exists; pass --overwrite to replace it")
        if not out_file.parent.exists():
            raise InputError(out_file, "the folder does not exist")
        if neural is not None:
            text = neural_text(neural, read_trajectory(traj))
            loads_model(text, str(out_file))
            write_text_atomic(out_file, text)
            out.print(f"wrote {out_file} (the present bonds of {neural}, neural)", markup=False)
            return
        window = parse_option_frames(frames, parse_frames)
        names = parse_markers(markers)
        recording = read_trajectory(traj)
        found = scaffold(
            recording,
            markers=list(names) if names else None,
            frames=window,
            total_mass=total_mass,
            up=up,
            gravity=gravity,
            neighbours=neighbours,
            name=traj.stem,
        )
        loads_model(found.text, str(out_file))  # it loads, or nothing is written
        write_text_atomic(out_file, found.text)
    except InputError as e:
        fail(e)
    for note in found.notes:
        out.print(note, markup=False, highlight=False)
    same = (f" --frames {frames}" if frames.strip() not in ("", "0:") else "") + (
        f" --markers {markers}" if markers else ""
    )  # the next command reads the frames and markers the scaffold was made of
    out.print(
        f"wrote {out_file}: {found.particles} particles, {found.bonds} candidate springs "
        f"(optional), {found.contacts} ground contacts, gravity {found.gravity}; next: "
        f"activebonds structure {out_file} {traj}{same} --out found.toml",
        markup=False,
        highlight=False,
    )
