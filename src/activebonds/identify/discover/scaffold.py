"""A candidate model written from a recording (``activebonds scaffold``): every number of it
with a comment saying where it came from, every candidate bond ``optional = true`` for
``activebonds structure``.

What is written, and the rules (``P`` markers, rate ``f`` Hz, window ``T`` seconds):

* **Particles**: one per marker, placed at the first frame of the window where every marker
  is present (its velocity the backward difference there, the forward one at the window's
  first frame). Masses are fixed, ``total_mass / P`` each (``--total-mass``, default
  :data:`MASS_PER_MARKER` kg per marker); free them (as ratios of ``total_mass``) once the
  structure is chosen, as ``structure`` needs fixed masses.
* **Candidate bonds** (binary springs). Up to :data:`COMPLETE_MAX` markers (``P (P + 1) / 2``
  candidates, at most 36: few enough for ``structure``'s elimination, which ``activebonds
  auto`` runs up to 40), **every pair** of markers and **an anchor per marker** (below); the
  reasons that follow are still named beside each pair. Beyond (or with ``--neighbours``), the
  union of the ``k`` nearest neighbours of each marker by median distance (``k`` = :data:`NEIGHBOURS` of the dimension), the near-rigid
  pairs among each marker's ``2 k`` nearest (their distance's spread, 5th to 95th
  percentile, at most :data:`RIGID` of its median) and, up to :data:`DELAUNAY_MAX` markers,
  the edges of the Delaunay triangulation of the markers at the placement frame (braces that
  nearest neighbours miss; beyond, their number and ``structure``'s time, which grows with
  the square of the candidates, grow fast).
* **Rest length**: the pair's median distance; bounds the observed range (minimum to maximum)
  widened by half the range on each side and to at least :data:`REST_MARGIN` of the median
  (a spring compressed under a load is never seen at its rest length). In a complete graph,
  from 0 to :data:`REST_REACH` times the largest distance seen: there a spring is also a
  regression term of the exact least squares, and one held far from its rest length adds a
  nearly constant pull along the pair (on the horse, the narrower bounds cost 0.1 mm of
  held-out one-step error; docs/experiments/auto.md).
* **Anchors** (complete graphs only): a unary spring-damper per marker, ``-k (x - a) - c v``,
  its anchor ``a`` free from the marker's median position to :data:`ANCHOR_REACH` times the
  recording's extent (the largest distance between two markers) away on each axis: a body held
  in place (on a treadmill, by its own legs) is pulled back to where it stays, and a far anchor
  with a weak spring is a nearly constant force (a weight held up). Stiffness and damping as a
  spring's (below) with the marker's mass for ``mu``; the value of ``k`` from the marker's own
  acceleration and distance from its median position.
* **Stiffness** (N/m) and **damping** (N s/m), from the pair's reduced mass
  ``mu = m_i m_j / (m_i + m_j)``, the rate and the window:

  - bounds ``k in [mu (2 pi / T)^2 / 10, 10 mu (pi f)^2]``: from a tenth of the spring whose
    oscillation takes the whole window to ten times the one oscillating at the Nyquist
    frequency ``f / 2`` (no recording at ``f`` Hz over ``T`` s shows a softer or a stiffer
    spring as anything but absent or rigid, so a fit does not sit on them);
  - bounds ``c in [2 mu / (100 T), 20 mu f]``: from a damper whose decay takes a hundred
    windows (invisible) to ten times the one that stops the relative motion within one frame;
  - values from the amplitudes: ``k = mu rms(L'') / rms(L - median L)`` (the stiffness whose
    force explains the pair's relative acceleration along it by its stretch; ``L''`` the
    second difference of its length over ``dt^2``) and ``c`` = 10 % of the critical damping
    ``2 sqrt(k mu)``, each clipped into its bounds.
* **Gravity** (``-9.81`` m/s^2 along the vertical) only where the vertical is confident: the
  ground guess is clear, the acceleration guess does not contradict it, and, without a flight
  phase to confirm it, the feet do not (a ground resting on one marker while along another
  direction several markers reach the lowest height often)
  (:mod:`activebonds.data.orientation`); where it is not but the markers fall at about g in
  flight along a direction (:func:`~activebonds.data.orientation.guess_gravity`: gravity
  itself, measured), that direction; otherwise none, and the summary says so (``--up``
  names the vertical, ``--no-gravity`` leaves it out). A flat recording (2D, or with no
  extent along an axis) has no vertical to guess.
* **Ground contacts** (with gravity): one per marker within reach of the ground (2 cm, or 7 %
  of the body's size where less: :func:`.gravity.contact_reach`), above or below it,
  in at least :data:`CONTACT_SHARE` of the frames, the plane at the guessed ground
  (height free within :data:`HEIGHT_RANGE`); stiffness ``M g / (n delta)`` (the whole weight
  ``M g`` shared by the ``n`` contacts at a penetration ``delta`` = :data:`PENETRATION`),
  bounds a factor 100 either way; damping 10 % of critical for a mass ``M / n``, bounds a
  factor 100 either way; friction 0.8 in ``[0, 2]``. On a treadmill (the contact markers
  move along the ground at a median velocity over :data:`BELT_SPEED` while on it, and that
  much faster than the markers' mean: a body sliding with its feet rides no belt; all at about
  that velocity, the interquartile range of their velocities within :data:`BELT_SPREAD` of it:
  a low point swinging through, as a pendulum's, rides none) the belt's velocity, that median,
  is the contacts' fixed ``surface_velocity``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from ... import bonds
from ...data.orientation import AXES
from ...errors import InputError
from ...nanstats import nanmean
from .gravity import G, contact_blocks, gravity_axis
from .model_text import quoted, searched, vector

MASS_PER_MARKER = 1.0  # kg: the default total mass is this times the markers
RIGID = 0.05  # a near-rigid pair's distance spread (5th-95th percentile) / its median
NEIGHBOURS = {2: 3, 3: 4}  # nearest neighbours per marker, by dimension
RIGID_REACH = 2  # near-rigid pairs are looked for among this many times k nearest neighbours
DELAUNAY_MAX = 16  # markers: the Delaunay edges are candidates up to this many (they grow fast)
COMPLETE_MAX = 8  # markers: up to this many, every pair and an anchor per marker are candidates
REST_REACH = 2.0  # complete graph: rest lengths from 0 to this times the largest distance seen
ANCHOR_REACH = 2.0  # anchors: free this many extents of the recording about the median position
REST_MARGIN = 0.2  # the rest length's bounds reach at least this share of the median


@dataclass
class Scaffold:
    """The candidate model's text and what it is made of, for people."""

    text: str
    particles: int
    bonds: int
    contacts: int
    gravity: str  # "-Z" or "none"
    notes: list[str] = field(default_factory=list)


