"""Settings of a gap fill (``activebonds fill``, :func:`.files.fill_file`), validated (pydantic):
every default, and the checks of the options that go together, each refused in one line naming
the option (:func:`activebonds.errors.option_error`). Imports no JAX: the command line reads
its defaults here."""

from __future__ import annotations

from pydantic import BaseModel, ConfigDict, Field, ValidationInfo, field_validator

from ..settings import parse_frames, parse_markers

METHODS = ("model", "spline", "linear", "pca")
PRIORS = ("pca",)
MAX_STEPS = 200  # Levenberg-Marquardt steps per fitted stretch, at most


class FillSettings(BaseModel):
    """How the gaps are filled: ``method`` (the model's trajectory, or a lab's spline, linear
    or PCA fill), which markers and frames, which gaps are left, and the model's fit.

    ``markers`` and ``frames`` may be given as the command line writes them ('A,B,C',
    'START:STOP'). Fields are checked in order, so a check of two options sees the first.
    """

    model_config = ConfigDict(extra="forbid", frozen=True)

    method: str = "model"
    # the model's smoothed trajectory written for every sample of its markers in the window
    denoise: bool = False
    prior: str | None = None  # "pca": the PCA fill as soft observations of the model's fit
    # weight of the continuity defects against the position errors; None: from how much of the
    # context's accelerations the model explains
    continuity: float | None = None
    integrator: str = "euler"
    markers: tuple[str, ...] | None = None  # default: the model's particles' markers
    frames: tuple[int, int | None] = (0, None)  # [start, stop) of the recorded frames
    max_gap: int | None = None  # gaps longer than this many frames are left
    context: int = Field(30, ge=2)  # frames on each side of a gap the model is fitted to
    horizon: int = Field(1, ge=1)  # frames per shooting window
    max_steps: int = Field(MAX_STEPS, ge=1)
    substeps: int = Field(1, ge=1)

    @field_validator("method")
    @classmethod
    def _method(cls, v):
        if v not in METHODS:
            raise ValueError(f"expected {', '.join(METHODS)}, got '{v}'")
        return v

    @field_validator("denoise", "prior")
    @classmethod
    def _model_only(cls, v, info: ValidationInfo):
        """Options of the model's fill alone (a prior also one of :data:`PRIORS`)."""
        if info.field_name == "prior" and v is not None and v not in PRIORS:
            raise ValueError(f"expected {', '.join(PRIORS)}, got '{v}'")
        method = info.data.get("method")
        if v not in (None, False) and method is not None and method != "model":
            raise ValueError(f"needs --method model, not {method}")
        return v

    @field_validator("continuity")
    @classmethod
    def _continuity(cls, v):
        if v is not None and not v > 0.0:
            raise ValueError(f"expected a positive weight, got {v}")
        return v

    @field_validator("integrator")
    @classmethod
    def _integrator(cls, v):
        from ...physics import integrators

        if v not in integrators.names():
            raise ValueError(f"expected {' or '.join(integrators.names())}, got '{v}'")
        return v

    @field_validator("markers", mode="before")
    @classmethod
    def _markers(cls, v):
        return parse_markers(v) if isinstance(v, str) or v is None else v

    @field_validator("frames", mode="before")
    @classmethod
    def _frames(cls, v):
        return parse_frames(v) if isinstance(v, str) else v
