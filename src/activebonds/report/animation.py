"""Recorded markers vs model, frame by frame: an animated GIF, and the JSON payload that the
report's in-browser player draws on a canvas.

Both show a 2D projection on the two axes along which the recording spreads most (X-Z, the
sagittal plane, for a horse trotting along X). The view is fitted to the recording, so a free
run that diverges leaves it instead of shrinking everything else.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import numpy as np
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure
from PIL import Image

from .plots import AXES, DPI, FREE_RUN, ONE_STEP
from .predict import Prediction, to_mm

MODEL_COLORS = ("tab:blue", "tab:orange", "tab:green", "tab:red", "tab:purple", "tab:brown")


def projection_axes(positions: np.ndarray) -> tuple[int, int]:
    """The two axes with the largest spread of the recorded positions [F, P, D], in order."""
    pos = np.asarray(positions, np.float64)
    if pos.shape[-1] <= 2:
        return (0, 1)
    finite = np.isfinite(pos).all(axis=-1)
    if not finite.any():
        return (0, 1)
    pts = pos[finite]
    spread = pts.max(axis=0) - pts.min(axis=0)
    a, b = sorted(np.argsort(-spread, kind="stable")[:2].tolist())
    return int(a), int(b)


def _check_same(predictions: Sequence[tuple[str, Prediction]]) -> Prediction:
    if not predictions:
        raise ValueError("no prediction to animate")
    first = predictions[0][1]
    for label, p in predictions[1:]:
        same = p.recorded.shape == first.recorded.shape and np.allclose(
            np.nan_to_num(p.recorded), np.nan_to_num(first.recorded), rtol=0, atol=1e-9
        )
        if not same:
            raise ValueError(f"{label}: predictions of different recordings cannot share a view")
    return first


def _view(rec2: np.ndarray) -> list[float]:
    """[xmin, xmax, ymin, ymax] of the projected recording (mm), with a margin."""
    finite = np.isfinite(rec2).all(axis=-1)
    pts = rec2[finite] if finite.any() else np.zeros((1, 2))
    lo, hi = pts.min(axis=0), pts.max(axis=0)
    pad = np.maximum(0.08 * (hi - lo).max(), 20.0)
    return [float(lo[0] - pad), float(hi[0] + pad), float(lo[1] - pad), float(hi[1] + pad)]


def _frames(n: int, max_frames: int) -> np.ndarray:
    stride = max(1, int(np.ceil(n / max_frames)))
    return np.arange(0, n, stride)


def _json_array(a: np.ndarray, digits: int = 2):
    """Nested lists with NaN/inf as None (valid JSON), rounded."""
    a = np.round(np.asarray(a, np.float64), digits)
    flat = [None if not np.isfinite(v) else float(v) for v in a.reshape(-1)]
    out: list = flat
    for size in reversed(a.shape[1:]):
        out = [out[i : i + size] for i in range(0, len(out), size)]
    return out


def payload(
    predictions: Sequence[tuple[str, Prediction]],
    *,
    title: str = "",
    axes: tuple[int, int] | None = None,
    max_frames: int = 1500,
) -> dict:
    """JSON-ready data for the report's canvas player: the recording and each labelled model's
    one-step and free-run positions, projected to 2D, in mm (None where unknown).

    All predictions must be along the same recording (e.g. the best standard and the best
    neural model of a comparison)."""
    first = _check_same(predictions)
    ax = axes or projection_axes(first.recorded)
    idx = _frames(first.n_frames, max_frames)
    sel = list(ax)

    def proj(a: np.ndarray) -> np.ndarray:
        return to_mm(a[idx][:, :, sel])

    rec2 = proj(first.recorded)
    return {
        "title": title,
        "names": list(first.names),
        "bonds": np.asarray(first.bonds, int).tolist(),
        "axes": [AXES[a] for a in ax],
        "frame_numbers": idx.tolist(),
        "times": [round(float(t), 6) for t in first.times[idx]],
        "fit_frames": int(first.fit_frames),
        "view": _view(rec2),
        "recorded": _json_array(rec2),
        "models": [
            {
                "label": label,
                "one_step": _json_array(proj(p.one_step)),
                "free_run": _json_array(proj(p.free_run)),
            }
            for label, p in predictions
        ],
    }


def _colors(n_models: int, i: int) -> tuple[str, str]:
    if n_models == 1:
        return ONE_STEP, FREE_RUN
    c = MODEL_COLORS[i % len(MODEL_COLORS)]
    return c, c


def write_gif(
    predictions: Sequence[tuple[str, Prediction]],
    path: str | Path,
    *,
    fps: float = 12.0,
    max_frames: int = 120,
    axes: tuple[int, int] | None = None,
    title: str = "",
) -> Path:
    """An animated GIF of the recording (black) and each model's one-step (circles, solid
    bonds) and free-run (squares, dashed bonds) positions in the 2D projection."""
    first = _check_same(predictions)
    ax_idx = axes or projection_axes(first.recorded)
    idx = _frames(first.n_frames, max_frames)
    sel = list(ax_idx)
    rec = to_mm(first.recorded[:, :, sel])
    view = _view(rec)
    bonds = np.asarray(first.bonds, int).reshape(-1, 2)

    fig = Figure(figsize=(7.2, 4.8), dpi=DPI * 0.8)
    FigureCanvasAgg(fig)  # the object API: no pyplot state, the backend left alone
    ax = fig.subplots()
    fig.subplots_adjust(left=0.12, right=0.74, bottom=0.1, top=0.92)
    ax.set_xlim(view[0], view[1])
    ax.set_ylim(view[2], view[3])
    ax.set_aspect("equal", adjustable="box")
    ax.set_xlabel(f"{AXES[ax_idx[0]]} (mm)")
    ax.set_ylabel(f"{AXES[ax_idx[1]]} (mm)")
    ax.grid(True, alpha=0.3)
    for p in range(rec.shape[1]):  # the recorded paths, faint
        ax.plot(rec[:, p, 0], rec[:, p, 1], color="0.85", lw=1, zorder=0)

    def lines(color, ls, lw, alpha=1.0):
        return [
            ax.plot([], [], color=color, ls=ls, lw=lw, alpha=alpha, animated=True)[0] for _ in bonds
        ]

    artists = []
    rec_bonds = lines("0.4", "-", 2.0)
    rec_pts = ax.plot([], [], "o", color="black", ms=6, label="recorded", animated=True)[0]
    artists += [*rec_bonds, rec_pts]
    layers = []
    n_models = len(predictions)
    for i, (label, p) in enumerate(predictions):
        c1, c2 = _colors(n_models, i)
        prefix = "" if n_models == 1 else f"{label} "
        for data, color, marker, ls, kind in (
            (p.one_step, c1, "o", "-", "one-step"),
            (p.free_run, c2, "s", "--", "free run"),
        ):
            pts = ax.plot(
                [],
                [],
                marker,
                mfc="none",
                mec=color,
                mew=1.5,
                ms=8,
                ls="none",
                label=f"{prefix}{kind}",
                animated=True,
            )[0]
            bl = lines(color, ls, 1.3, 0.9)
            layers.append((to_mm(data[:, :, sel]), pts, bl))
            artists += [*bl, pts]
    ax.legend(fontsize=7, loc="upper left", bbox_to_anchor=(1.02, 1.0), borderaxespad=0)
    caption = fig.text(0.5, 0.965, "", ha="center", va="center", fontsize=9, animated=True)
    artists.append(caption)
    fig.canvas.draw()
    background = fig.canvas.copy_from_bbox(fig.bbox)

    def draw(points, pts_artist, bond_artists, f):
        xy = points[f]
        ok = np.isfinite(xy).all(axis=-1)
        pts_artist.set_data(xy[ok, 0], xy[ok, 1])
        for (i, j), line in zip(bonds, bond_artists, strict=True):
            if ok[i] and ok[j]:
                line.set_data([xy[i, 0], xy[j, 0]], [xy[i, 1], xy[j, 1]])
            else:
                line.set_data([], [])

    images = []
    for f in idx:
        draw(rec, rec_pts, rec_bonds, f)
        for data, pts, bl in layers:
            draw(data, pts, bl, f)
        where = "fitted window" if f < first.fit_frames else "beyond the fit"
        caption.set_text(
            f"{title + '  ' if title else ''}frame {f}  t = {first.times[f]:.3f} s  ({where})"
        )
        fig.canvas.restore_region(background)
        for a in artists[:-1]:
            ax.draw_artist(a)
        fig.draw_artist(caption)
        rgba = np.asarray(fig.canvas.buffer_rgba())
        images.append(
            Image.fromarray(rgba[..., :3]).quantize(
                colors=64, method=Image.Quantize.FASTOCTREE, dither=Image.Dither.NONE
            )
        )
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    images[0].save(
        path,
        save_all=True,
        append_images=images[1:],
        duration=int(round(1000.0 / fps)),
        loop=0,
        optimize=False,
    )
    return path