def _window(traj, markers, frames):
    if markers is not None:
        traj.check_markers(markers)
        if len(set(markers)) != len(markers):
            raise InputError("--markers", "a marker is named twice")
        traj = traj.select(list(markers))
    start, stop = frames
    n = traj.n_frames
    stop = n if stop is None else stop
    if not (0 <= start < stop <= n):
        raise InputError("--frames", f"{start}:{stop} is not a window of the {n} frames")
    if stop - start < 3:
        raise InputError("--frames", f"{start}:{stop} holds fewer than 3 frames")
    return traj.window(start, stop), start


def _delaunay(x: np.ndarray) -> set[tuple[int, int]]:
    """The edges (i < j) of the Delaunay triangulation of the points x [P, D] (none where
    the points are too few or flat: no simplex of full dimension)."""
    from scipy.spatial import Delaunay, QhullError

    if x.shape[0] <= x.shape[1]:
        return set()
    try:
        simplices = Delaunay(x).simplices
    except (QhullError, ValueError):
        return set()
    edges = set()
    for simplex in simplices:
        for a in range(len(simplex)):
            for b in range(a + 1, len(simplex)):
                i, j = sorted((int(simplex[a]), int(simplex[b])))
                edges.add((i, j))
    return edges


def _pairs(
    dist: np.ndarray, spread: np.ndarray, k: int, placed: np.ndarray
) -> dict[tuple[int, int], list[str]]:
    """Candidate pairs (i < j) and why each is one."""
    p = dist.shape[0]
    why: dict[tuple[int, int], list[str]] = {}
    if p <= DELAUNAY_MAX:
        for i, j in sorted(_delaunay(placed)):
            why.setdefault((i, j), []).append("a Delaunay edge at the placement frame")
    order = np.argsort(np.where(np.eye(p, dtype=bool), np.inf, dist), axis=1)
    local = np.zeros((p, p), bool)
    for i in range(p):
        local[i, order[i, : RIGID_REACH * k]] = True
    for i in range(p):
        for j in range(i + 1, p):
            if spread[i, j] <= RIGID and (local[i, j] or local[j, i]):
                why.setdefault((i, j), []).append(
                    f"near-rigid (distance spread {100 * spread[i, j]:.2g} % of its median)"
                )
    for i in range(p):
        for rank, j in enumerate(order[i, : min(k, p - 1)]):
            if not np.isfinite(dist[i, j]):
                continue
            a, b = sorted((i, int(j)))
            why.setdefault((a, b), []).append(f"neighbour {rank + 1} of particle {i}")
    return dict(sorted(why.items()))


