"""``activebonds export``: a model in another simulator's format (MuJoCo's MJCF)."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer

from ..errors import InputError
from .app import app, fail, out
from .arguments import check_order
from .shared_options import ModelFile, Substeps


@app.command()
def export(
    model: ModelFile,
    fmt: Annotated[str, typer.Option("--format", help="Output format: mjcf (MuJoCo XML).")] = (
        "mjcf"
    ),
    out_path: Annotated[Path, typer.Option("--out", help="File to write (e.g. model.xml).")] = ...,
    rate: Annotated[
        float | None,
        typer.Option(
            help="Frame rate in Hz: MuJoCo's timestep is 1 / (rate x substeps), stepping as "
            "'simulate --rate --substeps' does (default: MuJoCo's 2 ms)."
        ),
    ] = None,
    substeps: Substeps = 1,
    start: Annotated[
        Path | None,
        typer.Option(
            "--from",
            help="Start from this recording: the positions at --frame and the velocity from "
            "which the model's step lands on the next frame (the forward difference where none "
            "does; the command says which), instead of the model file's.",
        ),
    ] = None,
    frame: Annotated[int, typer.Option(help="The frame of --from to start at.")] = 0,
):
    """Write the model for MuJoCo: point masses, gravity, binary spring-dampers (tendons),
    fixed unary anchors (joint springs) and ground contacts (a plane, a sphere per particle
    and a contact pair matching the bond's stiffness, damping and friction); neural and
    ternary bonds and contacts with a moving surface are refused. The
    start is the model file's positions and velocities, or --from a recording's --frame."""
    from ..export import FORMATS, write_mjcf
    from ..model import load_model

    notes: list[str] = []
    try:
        check_order("export", model)
        if fmt not in FORMATS:
            raise InputError("--format", f"expected {' or '.join(FORMATS)}, got '{fmt}'")
        m = load_model(model)
        if start is not None:
            from ..data import read_trajectory
            from ..simulation import start_at

            recording = read_trajectory(start)
            missing = [k for k in m.markers if k not in recording.markers]
            if missing:
                raise InputError(
                    start,
                    f"has no marker {missing[0]!r} of the model; it has: "
                    f"{', '.join(recording.markers)}",
                )
            if recording.dimension != m.dimension:
                raise InputError(
                    start, f"is {recording.dimension}D but the model is {m.dimension}D"
                )
            m = start_at(m, recording, frame, substeps, where="--frame", notes=notes)
        elif frame != 0:
            raise InputError("--frame", "needs --from TRAJ (the recording to start from)")
        write_mjcf(m, out_path, rate=rate, substeps=substeps, source=str(model))
    except InputError as e:
        fail(e)
    out.print(
        f"wrote {out_path} (MJCF: {len(m.spec.particle)} point masses; initial velocities in "
        "keyframe 'initial')",
        markup=False,
        highlight=False,
    )
    for note in notes:
        out.print(note, markup=False, highlight=False)
