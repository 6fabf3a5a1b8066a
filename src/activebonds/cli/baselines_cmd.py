"""``activebonds baselines``: what any fit of a model to a recording is judged against."""

from __future__ import annotations

import json

from rich.table import Table

from ..errors import InputError
from .app import app, fail, out, parse_option_frames
from .arguments import check_order
from .shared_options import AsJson, Bonds, Frames, ModelFile, ModelMarkers, Recording


@app.command()
def baselines(
    model: ModelFile,
    traj: Recording,
    markers: ModelMarkers = None,
    frames: Frames = "0:",
    bonds: Bonds = "model",
    as_json: AsJson = False,
):
    """One-step RMS errors (mm) on the frames: the zero-force (constant-velocity) predictor,
    the momentum floor of internal-force models, and the exact bounded least-squares optimum of
    the model's linear parameters (neural gains at 0)."""
    from ..data import read_trajectory
    from ..identify.costs.windows import make_windows, neighbours_of
    from ..identify.judge.baselines import model_floor_rms_mm, zero_force_rms_mm
    from ..identify.problem import select_data, variant
    from ..identify.settings import parse_frames, parse_markers
    from ..identify.solvers.lsq import least_squares
    from ..model import load_model
    from .options import settings_from_options

    try:
        check_order("baselines", model, [traj])
        settings = settings_from_options(
            markers=parse_markers(markers),
            frames=parse_option_frames(frames, parse_frames),
            bonds=bonds,
        )
        m = variant(load_model(model), settings.bonds)
        data = select_data(m, read_trajectory(traj), settings)
        windows = make_windows(data.positions, data.mask, data.dt, 1, 0, neighbours_of(m))
        result = {
            "frames": [settings.frames[0], settings.frames[0] + data.n_frames],
            "zero_force_rms_mm": zero_force_rms_mm(data.positions, data.mask, data.dt),
            "momentum_floor_mm": model_floor_rms_mm(m, data.positions, data.mask, data.dt),
        }
        try:
            lsq = least_squares(m, windows)
            result["least_squares_rms_mm"] = lsq.rms_mm
            result["least_squares_exact"] = lsq.exact
            result["least_squares"] = {m.layout.genes[g].name: v for g, v in lsq.values.items()}
        except InputError as e:
            result["least_squares_rms_mm"] = None
            result["least_squares_why_not"] = e.message
    except InputError as e:
        fail(e)
    if as_json:
        print(json.dumps(result, indent=2))
        return
    a, b = result["frames"]
    table = Table(title=f"{model} on {traj}, frames {a}:{b} (one-step RMS error)")
    table.add_column("reference")
    table.add_column("mm", justify="right")
    table.add_row("zero force (constant velocity)", f"{result['zero_force_rms_mm']:.6g}")
    floor = result["momentum_floor_mm"]
    table.add_row(
        "momentum floor (internal forces)",
        "n/a (external forces)" if floor is None else f"{floor:.6g}",
    )
    lsq_rms = result["least_squares_rms_mm"]
    table.add_row(
        "exact least squares (linear parameters)",
        result.get("least_squares_why_not", "") if lsq_rms is None else f"{lsq_rms:.6g}",
    )
    out.print(table)
    from ..model.names import labeller

    label = labeller(m.spec)
    for name, value in result.get("least_squares", {}).items():  # keys in JSON, words here
        out.print(f"  {label(name)} = {value:.6g}", markup=False)