def scaffold(
    traj,
    markers: list[str] | None = None,
    frames: tuple[int, int | None] = (0, None),
    total_mass: float | None = None,
    up: str | None = None,
    gravity: bool | None = None,
    neighbours: int | None = None,
    name: str | None = None,
    complete: bool | None = None,
) -> Scaffold:
    """The candidate model of a recording (see the module's docstring); ``complete``: every
    pair and an anchor per marker (default: up to :data:`COMPLETE_MAX` markers, unless
    ``neighbours`` is given). InputError (one line) for one marker, no frame with every marker, a flat recording asked for gravity, a
    total mass <= 0 or unknown markers."""
    source = traj.source or "the recording"
    data, offset, x, mask, whole = _checked(traj, markers, frames, total_mass, neighbours)
    names = list(data.markers)
    f_count, p, d = x.shape
    notes: list[str] = []
    vertical = gravity_axis(data, up, gravity, notes)
    total, mass_note = _total_mass(total_mass, p, notes)
    t0, v0, how = _placement(x, mask, int(whole[0]), data.dt)
    if complete is None:
        complete = neighbours is None and p <= COMPLETE_MAX
    graph = _Graph(x, neighbours or NEIGHBOURS[d], t0, complete)
    bounds = _Bounds(total / p / 2.0, data.rate, (f_count - 1) * data.dt)
    lines = [
        f"# Candidate model of {source}, written by activebonds scaffold.",
        f"# Frames {offset}:{offset + f_count} ({f_count} frames at {data.rate:g} Hz, T = "
        f"{bounds.duration:.4g} s), {p} markers.",
        "# Every candidate bond is optional: `activebonds structure` decides which the recording",
        "# needs. The rules behind every number: activebonds.identify.discover.scaffold's docstring.",
        f"name = {quoted(name or 'scaffold')}",
        f"dimension = {d}  # the recording's",
    ]
    bond_blocks: list[str] = []
    up_text = "none"
    if vertical is not None:
        axis, sign = vertical
        g = [0.0] * d
        g[axis] = -sign * G
        up_text = ("-" if sign > 0 else "+") + AXES[axis]
        lines.append(f"gravity = {vector(g)}  # m/s^2: {notes[-1]}")
        bond_blocks += contact_blocks(x, mask, names, axis, sign, total, data.dt, notes)
    contacts = len(bond_blocks)
    m = total / p
    lines.append(f"total_mass = {total!r}  # kg: {mass_note}, split equally over the {p} particles")
    for i, n in enumerate(names):
        lines += [
            "",
            "[[particle]]",
            f"name = {quoted(n)}",
            f"mass = {m!r}  # kg: total_mass / {p} (fixed: structure needs fixed masses)",
            f"position = {vector(x[t0, i])}  # m: frame {offset + t0}, the first with every marker",
            f"velocity = {vector(v0[i])}  # m/s: at frame {offset + t0}, {how}",
        ]
    for (i, j), why in graph.pairs.items():
        bond_blocks.append(_pair_block(graph, bounds, names, i, j, why, data.dt))
    anchors = []
    if complete:
        extent = float(np.nanmax(graph.med))  # the largest median distance between two markers
        limits = (m / bounds.mu) * np.array([*bounds.k, *bounds.c])
        anchors = _anchors(x, names, m, limits, data.dt, extent)
        notes.append(
            f"candidates: every pair of the {p} markers and an anchor per marker (at most "
            f"{COMPLETE_MAX} markers; --neighbours K for a neighbourhood graph)"
        )
    text = "\n".join(lines) + "\n" + "\n".join(bond_blocks + anchors) + "\n"
    bonds_count = len(graph.pairs) + len(anchors)
    return Scaffold(text, p, bonds_count, contacts, up_text, notes)


