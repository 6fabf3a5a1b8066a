"""A fit's inputs read once and checked before anything is compiled or written: the model file,
every recording, the cost chosen where it is ``auto`` (:mod:`.costs.choice`), the predictions
the gaps leave (:func:`.problem.check_predictions`) and the validation frames. :func:`fit
<activebonds.identify.driver.fit>` runs on what this returns; the command line prints its
notes first."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from ..data import read_trajectory
from ..data.trajectory import Trajectory
from ..model import Model, load_model
from .costs.choice import choose
from .problem import check_predictions, variant
from .settings import FitSettings


@dataclass(frozen=True, eq=False)
class Prepared:
    """What a fit needs, read and checked: the model and recordings as objects beside the
    files they came from (None for objects given), the settings with the cost chosen, and
    the lines that say which cost was chosen and what the gaps leave."""

    model: Model
    model_path: Path | None
    recordings: tuple[Trajectory, ...]
    paths: tuple[Path | None, ...]
    settings: FitSettings
    cost_note: str | None = None  # which cost ``auto`` chose and why
    predictions: str = ""  # what the gaps leave of the predictions
    held_out: object = None  # the validation frames (:func:`validation_frames`), or None

    @property
    def many(self) -> bool:
        return len(self.recordings) > 1

    @property
    def data(self) -> Trajectory | tuple[Trajectory, ...]:
        """One recording, or several (their costs added)."""
        return self.recordings if self.many else self.recordings[0]


def prepare(
    model: Model | str | Path,
    data: Trajectory | str | Path | list | tuple,
    settings: FitSettings,
    *,
    horizon_given: bool = True,
    strict: bool = False,
) -> Prepared:
    """Read ``model`` and ``data`` (objects or paths; a list of recordings fitted at once)
    once, choose the cost where ``settings.cost`` is ``auto`` (``horizon_given``: whether
    the settings' horizon was asked for, else the chosen cost's own), and check the
    predictions and the validation frames; an :class:`~activebonds.errors.InputError` names
    what cannot be used. ``strict``: refuse a CSV or TRC recording whose last row is
    incomplete."""
    model_path = Path(model) if isinstance(model, str | Path) else None
    items = list(data) if isinstance(data, list | tuple) else [data]
    paths = tuple(Path(d) if isinstance(d, str | Path) else None for d in items)
    model_obj = load_model(model_path) if model_path else model
    recordings = tuple(
        read_trajectory(p, strict=strict) if p else d for p, d in zip(paths, items, strict=True)
    )
    spec = variant(model_obj, settings.bonds)
    settings, why = choose(settings, spec, recordings[0], horizon_given)
    predictions = check_predictions(spec, recordings, settings)
    held_out = validation_frames(spec, recordings[0], settings)
    return Prepared(model_obj, model_path, recordings, paths, settings, why, predictions, held_out)


def validation_frames(model: Model, recording: Trajectory, settings: FitSettings):
    """The frames ``settings.validation`` of ``recording`` (the model's markers), checked
    (:class:`InputError` naming ``--validate``), or None without validation."""
    if settings.validation is None:
        return None
    from .judge.metrics import validation_data

    return validation_data(model, recording, settings, settings.validation)
