"""Recorded markers vs model, frame by frame: an animated GIF, and the JSON payload that the
report's in-browser player draws on a canvas.

Both show a 2D projection on the two axes along which the recording spreads most (X-Z, the
sagittal plane, for a horse trotting along X). The view is fitted to the recording, so a free
run that diverges leaves it instead of shrinking everything else.
"""

from __future__ import annotations

import subprocess
import tempfile
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure
from PIL import Image

from ..identify.judge.predictions import to_mm
from .plots import AXES, DPI, FREE_RUN, ONE_STEP
from .predict import Prediction

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
    first_frame: int = 0,
    start_time: float = 0.0,
) -> dict:
    """JSON-ready data for the report's canvas player: the recording and each labelled model's
    one-step and free-run positions, projected to 2D, in mm (None where unknown).

    All predictions must be along the same recording (e.g. the best standard and the best
    neural model of a comparison). ``first_frame``/``start_time``: the recording's number and
    time (s) of the predictions' first frame (``frame_numbers`` and ``times`` are the
    recording's; ``fit_end`` is the number of the first frame after the fitted window)."""
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
        "frame_numbers": (int(first_frame) + idx).tolist(),
        "times": [round(float(start_time) + float(t), 6) for t in first.times[idx]],
        "fit_frames": int(first.fit_frames),
        "first_frame": int(first_frame),
        "fit_end": int(first_frame) + int(first.fit_frames),
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


# The GIF's layout in inches: the axes keep this place and size, the figure grows to the right
# (and down) until the legend beside the axes fits whole.
_SIZE = (7.2, 4.8)
_AXES = (0.864, 0.48, 4.464, 3.936)  # left, bottom, width, height
_CAPTION_FROM_TOP = 0.17
_PAD = 0.08  # inches kept free around the legend
BLOCK = 16  # frames are padded (white) to a multiple of this: what H.264 encoders want