def _checked(traj, markers, frames, total_mass, neighbours):
    """(the window's recording, its first frame, positions [F, P, D], mask [F, P], the frames
    with every marker): the scaffold's inputs checked, one InputError line otherwise."""
    source = traj.source or "the recording"
    if total_mass is not None and not (math.isfinite(total_mass) and total_mass > 0):
        raise InputError("--total-mass", f"must be a number of kg > 0, got {total_mass:g}")
    if neighbours is not None and neighbours < 1:
        raise InputError("--neighbours", f"must be at least 1, got {neighbours}")
    data, offset = _window(traj, markers, frames)
    names = list(data.markers)
    p = len(names)
    if p < 2:
        raise InputError(
            "--markers" if markers is not None else source,
            f"one marker ({names[0]}): a model needs at least two to bond",
        )
    x = np.asarray(data.positions, np.float64)  # [F, P, D]
    mask = np.asarray(data.mask, bool)
    f_count = x.shape[0]
    whole = np.flatnonzero(mask.all(axis=1))  # the frames with every marker
    if whole.size == 0:
        raise InputError(
            source,
            f"no frame of {offset}:{offset + f_count} holds every one of the {p} markers; "
            "choose --markers or --frames where they are all present (activebonds info)",
        )
    return data, offset, x, mask, whole


def _total_mass(total_mass: float | None, p: int, notes: list[str]) -> tuple[float, str]:
    """(the total mass in kg, where it comes from): ``--total-mass``, else
    :data:`MASS_PER_MARKER` per marker (noted: the forces then scale with it)."""
    if total_mass is not None:
        return float(total_mass), "--total-mass"
    notes.append(
        f"masses: {MASS_PER_MARKER:g} kg per marker (no --total-mass): every stiffness and "
        "damping identified scales with the masses (markers alone cannot tell the force "
        "scale); give --total-mass KG for forces in newtons"
    )
    return p * MASS_PER_MARKER, f"{MASS_PER_MARKER:g} kg per marker (default)"


def _placement(x: np.ndarray, mask: np.ndarray, t0: int, dt: float):
    """(frame, velocities [P, D], how they were measured) of the placement: the first complete
    frame ``t0``, its velocity by a backward (else forward) difference."""
    f_count, p, d = x.shape
    if t0 > 0 and mask[t0 - 1].all():
        return t0, (x[t0] - x[t0 - 1]) / dt, "backward difference"
    if t0 + 1 < f_count and mask[t0 + 1].all():
        return t0, (x[t0 + 1] - x[t0]) / dt, "forward difference"
    return t0, np.zeros((p, d)), "none measurable (no complete neighbour frame): zero"


