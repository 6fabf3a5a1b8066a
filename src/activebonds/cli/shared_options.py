"""The arguments and options that several commands take, each declared once: the same flag,
meaning and help wherever it appears. A command gives its own default
(``frames: Frames = "0:"``)."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer

# arguments
Recording = Annotated[Path, typer.Argument(help="Recorded trajectory.")]
ModelFile = Annotated[Path, typer.Argument(help="Model file (TOML).")]
FittedModel = Annotated[
    Path, typer.Argument(help="Model file (TOML), e.g. a fit's RUN/best_model.toml.")
]

# the recording's markers and frames
ModelMarkers = Annotated[
    str | None,
    typer.Option(help="Markers followed by the particles, in order: A,B,C (default: the model's)."),
]
AllMarkers = Annotated[
    str | None, typer.Option(help="Markers to model, in order: A,B,C (default: all).")
]
Frames = Annotated[str, typer.Option(help="Frame window START:STOP.")]
Strict = Annotated[
    bool,
    typer.Option(
        "--strict",
        help="Refuse a CSV or TRC recording whose last row is incomplete (an interrupted "
        "export) instead of dropping that row with a warning.",
    ),
]

# a candidate model's physics (scaffold, auto)
TotalMass = Annotated[
    float | None,
    typer.Option(help="Total mass in kg, split equally (default: 1 kg per marker)."),
]
Up = Annotated[
    str | None, typer.Option(help="The vertical axis, e.g. Z or -Y: gravity along minus it.")
]
Gravity = Annotated[
    bool | None,
    typer.Option(
        "--gravity/--no-gravity",
        help="Gravity and ground contacts (default: where the vertical is confident).",
    ),
]

# the fit's search (fit, auto) and the model's stepping (simulate, export, fit)
Population = Annotated[int, typer.Option(help="The fit's population size.")]
Generations = Annotated[int, typer.Option(help="The fit's generations.")]
Seed = Annotated[int, typer.Option(help="Random seed.")]
Bonds = Annotated[str, typer.Option(help="model, standard or neural.")]
Substeps = Annotated[int, typer.Option(min=1, help="Integration steps per frame.")]
Integrator = Annotated[str, typer.Option(help="euler or verlet.")]

# the output
Overwrite = Annotated[bool, typer.Option(help="Replace an existing --out file.")]
AsJson = Annotated[bool, typer.Option("--json", help="Print JSON instead of a table.")]
