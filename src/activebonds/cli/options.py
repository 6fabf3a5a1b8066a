"""Command-line options to validated settings, with pydantic errors as one line."""

from __future__ import annotations

from pydantic import ValidationError

from ..errors import InputError
from ..identify.settings import FitSettings


def settings_from_options(**options) -> FitSettings:
    try:
        return FitSettings(**options)
    except ValidationError as e:
        first = e.errors()[0]
        name = "--" + str(first["loc"][0]).replace("_", "-") if first["loc"] else "options"
        raise InputError(name, first["msg"].removeprefix("Value error, ")) from None
