"""The walk family, found from a recording: whether it walks (:mod:`.recognise`: a stride
that repeats, :mod:`.stride`; a floor the body travels over, :mod:`.floor`) and the model
(:mod:`.family`: a force periodic in the stride's phase on every marker, nothing tying the
body to the room)."""

from .family import WalkVariant, harmonics_seen, phase_gaps, segment_bonds, walk_spec
from .floor import Floor, find_floor
from .recognise import Walk, recognise
from .stride import Stride, find_stride

__all__ = [
    "Floor",
    "Stride",
    "Walk",
    "WalkVariant",
    "find_floor",
    "find_stride",
    "harmonics_seen",
    "phase_gaps",
    "recognise",
    "segment_bonds",
    "walk_spec",
]
