"""Means over the recorded samples of arrays where NaN marks a missing one.

numpy's ``nanmean`` returns NaN where a slice holds no recorded sample, as this module does, and
also warns ("Mean of empty slice"); on a gappy recording that case is expected (a marker
occluded for a whole phase of the gait), its NaN is the answer, and the warning would reach the
user as noise. These say it by the NaN alone."""

from __future__ import annotations

import numpy as np


def nanmean(x, axis=None, keepdims: bool = False):
    """The mean of the non-NaN entries of ``x`` along ``axis``; NaN where there is none."""
    x = np.asarray(x, dtype=np.float64)
    seen = ~np.isnan(x)
    count = np.sum(seen, axis=axis, keepdims=keepdims)
    total = np.sum(np.where(seen, x, 0.0), axis=axis, keepdims=keepdims)
    mean = np.divide(total, count, out=np.full(np.shape(total), np.nan), where=count > 0)
    return mean if np.ndim(mean) else float(mean)
