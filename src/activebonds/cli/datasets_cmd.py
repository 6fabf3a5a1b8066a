"""``activebonds datasets``: the recordings shipped with the package, and where they are."""

from __future__ import annotations

from typing import Annotated

import typer
from rich.table import Table

from ..errors import InputError
from .app import app, fail, out


@app.command()
def datasets(
    name: Annotated[
        str | None,
        typer.Argument(help="A recording or example file: print only its path (for scripts)."),
    ] = None,
):
    """The bundled recordings (name, path, what, licence) and example files; with NAME (a
    recording or an example file such as triangle.toml), only its path:
    ``horse=$(activebonds datasets horse-trot)``."""
    from ..data.bundled import DATASETS, dataset

    if name is not None:
        try:
            print(dataset(name).path)
        except InputError as e:
            fail(e)
        return
    table = Table(title="bundled recordings (activebonds datasets NAME prints the path)")
    for column in ("name", "what", "path", "licence"):
        table.add_column(column, overflow="fold")
    for d in DATASETS.values():
        table.add_row(d.name, d.what, str(d.path), d.licence.rsplit("/", 1)[-1])
    out.print(table)
    from ..data.bundled import EXAMPLES

    folder = dataset(EXAMPLES[0]).path.parent
    out.print(f"example files (in {folder}): {', '.join(EXAMPLES)}", markup=False)