class Scene:
    """The animation's figure (matplotlib's object API, Agg), drawn frame by frame by blitting.

    ``first_frame``/``start_time``: the recording's number and time (s) of the predictions'
    first frame, so captions show frames as numbered in the recording."""

    def __init__(
        self,
        predictions: Sequence[tuple[str, Prediction]],
        *,
        max_frames: int = 120,
        axes: tuple[int, int] | None = None,
        title: str = "",
        first_frame: int = 0,
        start_time: float = 0.0,
    ):
        first = _check_same(predictions)
        self.first, self.title = first, title
        self.first_frame, self.start_time = int(first_frame), float(start_time)
        ax_idx = axes or projection_axes(first.recorded)
        self.indices = _frames(first.n_frames, max_frames)
        sel = list(ax_idx)
        rec = to_mm(first.recorded[:, :, sel])
        view = _view(rec)
        self.bonds = np.asarray(first.bonds, int).reshape(-1, 2)

        fig = self.fig = Figure(figsize=_SIZE, dpi=DPI * 0.8)
        FigureCanvasAgg(fig)  # the object API: no pyplot state, the backend left alone
        ax = self.ax = fig.add_axes((0, 0, 1, 1))
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
                ax.plot([], [], color=color, ls=ls, lw=lw, alpha=alpha, animated=True)[0]
                for _ in self.bonds
            ]

        artists = []
        rec_bonds = lines("0.4", "-", 2.0)
        rec_pts = ax.plot([], [], "o", color="black", ms=6, label="recorded", animated=True)[0]
        artists += [*rec_bonds, rec_pts]
        layers = [(rec, rec_pts, rec_bonds)]
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
        self.legend = ax.legend(
            fontsize=7, loc="upper left", bbox_to_anchor=(1.02, 1.0), borderaxespad=0
        )
        self.caption = fig.text(0.5, 0.5, "", ha="center", va="center", fontsize=9, animated=True)
        self.artists, self.layers = artists, layers
        self._fit_legend()
        fig.canvas.draw()
        self.background = fig.canvas.copy_from_bbox(fig.bbox)

    def _place(self, width: float, height: float) -> None:
        left, bottom, w, h = _AXES
        top_margin = _SIZE[1] - bottom - h
        self.fig.set_size_inches(width, height)
        self.ax.set_position(
            (left / width, (height - top_margin - h) / height, w / width, h / height)
        )
        self.caption.set_position((0.5, 1 - _CAPTION_FROM_TOP / height))

    def _fit_legend(self) -> None:
        """Grow the figure until the legend (beside the axes) lies inside it with a margin."""
        width, height = _SIZE
        self._place(width, height)
        for _ in range(3):
            self.fig.canvas.draw()
            box = self.legend.get_window_extent(self.fig.canvas.get_renderer())
            dpi = self.fig.dpi
            right = box.x1 / dpi + _PAD - width
            below = _PAD - box.y0 / dpi
            if right <= 0 and below <= 0:
                return
            width, height = width + max(right, 0.0), height + max(below, 0.0)
            self._place(width, height)

    def _draw(self, points, pts_artist, bond_artists, f) -> None:
        xy = points[f]
        ok = np.isfinite(xy).all(axis=-1)
        pts_artist.set_data(xy[ok, 0], xy[ok, 1])
        for (i, j), line in zip(self.bonds, bond_artists, strict=True):
            if ok[i] and ok[j]:
                line.set_data([xy[i, 0], xy[j, 0]], [xy[i, 1], xy[j, 1]])
            else:
                line.set_data([], [])

    def caption_text(self, f: int) -> str:
        """'frame N  t = T s  (where)' with N and T as in the recording."""
        where = "fitted window" if f < self.first.fit_frames else "beyond the fit"
        number = self.first_frame + int(f)
        t = self.start_time + float(self.first.times[f])
        prefix = f"{self.title}  " if self.title else ""
        return f"{prefix}frame {number}  t = {t:.3f} s  ({where})"

    def render(self, f: int) -> np.ndarray:
        """Frame ``f`` (index into the predictions) as RGB [H, W, 3] uint8, padded with white
        to a multiple of :data:`BLOCK` pixels each way."""
        for data, pts, bl in self.layers:
            self._draw(data, pts, bl, f)
        self.caption.set_text(self.caption_text(f))
        canvas = self.fig.canvas
        canvas.restore_region(self.background)
        for a in self.artists:
            self.ax.draw_artist(a)
        self.fig.draw_artist(self.caption)
        rgb = np.asarray(canvas.buffer_rgba())[..., :3]
        h, w = rgb.shape[:2]
        out = np.full((-(-h // BLOCK) * BLOCK, -(-w // BLOCK) * BLOCK, 3), 255, np.uint8)
        out[:h, :w] = rgb
        return out

    def frames(self) -> list[np.ndarray]:
        return [self.render(f) for f in self.indices]


def _save_gif(images: list[np.ndarray], path: Path, fps: float) -> Path:
    frames = [
        Image.fromarray(a).quantize(
            colors=64, method=Image.Quantize.FASTOCTREE, dither=Image.Dither.NONE
        )
        for a in images
    ]
    path.parent.mkdir(parents=True, exist_ok=True)
    frames[0].save(
        path,
        save_all=True,
        append_images=frames[1:],
        duration=int(round(1000.0 / fps)),
        loop=0,
        optimize=False,
    )
    return path


def _ffmpeg() -> str:
    """The ffmpeg binary of imageio-ffmpeg (ImportError or RuntimeError when there is none)."""
    import imageio_ffmpeg

    return imageio_ffmpeg.get_ffmpeg_exe()


def write_mp4(images: Sequence[np.ndarray], path: str | Path, *, fps: float = 12.0) -> Path:
    """Encode RGB frames [H, W, 3] (even sides) as an H.264 MP4 (yuv420p, fast start) with
    the ffmpeg binary that ``imageio-ffmpeg`` ships. Raises ImportError/RuntimeError/OSError
    when that is not possible; no partial file is left.

    ffmpeg is started without a ``preexec_fn`` (unlike ``imageio_ffmpeg.write_frames``): no
    Python code runs in the forked child of this multithreaded (JAX) process."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    exe = _ffmpeg()
    h, w = images[0].shape[:2]
    tmp = path.with_name(f".{path.stem}.tmp{path.suffix}")
    cmd = [
        exe, "-y", "-loglevel", "error", "-hide_banner",
        "-f", "rawvideo", "-pix_fmt", "rgb24", "-s", f"{w}x{h}", "-r", f"{fps:g}", "-i", "-",
        "-an", "-c:v", "libx264", "-pix_fmt", "yuv420p", "-crf", "20",
        "-movflags", "+faststart", "-f", "mp4", str(tmp),
    ]  # fmt: skip
    try:
        with tempfile.TemporaryFile() as log:
            proc = subprocess.Popen(cmd, stdin=subprocess.PIPE, stdout=log, stderr=log)
            try:
                for a in images:
                    proc.stdin.write(np.ascontiguousarray(a, dtype=np.uint8).tobytes())
                proc.stdin.close()
                code = proc.wait(timeout=120)
            except BaseException:
                proc.kill()
                proc.wait()
                raise
            if code != 0:
                log.seek(0)
                lines = log.read().decode("utf-8", "replace").strip().splitlines()
                raise RuntimeError(f"ffmpeg exited with {code}: {lines[-1] if lines else ''}")
        tmp.replace(path)
    except subprocess.TimeoutExpired as e:
        raise RuntimeError(f"ffmpeg took more than {e.timeout:g} s") from None
    finally:
        tmp.unlink(missing_ok=True)
    return path


@dataclass(frozen=True)
class Media:
    """The animation's files: the GIF, and the MP4 or None with ``note`` saying why not."""

    gif: Path
    mp4: Path | None
    note: str = ""


def write_animation(
    predictions: Sequence[tuple[str, Prediction]],
    gif_path: str | Path,
    *,
    mp4: bool = True,
    fps: float = 12.0,
    max_frames: int = 120,
    axes: tuple[int, int] | None = None,
    title: str = "",
    first_frame: int = 0,
    start_time: float = 0.0,
) -> Media:
    """The animation as a GIF at ``gif_path`` and (``mp4``) the same frames as an MP4 beside
    it (same stem). Without a working ffmpeg the GIF is still written and ``note`` says, in
    one line, why there is no MP4."""
    scene = Scene(
        predictions,
        max_frames=max_frames,
        axes=axes,
        title=title,
        first_frame=first_frame,
        start_time=start_time,
    )
    images = scene.frames()
    gif = _save_gif(images, Path(gif_path), fps)
    if not mp4:
        return Media(gif, None)
    try:
        video = write_mp4(images, gif.with_suffix(".mp4"), fps=fps)
    except (ImportError, RuntimeError, OSError, ValueError) as e:
        first_line = (str(e).strip().splitlines() or [type(e).__name__])[0]
        return Media(gif, None, f"No MP4 of the animation: ffmpeg is unavailable ({first_line}).")
    return Media(gif, video)


def write_gif(predictions: Sequence[tuple[str, Prediction]], path: str | Path, **options) -> Path:
    """An animated GIF of the recording (black) and each model's one-step (circles, solid
    bonds) and free-run (squares, dashed bonds) positions in the 2D projection; ``options``:
    :func:`write_animation`'s (``fps``, ``max_frames``, ``axes``, ``title``, ``first_frame``,
    ``start_time``)."""
    return write_animation(predictions, path, mp4=False, **options).gif
