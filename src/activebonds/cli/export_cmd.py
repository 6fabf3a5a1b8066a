"""``activebonds export``: a model in another simulator's format (MuJoCo's MJCF)."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer

from ..errors import InputError
from .app import app, fail, out


@app.command()
def export(
    model: Annotated[Path, typer.Argument(help="Model file (TOML).")],
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
    substeps: Annotated[int, typer.Option(min=1, help="Integration steps per frame.")] = 1,
):
    """Write the model for MuJoCo: point masses, gravity, binary spring-dampers (tendons) and
    fixed unary anchors (joint springs); neural, ternary and contact bonds are refused."""
    from ..export import FORMATS, write_mjcf
    from ..model import load_model

    try:
        if fmt not in FORMATS:
            raise InputError("--format", f"expected {' or '.join(FORMATS)}, got '{fmt}'")
        m = load_model(model)
        write_mjcf(m, out_path, rate=rate, substeps=substeps, source=str(model))
    except InputError as e:
        fail(e)
    out.print(
        f"wrote {out_path} (MJCF: {len(m.spec.particle)} point masses; initial velocities in "
        "keyframe 'initial')",
        markup=False,
        highlight=False,
    )
