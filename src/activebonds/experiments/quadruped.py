"""A simulated quadruped on a treadmill: a rhythmic recording nobody measured, to judge the gait
family (:mod:`~activebonds.identify.discover.gait`) and ``activebonds auto`` on a gait that
is not the bundled horse's (other marker names and count, rate, period, stride shape).

Kinematic, not physical: a body (a head, withers, a croup and a tail marker) that bobs and
pitches twice a stride and sways once, and four feet that each step through a stance (moving
back on the ground) and a swing (lifted, brought forward), smooth in time, the legs' phases a trot's or a walk's. The tempo wanders (a random walk of the
stride frequency, :data:`TEMPO_WANDER` of it over a stride, mean-reverting), each stride's
step length and lift vary by :data:`STRIDE_SPREAD`, and every marker carries white noise of
``noise_mm``. Seeded: the same arguments give the same recording.
"""

from __future__ import annotations

import numpy as np

TEMPO_WANDER = 0.04  # the stride frequency's random walk, a share of it per stride (SD)
STRIDE_SPREAD = 0.08  # each stride's step length and lift, a share of them (SD)
LEG_PHASES = {  # each foot's phase lag (strides): fore left, fore right, hind left, hind right
    "trot": (0.0, 0.5, 0.5, 0.0),
    "walk": (0.0, 0.5, 0.75, 0.25),
}
DUTY = {"trot": 0.45, "walk": 0.65}  # the share of a stride each foot is on the ground


def quadruped(
    gait: str = "trot",
    rate: float = 100.0,
    seconds: float = 12.0,
    stride_hz: float = 1.2,
    noise_mm: float = 0.3,
    seed: int = 0,
):
    """The recording (a :class:`~activebonds.data.Trajectory`, metres, Z up): markers
    ``nose, neck, hip, tail, foot_a .. foot_d``."""
    from ..data import Trajectory

    rng = np.random.default_rng(seed)
    n = int(round(seconds * rate))
    dt = 1.0 / rate
    f = np.empty(n)
    f[0] = stride_hz
    for k in range(1, n):  # mean-reverting random walk of the tempo
        step = TEMPO_WANDER * stride_hz * np.sqrt(dt * stride_hz) * rng.standard_normal()
        f[k] = f[k - 1] + step - 0.5 * dt * stride_hz * (f[k - 1] - stride_hz)
    phase = np.concatenate([[0.0], np.cumsum(f[:-1] * dt)])  # strides
    stride = np.floor(phase).astype(int)
    spread = 1.0 + STRIDE_SPREAD * rng.standard_normal((stride.max() + 2, 2))
    step, lift = 0.55 * spread[stride, 0], 0.09 * spread[stride, 1]
    x = np.zeros((n, 8, 3))
    w = 2 * np.pi * phase
    bob = 0.02 * np.cos(2 * w)
    sway = 0.015 * np.sin(w)
    body = {"nose": (0.75, 1.55), "neck": (0.45, 1.45), "hip": (-0.45, 1.35), "tail": (-0.6, 1.2)}
    for i, (ahead, height) in enumerate(body.values()):
        pitch = 0.02 * np.sin(2 * w + 0.6) * ahead
        x[:, i] = np.stack([np.full(n, ahead), sway, height + bob + pitch], axis=1)
    feet = ((0.45, 0.12), (0.45, -0.12), (-0.45, 0.12), (-0.45, -0.12))
    duty = DUTY[gait]
    for j, ((ahead, side), lag) in enumerate(zip(feet, LEG_PHASES[gait], strict=True)):
        # this foot's phase within its stride, warped (smoothly) so that the first half of
        # the warped cycle, the stance, lasts ``duty`` of the stride
        u = 2 * np.pi * (phase - lag)
        warped = u + (2 * duty - 1) * np.sin(u)
        along = 0.5 * np.cos(warped)  # forward at touch-down, back at lift-off
        up = np.maximum(0.0, -np.sin(warped)) ** 1.5  # lifted in the swing only
        x[:, 4 + j] = np.stack([ahead + step * along, side + 0.3 * sway, 0.02 + lift * up], axis=1)
    x += 1e-3 * noise_mm * rng.standard_normal(x.shape)
    names = ("nose", "neck", "hip", "tail", "foot_a", "foot_b", "foot_c", "foot_d")
    return Trajectory(x, np.ones((n, 8), bool), names, float(rate))
