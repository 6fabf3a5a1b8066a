"""Reports of identification runs: predictions, figures, an animated GIF and one
self-contained HTML file (no external resource; works offline)."""

from ..identify.judge.metrics import FreeRunMetrics, free_run_metrics, zero_force_metrics
from .animation import payload, projection_axes, write_gif
from .files import staged_directory
from .html import (
    Figure,
    Section,
    Table,
    errors_table,
    render,
    run_sections,
    summary_table,
    write_comparison_report,
    write_report,
)
from .plots import Series
from .predict import Prediction, predict, predict_run
from .runs import RunRecord, load_run

__all__ = [
    "Figure",
    "FreeRunMetrics",
    "Prediction",
    "RunRecord",
    "Section",
    "Series",
    "Table",
    "errors_table",
    "free_run_metrics",
    "load_run",
    "payload",
    "predict",
    "predict_run",
    "projection_axes",
    "render",
    "run_sections",
    "staged_directory",
    "summary_table",
    "write_comparison_report",
    "write_gif",
    "write_report",
    "zero_force_metrics",
]
