"""Recordings shipped inside the package, by short name, so that examples and scripts can
point at real data without knowing where pip put it (``activebonds datasets NAME``).

The horse recordings are the Vienna Horse Data Collection's (CC BY-SA 4.0): their licence and
provenance sit beside them in ``datasets/horse_vhdc/``. The human walk is OpenSim's
``subject01_walk1`` (Apache-2.0), licence and provenance beside it in ``datasets/human_opensim/``.
"""

from __future__ import annotations

from dataclasses import dataclass
from importlib import resources
from pathlib import Path

from ..errors import InputError


@dataclass(frozen=True)
class Bundled:
    name: str
    relative: str  # inside the installed package
    what: str
    licence: str  # the licence file, beside the recording

    @property
    def path(self) -> Path:
        path = Path(str(resources.files("activebonds") / self.relative))
        if not path.exists():
            raise FileNotFoundError(f"bundled file missing from the installation: {self.relative}")
        return path


_VHDC = "datasets/horse_vhdc/"
_OPENSIM = "datasets/human_opensim/"
DATASETS: dict[str, Bundled] = {
    d.name: d
    for d in (
        Bundled(
            "horse-trot",
            _VHDC + "Horse1_M1_trot1_kinematics.csv",
            "VHDC Horse1 at trot: 7 markers (Head, Withers, Sacrum, four hooves), 600 frames, 60 Hz",
            _VHDC + "LICENSE_VHDC_CC-BY-SA-4.0.txt",
        ),
        Bundled(
            "horse-walk",
            _VHDC + "Horse1_M1_walk1_kinematics.csv",
            "VHDC Horse1 at walk: the same 7 markers, 600 frames, 60 Hz",
            _VHDC + "LICENSE_VHDC_CC-BY-SA-4.0.txt",
        ),
        Bundled(
            "human-walk",
            _OPENSIM + "subject01_walk1.trc",
            "OpenSim subject01 walk: 41 markers (pelvis, legs, feet, trunk, arms, head), "
            "151 frames, 60 Hz, mm",
            _OPENSIM + "LICENSE_opensim-core_Apache-2.0.txt",
        ),
    )
}


# The example files (the repository's examples/ folder, also installed with the package).
EXAMPLES = (
    "triangle.toml",
    "triangle.csv",
    "triangle_candidates.toml",
    "chain2d.toml",
    "horse_limb.toml",
    "horse_trot_drive.toml",
    "horse_trot_entrained.toml",
    "horse_trot_ground.toml",
    "sweep.toml",
)


def dataset(name: str) -> Bundled:
    """The bundled recording or example file called ``name``; InputError listing the names
    otherwise."""
    if name in DATASETS:
        return DATASETS[name]
    if name in EXAMPLES:
        return Bundled(name, f"examples/{name}", "example file", "")
    raise InputError(
        "datasets",
        f"no bundled file {name!r}; expected one of {', '.join([*DATASETS, *EXAMPLES])}",
    )
