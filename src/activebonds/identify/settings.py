"""Settings of an identification run, validated (pydantic) and stored in the run directory."""

from __future__ import annotations

from typing import Literal

from pydantic import BaseModel, ConfigDict, Field, field_validator, model_validator

AUTO = "auto"  # a cost chosen for the recording (identify.costs.choice)


class FitSettings(BaseModel):
    """Everything that, with the model, the data and the software versions, decides a run."""

    model_config = ConfigDict(extra="forbid", frozen=True, populate_by_name=True)

    markers: tuple[str, ...] | None = None  # default: the model's particles' markers
    frames: tuple[int, int | None] = (0, None)  # [start, stop) of the recorded frames
    bonds: Literal["model", "standard", "neural"] = "model"
    population: int = Field(100, ge=4, le=100_000)
    generations: int = Field(1000, ge=1, le=100_000_000)
    seed: int = Field(0, ge=0, le=2**31 - 1)
    # frames per prediction: the ES's cost uses the first; ``refine`` runs a stage per entry
    horizon: tuple[int, ...] = (1,)
    # the refinement's cost, a name of identify.costs ("auto": chosen when the fit reads its
    # recording, identify.costs.choice; never stored so)
    cost: str = "restart"
    refine: Literal["none", "lm"] = "lm"
    # Levenberg-Marquardt steps per refinement stage, at most (``fit --max-steps``)
    max_steps: int = Field(500, ge=1, le=1_000_000)
    smooth: int = Field(0, ge=0, le=1001)  # Savitzky-Golay window of the restart states, 0: off
    substeps: int = Field(1, ge=1, le=1000)
    integrator: str = "euler"  # a scheme of physics.integrators
    elite_fraction: float = Field(0.1, gt=0, lt=1)
    crossover_rate: float = Field(0.5, ge=0, le=1)
    selection_pressure: float = Field(4.0, ge=0)
    sigma_init: float = Field(0.1, gt=0, le=1)
    adapt_variants: bool = False
    # lsq: one individual at the linear optimum; model: one at the model file's values (a
    # structure result's, say)
    init: Literal["uniform", "lsq", "model"] = "uniform"
    optimizer: str = "es"  # a name of identify.strategies: "es" (the paper's), "random", "cmaes"
    chunk: int = Field(250, ge=1, le=100_000)  # generations per compiled call, at most
    checkpoint_every: int = Field(5000, ge=1)  # generations between checkpoints
    # float64; float32 throughout; or mixed: the ES's one-step cost evaluated in float32, the
    # ES state, history and refinement in float64 (benchmarks/README.md: speed and quality)
    precision: Literal["float32", "float64", "mixed"] = "float64"
    # frames [start, stop) of the first recording, not fitted, on which the validation stage
    # measures the model (``fit --validate``); None: no validation
    # (``fit(..., validate=(START, STOP))`` in Python)
    validation: tuple[int, int | None] | None = Field(None, alias="validate")

    @field_validator("smooth")
    @classmethod
    def _smooth(cls, v):
        from ..data.smoothing import check_window

        return check_window(v)

    @field_validator("horizon", mode="before")
    @classmethod
    def _horizon(cls, v):
        return (v,) if isinstance(v, int) else v

    @field_validator("horizon")
    @classmethod
    def _horizons(cls, v):
        if not v or any(h < 1 for h in v):
            raise ValueError(f"horizons must be integers >= 1, got {list(v)}")
        return v

    @model_validator(mode="after")
    def _stages(self):
        if self.refine == "none" and len(self.horizon) > 1:
            raise ValueError(
                "a horizon curriculum (several horizons) is run by the refinement; add --refine lm"
            )
        if self.refine == "none" and self.cost != AUTO and self._cost().refinement_only:
            raise ValueError(f"the {self.cost} cost is the refinement's; add --refine lm")
        return self

    def _cost(self):
        from .costs import get

        if self.cost == AUTO:
            raise ValueError("the cost is chosen when the fit reads its recording (cost 'auto')")
        return get(self.cost)

    @property
    def stepper(self):
        """The integrator with its substeps (:class:`~activebonds.physics.integrators.Integrator`)."""
        from ..physics.integrators import Integrator

        return Integrator(self.integrator, self.substeps)

    @property
    def es_horizon(self) -> int:
        """The horizon of the ES's cost: the first of ``horizon``; 1 (the one-step cost) when
        the refinement shoots, as a shooting state cannot be evolved."""
        return self.horizon[0] if self._cost().evolvable else 1

    @property
    def es_exact(self) -> bool:
        """The ES evolves on the plain one-step cost (one Euler substep, whose optimum
        ``--init lsq`` solves exactly where the model's families allow) when the refinement
        shoots: the ES's cost is then only the shooting's start, and at the shooting's
        substeps it would cost them times more (a start-velocity solve per prediction, Newton's
        method on contact models) for a start no better."""
        return not self._cost().evolvable

    @property
    def es_substeps(self) -> int:
        """Substeps of the ES's cost (``substeps`` unless :attr:`es_exact`)."""
        return 1 if self.es_exact else self.substeps

    @property
    def es_integrator(self) -> str:
        """Integrator of the ES's cost (``integrator`` unless :attr:`es_exact`)."""
        from ..physics.integrators import DEFAULT

        return DEFAULT if self.es_exact else self.integrator

    @field_validator("frames", "validation")
    @classmethod
    def _frames(cls, v):
        if v is None:
            return v
        start, stop = v
        if start < 0 or (stop is not None and stop <= start):
            raise ValueError(
                f"frames must be START:STOP with 0 <= START < STOP, got {frames_text(v)}"
            )
        return v

    @field_validator("cost", "integrator")
    @classmethod
    def _registered(cls, v, info):
        """A cost's or an integration scheme's registered name (a cost may be ``auto``)."""
        from ..physics.integrators import SCHEMES
        from .costs import COSTS

        if not (info.field_name == "cost" and v == AUTO):
            (COSTS if info.field_name == "cost" else SCHEMES).find(v)
        return v

    @field_validator("optimizer")
    @classmethod
    def _optimizer(cls, v):
        from .search.strategies import names

        if v not in names():
            raise ValueError(f"unknown optimizer {v!r}; choose one of {', '.join(names())}")
        return v

    def es(self):
        """The paper's ES's own settings (:class:`~activebonds.identify.search.es.ESSettings`)."""
        from .search.es import ESSettings

        return ESSettings(
            population=self.population,
            elite_fraction=self.elite_fraction,
            crossover_rate=self.crossover_rate,
            selection_pressure=self.selection_pressure,
            sigma_init=self.sigma_init,
            adapt_variants=self.adapt_variants,
        )

    def job(self) -> dict:
        """The settings that define the result (chunking, checkpoint frequency and the
        validation frames do not)."""
        exclude = {"chunk", "checkpoint_every", "generations", "validation"}
        if self.max_steps == FitSettings.model_fields["max_steps"].default:
            exclude.add("max_steps")  # runs from before the option resume as they were
        return self.model_dump(mode="json", exclude=exclude)


def parse_frames(text: str) -> tuple[int, int | None]:
    """'START:STOP' (either side may be empty) -> (start, stop)."""
    if ":" not in text:
        raise ValueError(f"expected START:STOP, got '{text}'")
    a, b = text.split(":", 1)
    try:
        start = int(a) if a.strip() else 0
        stop = int(b) if b.strip() else None
    except ValueError:
        raise ValueError(f"expected START:STOP with integers, got '{text}'") from None
    return start, stop


def frames_text(frames: tuple[int, int | None]) -> str:
    """(start, stop) -> 'START:STOP' (an open end left empty), as :func:`parse_frames` reads."""
    start, stop = frames
    return f"{start}:{'' if stop is None else stop}"


def parse_markers(text: str | None) -> tuple[str, ...] | None:
    """'A, B,C' -> ('A', 'B', 'C'); None or '' -> None (the model's own markers)."""
    return tuple(m.strip() for m in text.split(",")) if text else None
