"""Files bundled inside the package: example models and the VHDC horse data (CC BY-SA 4.0,
attribution and licence in datasets/horse_vhdc/)."""

from __future__ import annotations

from importlib import resources
from pathlib import Path


def bundled(relative: str) -> Path:
    path = Path(str(resources.files("activebonds") / relative))
    if not path.exists():
        raise FileNotFoundError(f"bundled file missing from the installation: {relative}")
    return path


def horse_trot() -> Path:
    from ..data.bundled import dataset

    return dataset("horse-trot").path


def example(name: str) -> Path:
    return bundled(f"examples/{name}.toml")
