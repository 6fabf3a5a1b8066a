"""Checkpoints (private to :class:`~.RunDir`): RUN/checkpoints/gen-XXXXXXXXX.npz, the loop
state by its pytree paths and the history by column, written atomically, the two newest kept.

A checkpoint stores the loop state pytree by its paths (``state_generation``,
``state_failed_total``, then the strategy's state: ``state_genes``, ``state_sigma``, ... for
the paper's ES) and the history by column (``history_best_cost``, ...), so any strategy's state
round-trips. Nothing is ever unpickled: checkpoints are read with ``allow_pickle=False``.
"""

from __future__ import annotations

import io
from pathlib import Path

import jax
import numpy as np

from ...atomic import remove_leftovers
from ._files import write_atomic

KEEP_CHECKPOINTS = 2
LOOP_KEYS = ("generation", "failed_total")  # the loop's own entries of a checkpointed state


def flatten_state(state) -> dict[str, np.ndarray]:
    """The loop state (evolve.Run) as arrays by path: the loop's entries, then the
    strategy's (their paths without the 'strategy' prefix, joined by '.')."""
    out = {k: np.asarray(getattr(state, k)) for k in LOOP_KEYS}
    leaves = jax.tree_util.tree_flatten_with_path(state.strategy)[0]
    for path, leaf in leaves:
        name = _path_name(path)
        if name in out:
            raise ValueError(f"a strategy state may not have an entry named {name!r}")
        out[name] = np.asarray(leaf)
    return out


def unflatten_state(arrays: dict[str, np.ndarray], template):
    """Arrays by path back into the structure (and dtypes) of ``template``."""
    import jax.numpy as jnp

    leaves = jax.tree_util.tree_flatten_with_path(template.strategy)
    strategy = [jnp.asarray(arrays[_path_name(path)], leaf.dtype) for path, leaf in leaves[0]]
    loop = {k: jnp.asarray(arrays[k], getattr(template, k).dtype) for k in LOOP_KEYS}
    return template._replace(strategy=jax.tree_util.tree_unflatten(leaves[1], strategy), **loop)


def state_shapes(template) -> dict[str, tuple]:
    """The shape of every entry of a checkpointed state, from a template (eval_shape)."""
    flat = {k: getattr(template, k) for k in LOOP_KEYS}
    for path, leaf in jax.tree_util.tree_flatten_with_path(template.strategy)[0]:
        flat[_path_name(path)] = leaf
    return {k: tuple(v.shape) for k, v in flat.items()}


def _path_name(path) -> str:
    """A strategy-state leaf's checkpoint name: its pytree path joined by '.'."""
    return ".".join(_key_name(k) for k in path) or "strategy"


def _key_name(key) -> str:
    for attr in ("name", "key", "idx"):
        if hasattr(key, attr):
            return str(getattr(key, attr))
    return str(key)


def save(run: Path, state: dict[str, np.ndarray], history: dict[str, np.ndarray]) -> None:
    """A flattened loop state (:func:`flatten_state`) and the history up to
    ``state['generation']``, atomically; keep the two newest."""
    folder = run / "checkpoints"
    gen = int(state["generation"])
    arrays = {f"state_{k}": np.asarray(v) for k, v in state.items()}
    arrays.update({f"history_{k}": np.asarray(v) for k, v in history.items()})
    buf = io.BytesIO()
    np.savez(buf, **arrays)
    write_atomic(folder / f"gen-{gen:09d}.npz", lambda fh: fh.write(buf.getvalue()))
    # Keep this one and the newest older one; files of later generations (foreign or from a
    # run that went further before an overwrite) are left alone.
    older = [
        p
        for p in folder.glob("gen-*.npz")
        if _generation_of(p) is not None and _generation_of(p) < gen
    ]
    for old in sorted(older, key=_generation_of)[: -(KEEP_CHECKPOINTS - 1)]:
        old.unlink(missing_ok=True)


def _generation_of(path: Path) -> int | None:
    try:
        return int(path.stem.removeprefix("gen-"))
    except ValueError:
        return None


def newest(run: Path) -> int | None:
    """The generation of the newest checkpoint file in RUN/checkpoints (checkpoints are
    renamed into place complete), or None."""
    gens = [
        g for p in (run / "checkpoints").glob("gen-*.npz") if (g := _generation_of(p)) is not None
    ]
    return max(gens) if gens else None


def load(run: Path, shapes: dict[str, tuple]):
    """The newest checkpoint that loads completely and holds every entry of ``shapes`` with
    that shape; torn, truncated or foreign files are skipped (and reported), leftovers of
    writes removed. Returns (state arrays by path, history by column, skipped files)."""
    folder = run / "checkpoints"
    remove_leftovers(folder)
    remove_leftovers(run)
    for stray in run.glob(".*.tmp"):  # left by an interrupted save_model of an older version
        stray.unlink(missing_ok=True)
    skipped = []
    for path in sorted(folder.glob("gen-*.npz"), reverse=True):
        try:
            state, history = _read(path, shapes)
            return state, history, skipped
        except Exception as err:  # noqa: BLE001 - any unreadable checkpoint is skipped
            skipped.append(f"{path.name}: {type(err).__name__}")
    return None, None, skipped


def _read(path: Path, shapes: dict[str, tuple]):
    """(state, history) of one checkpoint file; ValueError (or any other) if it does not
    hold every entry of ``shapes`` with that shape and a history up to its generation."""
    raw = path.read_bytes()  # np.load on a path leaks the handle of a corrupt file
    with np.load(io.BytesIO(raw), allow_pickle=False) as z:
        arrays = {k: z[k] for k in z.files}
    state = {k[6:]: v for k, v in arrays.items() if k.startswith("state_")}
    history = {k[8:]: v for k, v in arrays.items() if k.startswith("history_")}
    for k in (*LOOP_KEYS, *shapes):
        if k not in state:
            raise ValueError(f"no entry {k}")
    for k, shape in shapes.items():
        if state[k].shape != shape:
            raise ValueError(f"{k} has shape {state[k].shape}, expected {shape}")
    gen = int(state["generation"])
    if any(len(v) != gen for v in history.values()):
        raise ValueError("history length does not match the generation")
    return state, history
