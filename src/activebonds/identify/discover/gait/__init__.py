"""The gait family, found from a recording: its rhythm (:mod:`.rhythm`), the signals its drive
reads (:mod:`.signals`) and the model (:mod:`.family`)."""

from .family import GaitVariant, gait_spec, solve
from .rhythm import Rhythm, find_rhythm
from .signals import Signal, survey

__all__ = ["GaitVariant", "Rhythm", "Signal", "find_rhythm", "gait_spec", "solve", "survey"]
