"""``activebonds fill`` in Python: a recording's gaps filled from files to files
(:func:`fill_file`). The model file and the recording are read and checked once, the gaps
planned (:func:`activebonds.data.fill.plan_fill`), filled by the model's trajectory
(:func:`.fill.model_fill`) or a lab's method, and the filled recording written with its
sidecar record of every sample of every gap; bad input is one :class:`InputError` line and
nothing is written."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ...data import read_trajectory
from ...data._common import by_extension, check_output_path
from ...data.fill import FilledSample, FillPlan, apply_fill, plan_fill, record_csv
from ...data.writers import WRITERS, atomic_write
from ...errors import InputError
from ...model import load_model
from ..problem import particle_markers
from .settings import FillSettings

# the settings the model's fill takes, by the names of :func:`.fill.model_fill`'s options
MODEL_FILL_OPTIONS = {
    "context", "horizon", "substeps", "integrator", "denoise", "continuity", "max_steps", "prior"
}  # fmt: skip


def record_path(out: Path) -> Path:
    """The sidecar CSV beside the filled file: ``filled.trc`` -> ``filled.gaps.csv``."""
    return out.with_name(out.stem + ".gaps.csv")


@dataclass(frozen=True, eq=False)
class FilledFile:
    """What :func:`fill_file` wrote: the filled recording ``out`` and its sidecar ``record``,
    the plan (gaps filled and left, and why), the window's filled positions ``values``
    [F, M, D], every sample of every gap (``records``) and the model fit's note (None for a
    lab's method)."""

    out: Path
    record: Path
    settings: FillSettings
    plan: FillPlan
    values: np.ndarray
    records: list[FilledSample]
    note: str | None

    def lines(self) -> list[str]:
        """What ``activebonds fill`` prints: the gaps filled, the uncertainty of the filled
        samples, the model fit's note, the gaps left and why, and where the record is."""
        method, filled = self.settings.method, self.plan.to_fill
        samples = sum(g.length for g in filled)
        line = f"wrote {self.out}: {len(filled)} gap(s) filled by {method} ({samples} samples)"
        if self.settings.denoise:
            line += (
                "; every present sample of the model's markers replaced by the model's trajectory"
            )
        lines = [line]
        done = [
            r.uncertainty_mm
            for r in self.records
            if r.status == "filled" and r.uncertainty_mm == r.uncertainty_mm
        ]
        if done:
            lines.append(
                f"estimated uncertainty of the filled samples: median {np.median(done):.3g} "
                f"mm, largest {np.max(done):.3g} mm"
            )
        if self.note:
            lines.append(self.note)
        reasons: dict[str, list] = {}
        for g in self.plan.left:
            reasons.setdefault(g.reason.split(" (")[0], []).append(g)
        for reason, gaps in reasons.items():
            shown = ", ".join(f"{g.marker} {g.frames}" for g in gaps[:4])
            more = f" and {len(gaps) - 4} more" if len(gaps) > 4 else ""
            extra = " (extrapolation: not filled)" if reason.startswith("at the") else ""
            lines.append(f"left {len(gaps)} gap(s) {reason}{extra}: {shown}{more}")
        lines.append(f"every sample of every gap of the chosen markers: {self.record}")
        return lines


def fill_file(
    model: str | Path,
    recording: str | Path,
    out: str | Path,
    settings: FillSettings | None = None,
    record: str | Path | None = None,
) -> FilledFile:
    """Fill the gaps of the model's markers in ``recording`` and write every marker and frame
    to ``out`` (.csv, .trc, .c3d, .npz, .mat), with the sidecar CSV ``record`` (default: OUT's name
    with .gaps.csv) listing every sample of every gap, filled or left. ``settings``: the
    method, markers, frames and the model fit's options (default: :class:`FillSettings`'s).

    Raises:
        InputError: an output that cannot be written, a model and a recording that do not go
            together, a marker never present, a fill that fails; nothing is then written.
    """
    settings = FillSettings() if settings is None else settings
    model, recording, out = Path(model), Path(recording), Path(out)
    render = by_extension(WRITERS, out)
    sidecar = Path(record) if record is not None else record_path(out)
    if sidecar.resolve() == out.resolve():
        raise InputError("--record", f"is the filled file itself ({out})")
    check_output_path(out)
    check_output_path(sidecar)
    m = load_model(model)
    chosen = particle_markers(m, settings.markers)
    data = read_trajectory(recording)
    if data.dimension != m.dimension:
        raise InputError(
            recording, f"the data are {data.dimension}D but the model is {m.dimension}D"
        )
    plan = plan_fill(data, chosen, settings.frames, settings.max_gap)
    values, uncertainty, note = _fill_values(m, plan, settings)
    filled, records = apply_fill(
        plan, values, uncertainty, settings.method, denoised=settings.denoise
    )
    text = render(filled, out)  # every check of the format before anything is written
    _write_both(out, text, sidecar, record_csv(records))
    return FilledFile(out, sidecar, settings, plan, values, records, note)


def _fill_values(m, plan: FillPlan, s: FillSettings):
    """(values [F, M, D] of the window, per gap to fill its uncertainty in metres, a note)."""
    if s.method == "model":
        from .fill import model_fill

        found = model_fill(m, plan, **s.model_dump(include=MODEL_FILL_OPTIONS))
        return found.values, found.uncertainty, found.note()
    from ...data.fill import baseline_uncertainty, fill_baseline

    gaps = plan.local()
    positions, mask = plan.positions, plan.mask
    values = fill_baseline(s.method, positions, mask, gaps)
    return values, baseline_uncertainty(s.method, positions, mask, gaps), None


def _write_both(out: Path, data: bytes, sidecar: Path, listing: bytes) -> None:
    """The sidecar, then the filled file, each atomically; a failure of the second removes
    the first unless it was there before."""
    existed = sidecar.exists()
    atomic_write(sidecar, listing)
    try:
        atomic_write(out, data)
    except BaseException:
        if not existed:
            sidecar.unlink(missing_ok=True)
        raise
