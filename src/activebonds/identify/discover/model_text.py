"""Numbers and names as a model file's TOML text: a float to six significant digits, a vector,
a quoted name, a searched parameter with its bounds (the scaffold's blocks)."""

from __future__ import annotations

import json


def toml_float(x: float) -> str:
    """A TOML float, six significant digits."""
    s = f"{x:.6g}"
    return s if any(c in s for c in ".en") else s + ".0"


def vector(xs) -> str:
    return "[" + ", ".join(toml_float(x) for x in xs) + "]"


def quoted(s: str) -> str:
    return json.dumps(s)


def searched(value: float, lo: float, hi: float) -> str:
    return f"{{ value = {toml_float(value)}, min = {toml_float(lo)}, max = {toml_float(hi)} }}"