class _Graph:
    """The candidate pairs: the pairs' distances over the frames where both are present
    (``length`` [F, P, P], NaN where one is missing; their median ``med``) and the pairs
    (i < j) with why each is one; every pair where ``complete``."""

    def __init__(self, x: np.ndarray, k_nn: int, t0: int, complete: bool):
        p = x.shape[1]
        diff = x[:, :, None, :] - x[:, None, :, :]
        self.length = np.sqrt(np.sum(diff**2, axis=-1))
        self.complete = complete
        with np.errstate(all="ignore"):
            self.med = np.nanmedian(self.length, axis=0)
            lo5, hi95 = np.nanpercentile(self.length, [5, 95], axis=0)
            spread = (hi95 - lo5) / self.med
        pairs = _pairs(self.med, np.nan_to_num(spread, nan=np.inf), k_nn, x[t0])
        if complete:
            every = f"every pair ({p} markers: the complete graph)"
            pairs = {
                (i, j): [every, *pairs.get((i, j), [])]
                for i in range(p)
                for j in range(i + 1, p)
                if np.isfinite(self.med[i, j])
            }
        self.pairs = pairs


@dataclass(frozen=True)
class _Bounds:
    """A spring-damper's search bounds for the reduced mass ``mu`` of a pair of equal masses,
    from the recording's ``rate`` (Hz) and ``duration`` (s)."""

    mu: float
    rate: float
    duration: float

    @property
    def k(self) -> tuple[float, float]:
        mu = self.mu
        return mu * (2 * math.pi / self.duration) ** 2 / 10, 10 * mu * (math.pi * self.rate) ** 2

    @property
    def c(self) -> tuple[float, float]:
        return 2 * self.mu / (100 * self.duration), 20 * self.mu * self.rate


def _pair_block(graph: _Graph, bounds: _Bounds, names, i: int, j: int, why, dt: float) -> str:
    """The [[bond]] block of the candidate spring-damper between markers i and j."""
    series = graph.length[:, i, j]
    seen = np.isfinite(series)
    dmin, dmax = float(np.nanmin(series)), float(np.nanmax(series))
    l0 = float(graph.med[i, j])
    half = 0.5 * (dmax - dmin)
    rl_lo = max(0.0, min(dmin - half, (1 - REST_MARGIN) * l0))
    rl_hi = max(dmax + half, (1 + REST_MARGIN) * l0)
    rest_rule = f"widened by half the range and to +-{100 * REST_MARGIN:g} % of the median"
    if graph.complete:
        rl_lo, rl_hi = 0.0, REST_REACH * dmax
        rest_rule = f"bounds 0 .. {REST_REACH:g} x the largest (a complete graph)"
    stretch = series - l0
    acc = (series[2:] - 2 * series[1:-1] + series[:-2]) / dt**2
    acc = acc[np.isfinite(acc)]
    rms_s = float(np.sqrt(nanmean(stretch**2)))
    rms_a = float(np.sqrt(np.mean(acc**2))) if acc.size else 0.0
    mu, (k_lo, k_hi), (c_lo, c_hi) = bounds.mu, bounds.k, bounds.c
    k0, c0 = _start_values(mu, rms_a, rms_s, (k_lo, k_hi), (c_lo, c_hi))
    return "\n".join(
        [
            "",
            f"# {names[i]}-{names[j]}: {'; '.join(why)}".replace(f"particle {i}", names[i]).replace(
                f"particle {j}", names[j]
            ),
            "[[bond]]",
            f"kind = {quoted(bonds.binary.KIND.name)}",
            f"particles = [{quoted(names[i])}, {quoted(names[j])}]",
            "optional = true",
            f"rest_length = {searched(l0, rl_lo, rl_hi)}  # m: median distance over "
            f"{int(seen.sum())} frames; observed {dmin:.4g}..{dmax:.4g}, {rest_rule}",
            f"stiffness = {searched(k0, k_lo, k_hi)}  # N/m: mu {mu:.4g} kg x rms "
            f"acceleration {rms_a:.3g} m/s^2 / rms stretch {1000 * rms_s:.3g} mm; "
            f"bounds mu (2 pi / {bounds.duration:.4g} s)^2 / 10 .. 10 mu (pi {bounds.rate:g} Hz)^2",
            f"damping = {searched(c0, c_lo, c_hi)}  # N s/m: 10 % of critical "
            f"2 sqrt(k mu); bounds 2 mu / (100 T) .. 20 mu f",
        ]
    )


