"""Command-line options to validated settings, with pydantic errors as one line."""

from __future__ import annotations

from pydantic import ValidationError

from ..errors import option_error
from ..identify.settings import FitSettings


def settings_of(settings: type, **options):
    """``settings(**options)`` (a pydantic model), a refusal as the one line of the option at
    fault (:func:`activebonds.errors.option_error`)."""
    try:
        return settings(**options)
    except ValidationError as e:
        raise option_error(e) from None


def settings_from_options(**options) -> FitSettings:
    """The fit's settings (:class:`FitSettings`) from its options."""
    return settings_of(FitSettings, **options)
