"""Arguments given in the wrong order: a recording where a command takes its model file, or a
model file where it takes a recording. Told in one line with the command's order, before the
model file is parsed (a recording read as TOML says only "not valid TOML")."""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

from ..errors import InputError

MODEL_SUFFIX = ".toml"


def check_order(command: str, model: Path, recordings: Sequence[Path] = ()) -> None:
    """Refuse (:class:`InputError`) a ``model`` argument with a recording's extension or a
    recording argument with a model file's; ``recordings``: the command's recording
    arguments (none for a command that takes a model file only)."""
    from ..data.readers import READERS  # the recordings' extensions

    usage = f"activebonds {command} MODEL DATA" if recordings else f"activebonds {command} MODEL"
    models = [p for p in recordings if Path(p).suffix.lower() == MODEL_SUFFIX]
    if Path(model).suffix.lower() in READERS:
        if models:
            raise InputError(
                None,
                f"the arguments look swapped: {model} is a recording and {models[0]} a model "
                f"file; the order is `{usage}` (the model file, .toml, first)",
            )
        raise InputError(
            model, f"a recording where the model file (TOML) is expected; the order is `{usage}`"
        )
    if models:
        raise InputError(
            models[0],
            f"a model file where a recording is expected; the order is `{usage}` (the model "
            "file first: arguments swapped?)",
        )
