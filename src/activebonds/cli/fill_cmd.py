"""``activebonds fill``: fill a recording's marker gaps with a model's physics or a lab's
interpolation, and list every sample filled or left."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer

from ..errors import InputError
from .app import app, fail, out, parse_option_frames
from .arguments import check_order

METHODS = ("model", "spline", "linear", "pca")
MAX_STEPS = 200  # identify.fill.MAX_STEPS (not imported here: the command line starts fast)
PRIORS = ("pca",)  # identify.fill.PRIORS


def record_path(out_path: Path) -> Path:
    """The sidecar CSV beside the filled file: ``filled.trc`` -> ``filled.gaps.csv``."""
    return out_path.with_name(out_path.stem + ".gaps.csv")


@app.command()
def fill(
    model: Annotated[
        Path,
        typer.Argument(help="Model file (TOML), e.g. a fit's RUN/best_model.toml."),
    ],
    traj: Annotated[Path, typer.Argument(help="Recorded trajectory with gaps.")],
    out_path: Annotated[
        Path,
        typer.Option(
            "--out", help="File to write (.csv, .trc, .c3d, .npz), every marker and frame."
        ),
    ] = ...,
    method: Annotated[
        str,
        typer.Option(
            help="model (the model's trajectory, fitted to the markers present around the "
            "gap), spline (cubic), linear, or pca (Gløersen & Federolf 2016)."
        ),
    ] = "model",
    markers: Annotated[
        str | None,
        typer.Option(
            help="Markers followed by the particles, in order: A,B,C (default: the model's). "
            "Only their gaps are filled."
        ),
    ] = None,
    frames: Annotated[
        str, typer.Option(help="Frame window START:STOP filled and fitted to.")
    ] = "0:",
    max_gap: Annotated[
        int | None,
        typer.Option(help="Leave gaps longer than this many frames (listed in the record)."),
    ] = None,
    denoise: Annotated[
        bool,
        typer.Option(
            help="With --method model: write the model's smoothed trajectory for every sample "
            "of the model's markers in the window, not only in the gaps."
        ),
    ] = False,
    context: Annotated[
        int,
        typer.Option(
            min=2, help="Frames on each side of a gap that the model's trajectory is fitted to."
        ),
    ] = 30,
    horizon: Annotated[
        int,
        typer.Option(
            min=1,
            help="Frames per shooting window of the model's fit (1: every frame's state free).",
        ),
    ] = 1,
    continuity: Annotated[
        float | None,
        typer.Option(
            help="Weight of the model's continuity defects against the position errors "
            "(default: from how much of the context's accelerations the model explains, "
            "0.3 for a model that explains none to 100 for one that explains them all).",
        ),
    ] = None,
    prior: Annotated[
        str | None,
        typer.Option(
            help="With --method model: pca fits the model's trajectory again with the PCA "
            "fill of the missing samples (its positions and its steps from frame to frame) as "
            "soft observations, weighed by the PCA fill's own error on artificial gaps against "
            "the model's residuals (default: none, the model alone). Helps on gaps of 30 "
            "frames and more, hurts on short ones (docs/EXPERIMENTS.md).",
        ),
    ] = None,
    max_steps: Annotated[
        int,
        typer.Option(
            min=1,
            help="Levenberg-Marquardt steps per fitted stretch, at most (a stretch that stops "
            "there is counted as not converged: raise it).",
        ),
    ] = MAX_STEPS,
    substeps: Annotated[
        int, typer.Option(min=1, help="Integration substeps per frame (as the model was fitted).")
    ] = 1,
    integrator: Annotated[
        str, typer.Option(help="euler or verlet (as the model was fitted).")
    ] = "euler",
    record: Annotated[
        Path | None,
        typer.Option(
            help="The sidecar CSV listing every sample of every gap: frame, marker, filled or "
            "left, method, estimated uncertainty (model: its standard error scaled by the "
            "residuals around the gap, see the gap-filling how-to; default: OUT's name with "
            ".gaps.csv)."
        ),
    ] = None,
    report: Annotated[
        Path | None,
        typer.Option(
            help="Also write this self-contained HTML page: per filled gap, the recording "
            "around it, the filled samples and the cubic spline's fill beside them."
        ),
    ] = None,
):
    """Fill the gaps of the model's markers: with the model's parameters fixed, its
    trajectory fitted (multiple shooting, the missing samples masked) to the markers present
    around each gap, or with a baseline. Gaps at the start or end of the window and gaps
    longer than --max-gap are left and listed."""
    from ..data import read_trajectory
    from ..data._common import check_output_path
    from ..data.fill import plan_fill
    from ..data.writers import WRITERS
    from ..identify.settings import parse_frames, parse_markers
    from ..model import load_model

    try:
        check_order("fill", model, [traj])
        if method not in METHODS:
            raise InputError("--method", f"expected {', '.join(METHODS)}, got '{method}'")
        if denoise and method != "model":
            raise InputError("--denoise", f"needs --method model, not {method}")
        if prior is not None and prior not in PRIORS:
            raise InputError("--prior", f"expected {', '.join(PRIORS)}, got '{prior}'")
        if prior is not None and method != "model":
            raise InputError("--prior", f"needs --method model, not {method}")
        if continuity is not None and not continuity > 0.0:
            raise InputError("--continuity", f"expected a positive weight, got {continuity}")
        if integrator not in ("euler", "verlet"):
            raise InputError("--integrator", f"expected euler or verlet, got '{integrator}'")
        render = WRITERS.get(out_path.suffix.lower())
        if render is None:
            raise InputError(
                out_path,
                f"unknown trajectory file extension {out_path.suffix or '(none)'!r}; "
                f"expected one of {', '.join(WRITERS)}",
            )
        sidecar = record if record is not None else record_path(out_path)
        if sidecar.resolve() == out_path.resolve():
            raise InputError("--record", f"is the filled file itself ({out_path})")
        check_output_path(out_path)
        check_output_path(sidecar)
        if report is not None:
            if report.suffix.lower() not in (".html", ".htm"):
                raise InputError("--report", f"expected an .html page, got '{report.name}'")
            if not report.absolute().parent.is_dir():
                raise InputError("--report", f"the folder of {report} does not exist")
        window = parse_option_frames(frames, parse_frames)
        m = load_model(model)
        chosen = parse_markers(markers) or m.markers
        if len(chosen) != len(m.particle_names):
            raise InputError(
                "--markers",
                f"{len(chosen)} markers given for a model of {len(m.particle_names)} particles "
                f"({', '.join(m.particle_names)}); give one marker per particle, in order",
            )
        data = read_trajectory(traj)
        if data.dimension != m.dimension:
            raise InputError(
                traj, f"the data are {data.dimension}D but the model is {m.dimension}D"
            )
        plan = plan_fill(data, chosen, window, max_gap)
        values, uncertainty, note = _fill_values(
            m,
            plan,
            method,
            denoise,
            context,
            horizon,
            substeps,
            integrator,
            continuity,
            max_steps,
            prior,
        )
        from ..data.fill import apply_fill, record_csv

        filled, records = apply_fill(plan, values, uncertainty, method, denoised=denoise)
        text = render(filled, out_path)  # every check of the format before anything is written
        page = None
        if report is not None:
            from ..report.fill import fill_report

            page = fill_report(plan, values, method, traj.name, note)
        _write_both(out_path, text, sidecar, record_csv(records))
        if page is not None:
            from ..report.files import write_html

            write_html(report, page)
    except InputError as e:
        fail(e)
    _summary(plan, records, method, out_path, sidecar, denoise, note)
    if report is not None:
        say(f"wrote {report} (the filled gaps drawn, the spline's fill beside)")


def _fill_values(
    m, plan, method, denoise, context, horizon, substeps, integrator, continuity, max_steps, prior
):
    """(values [F, M, D] of the window, per gap to fill its uncertainty in metres, a note)."""
    if method == "model":
        from ..identify.gaps.fill import model_fill

        found = model_fill(
            m,
            plan,
            context=context,
            horizon=horizon,
            substeps=substeps,
            integrator=integrator,
            denoise=denoise,
            continuity=continuity,
            max_steps=max_steps,
            prior=prior,
        )
        return found.values, found.uncertainty, found.note()
    from ..data.fill import baseline_uncertainty, fill_baseline

    gaps = plan.local()
    positions, mask = plan.positions, plan.mask
    values = fill_baseline(method, positions, mask, gaps)
    return values, baseline_uncertainty(method, positions, mask, gaps), None


def _write_both(out_path: Path, data: bytes, sidecar: Path, listing: bytes) -> None:
    """The sidecar, then the filled file, each atomically; a failure of the second removes
    the first unless it was there before."""
    from ..data.writers import atomic_write

    existed = sidecar.exists()
    atomic_write(sidecar, listing)
    try:
        atomic_write(out_path, data)
    except BaseException:
        if not existed:
            sidecar.unlink(missing_ok=True)
        raise


def _summary(plan, records, method, out_path, sidecar, denoise, note) -> None:
    filled = plan.to_fill
    left = plan.left
    samples = sum(g.length for g in filled)
    line = f"wrote {out_path}: {len(filled)} gap(s) filled by {method} ({samples} samples)"
    if denoise:
        line += "; every present sample of the model's markers replaced by the model's trajectory"
    say(line)
    done = [
        r.uncertainty_mm
        for r in records
        if r.status == "filled" and r.uncertainty_mm == r.uncertainty_mm
    ]
    if done:
        import numpy as np

        say(
            f"estimated uncertainty of the filled samples: median {np.median(done):.3g} mm, "
            f"largest {np.max(done):.3g} mm"
        )
    if note:
        say(note)
    reasons: dict[str, list] = {}
    for g in left:
        reasons.setdefault(g.reason.split(" (")[0], []).append(g)
    for reason, gaps in reasons.items():
        shown = ", ".join(f"{g.marker} {g.frames}" for g in gaps[:4])
        more = f" and {len(gaps) - 4} more" if len(gaps) > 4 else ""
        extra = " (extrapolation: not filled)" if reason.startswith("at the") else ""
        say(f"left {len(gaps)} gap(s) {reason}{extra}: {shown}{more}")
    say(f"every sample of every gap of the chosen markers: {sidecar}")


def say(line: str) -> None:
    out.print(line, markup=False, highlight=False, emoji=False)
