"""Reports of identification runs: predictions, figures, an animated GIF and one
self-contained HTML file (no external resource; works offline). The
public names are imported when first used, so that ``evaluate`` (no figure) does not import
matplotlib."""

from ..lazy import exports
from .predict import Prediction as Prediction  # the function "predict", not its module
from .predict import predict as predict
from .predict import predict_run as predict_run

_PUBLIC = {
    "FreeRunMetrics": "activebonds.identify.judge.metrics",
    "free_run_metrics": "activebonds.identify.judge.metrics",
    "zero_force_metrics": "activebonds.identify.judge.metrics",
    "payload": "activebonds.report.animation",
    "projection_axes": "activebonds.report.animation",
    "write_gif": "activebonds.report.animation",
    "staged_directory": "activebonds.report.files",
    "Figure": "activebonds.report.html",
    "Section": "activebonds.report.html",
    "Table": "activebonds.report.html",
    "errors_table": "activebonds.report.html",
    "render": "activebonds.report.html",
    "run_sections": "activebonds.report.html",
    "summary_table": "activebonds.report.html",
    "write_comparison_report": "activebonds.report.html",
    "write_report": "activebonds.report.html",
    "Series": "activebonds.report.plots",
    "RunRecord": "activebonds.report.runs",
    "load_run": "activebonds.report.runs",
}

__getattr__, __dir__ = exports(__name__, _PUBLIC)
__all__ = sorted([*_PUBLIC, "Prediction", "predict", "predict_run"])
