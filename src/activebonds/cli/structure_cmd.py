"""``activebonds structure``: which optional bonds a recording needs (structure identification)."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Annotated

import typer
from rich.table import Table

from ..errors import InputError
from .app import app, fail, out, parse_option_frames
from .arguments import check_order
from .shared_options import AsJson, Frames, ModelMarkers, Overwrite, Recording


@app.command()
def structure(
    model: Annotated[Path, typer.Argument(help="Model file (TOML) with optional bonds.")],
    traj: Recording,
    out_file: Annotated[
        Path, typer.Option("--out", help="The identified model file to write (TOML).")
    ],
    markers: ModelMarkers = None,
    frames: Frames = "0:",
    smooth: Annotated[
        int, typer.Option(help="Savitzky-Golay window (frames) applied to the data first; 0: off.")
    ] = 0,
    overwrite: Overwrite = False,
    as_json: AsJson = False,
):
    """Decide which optional bonds are present: backward elimination under the BIC on the
    exact one-step least squares. Writes every candidate with present = true or false and the
    linear parameters at their optimum; prints each decision with its evidence."""
    from ..data import read_trajectory
    from ..data.smoothing import check_window
    from ..identify.discover.structure import structure_of
    from ..identify.settings import parse_frames, parse_markers
    from ..model import load_model, save_model
    from .options import settings_from_options

    try:
        check_order("structure", model, [traj])
        if out_file.exists() and not overwrite:
            raise InputError(out_file, "exists; pass --overwrite to replace it")
        if smooth:
            try:
                check_window(smooth)
            except ValueError as e:
                raise InputError("--smooth", str(e)) from None
        settings = settings_from_options(
            markers=parse_markers(markers),
            frames=parse_option_frames(frames, parse_frames),
        )
        m = load_model(model)  # the model file's errors first
        recording = read_trajectory(traj)
        try:
            result = structure_of(m, recording, settings, smooth)
        except InputError as e:  # name the model file, not the model's name
            raise InputError(model, e.message) from None
        save_model(result.spec, out_file)
    except InputError as e:
        fail(e)
    record = {"written": str(out_file), **result.record()}
    if as_json:
        print(json.dumps(record, indent=2))
        return
    table = Table(title=f"{model} on {traj}: optional bonds (BIC, exact least squares)")
    for col in ("bond", "decision", "BIC without - with", "RSS without / with - 1"):
        table.add_column(col, justify="left" if col in ("bond", "decision") else "right")
    for d in result.decisions:
        table.add_row(
            f"[{d.bond}] {d.label}",
            "present" if d.present else "absent",
            f"{d.delta_bic:.4g}",
            f"{d.cost_change:+.3g}",
        )
    out.print(table)
    out.print(
        f"one-step RMS {result.rms_mm:.6g} mm (every candidate: {result.full_rms_mm:.6g} mm, "
        f"zero force: {result.zero_force_rms_mm:.6g} mm); "
        f"{sum(d.present for d in result.decisions)} of {len(result.decisions)} present; "
        f"written to {out_file}"
    )
