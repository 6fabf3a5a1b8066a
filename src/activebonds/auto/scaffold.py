"""Step 1 of ``activebonds auto``, the scaffold: a candidate model of the fitted frames,
found before anything is written (it checks the markers, the mass, the vertical)."""

from __future__ import annotations

from .folder import Folder, Options, Windows


def scaffold_of(recording, split: Windows, options: Options, name: str):
    """The candidate model of the fitted frames (:func:`~activebonds.identify.discover.scaffold.
    scaffold` with the options), its inputs checked."""
    from ..identify.discover.scaffold import scaffold

    return scaffold(
        recording,
        markers=list(options.markers) if options.markers else None,
        frames=split.fitted,
        total_mass=options.total_mass,
        up=options.up,
        gravity=options.gravity,
        name=name,
    )


def write_scaffold(folder: Folder, found, say) -> str:
    """The scaffold ``found`` (checked to load) written, its notes said."""
    from ..atomic import write_text_atomic
    from ..model import loads_model

    loads_model(found.text, str(folder.scaffold))
    for note in found.notes:
        say(f"      {note}")
    write_text_atomic(folder.scaffold, found.text)
    return (
        f"{found.particles} particles, {found.bonds} candidate bonds, {found.contacts} "
        f"ground contacts, gravity {found.gravity}: {folder.scaffold}"
    )