def _anchors(x, names, m, limits, dt, extent) -> list[str]:
    """The anchors' [[bond]] blocks: a unary spring-damper per marker, its anchor free about
    the marker's median position (see the module's docstring); ``limits``: the stiffness and
    damping bounds (k_lo, k_hi, c_lo, c_hi) for a mass ``m``."""
    out = []
    reach = ANCHOR_REACH * extent
    unary = bonds.unary.KIND.name
    k_lo, k_hi, c_lo, c_hi = (float(v) for v in limits)
    for i, n in enumerate(names):
        xi = x[:, i]
        centre = np.nanmedian(xi, axis=0)
        dist = np.sqrt(np.nansum((xi - centre) ** 2, axis=-1))
        dist = dist[np.isfinite(xi).all(axis=-1)]
        acc = (xi[2:] - 2 * xi[1:-1] + xi[:-2]) / dt**2
        acc = np.sqrt(np.sum(acc**2, axis=-1))
        acc = acc[np.isfinite(acc)]
        rms_d = float(np.sqrt(np.mean(dist**2))) if dist.size else 0.0
        rms_a = float(np.sqrt(np.mean(acc**2))) if acc.size else 0.0
        k0, c0 = _start_values(m, rms_a, rms_d, (k_lo, k_hi), (c_lo, c_hi))
        out.append(
            "\n".join(
                [
                    "",
                    f"# {n} anchored: a candidate of the complete graph",
                    "[[bond]]",
                    f"kind = {quoted(unary)}",
                    f"particles = [{quoted(n)}]",
                    "optional = true",
                    f"anchor = {{ value = {vector(centre)}, min = {vector(centre - reach)}, "
                    f"max = {vector(centre + reach)} }}  # m: the marker's median position, free "
                    f"{ANCHOR_REACH:g} x the recording's extent {extent:.4g} m about it",
                    f"stiffness = {searched(k0, k_lo, k_hi)}  # N/m: its mass {m:.4g} kg x rms "
                    f"acceleration {rms_a:.3g} m/s^2 / rms distance from the median "
                    f"{1000 * rms_d:.3g} mm; bounds as a spring's, m for mu",
                    f"damping = {searched(c0, c_lo, c_hi)}  # N s/m: 10 % of critical "
                    "2 sqrt(k m); bounds as a spring's, m for mu",
                ]
            )
        )
    return out


def neural_text(found, recording=None) -> str:
    """The model file of a structure result (``FOUND.toml``) with its present springs as
    mechanical-neural bonds (``fit --bonds neural``'s defaults for the neural parameters) and
    its absent candidates dropped: neural bonds cannot be optional. With ``recording``, its
    markers must hold the model's (InputError otherwise)."""
    from ...model import dumps_model, load_model
    from ...model.variants import as_neural

    model = load_model(found)
    if recording is not None:
        missing = [m for m in model.markers if m not in recording.markers]
        if missing:
            raise InputError(
                recording.source or "the recording",
                f"has no marker {missing[0]!r} of {found}",
            )
    kept = [
        b.model_copy(update={"optional": None, "present": None})
        for b in model.spec.bond
        if not b.absent
    ]
    spec = model.spec.model_copy(update={"bond": kept})
    from ...model import build

    neural = as_neural(build(spec))
    return (
        f"# {found}'s present bonds as mechanical-neural bonds (activebonds scaffold --neural);\n"
        "# its absent candidates dropped.\n" + dumps_model(neural)
    )


def _start_values(mass, rms_acc, rms_disp, k_bounds, c_bounds):
    """(stiffness, damping) start values of a bond: the stiffness that explains the RMS
    acceleration by the RMS displacement (the upper bound without displacement), and a tenth
    of the critical damping, each clipped to its bounds."""
    k_lo, k_hi = k_bounds
    k_raw = mass * rms_acc / rms_disp if rms_disp > 0 else k_hi
    k0 = float(np.clip(k_raw, k_lo, k_hi))
    return k0, float(np.clip(0.1 * 2 * math.sqrt(k0 * mass), *c_bounds))
