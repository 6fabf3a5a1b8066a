"""Export a model to other simulators' formats: MuJoCo's MJCF (:mod:`.mjcf`)."""

from .mjcf import check_exportable, to_mjcf, write_mjcf

FORMATS = ("mjcf",)

__all__ = ["FORMATS", "check_exportable", "to_mjcf", "write_mjcf"]
