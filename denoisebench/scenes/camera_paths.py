"""Camera moves: per-frame camera-to-world matrices built from look-at poses.

Matrices follow USD's conventions: 4×4, row vectors (``p_world = p_local @ M``, translation in the
last row), the camera looking down its local −Z with +Y up. Every function returns an ``F×4×4``
float64 array, one pose per integer frame ``0..F-1``; :func:`denoisebench.scenes.authoring.SceneBuilder.camera`
writes them as time samples of a single ``xformOp:transform``.

Moves take the world ``up`` vector so that they work on Y-up and Z-up stages alike.
"""

from __future__ import annotations

import numpy as np


def _unit(v) -> np.ndarray:
    v = np.asarray(v, dtype=np.float64)
    n = float(np.linalg.norm(v))
    if n == 0.0:
        raise ValueError("zero-length vector")
    return v / n


def look_at(eye, target, up=(0.0, 1.0, 0.0)) -> np.ndarray:
    """Camera-to-world matrix (row-vector convention) at ``eye`` looking at ``target``.

    The camera's −Z points at the target and its +Y is as close to ``up`` as possible. When the
    view direction is parallel to ``up`` another up vector is chosen.
    """
    eye = np.asarray(eye, dtype=np.float64)
    forward = _unit(np.asarray(target, dtype=np.float64) - eye)
    z = -forward
    up = _unit(up)
    x = np.cross(up, z)
    if np.linalg.norm(x) < 1e-8:  # looking straight along up: pick any perpendicular up
        alt = np.array([0.0, 0.0, 1.0]) if abs(up[2]) < 0.9 else np.array([1.0, 0.0, 0.0])
        x = np.cross(alt, z)
    x = _unit(x)
    y = np.cross(z, x)
    m = np.eye(4)
    m[0, :3], m[1, :3], m[2, :3], m[3, :3] = x, y, z, eye
    return m


def _frame_params(frames: int) -> np.ndarray:
    """Sequence parameter in [0, 1] at each frame (0 for a single frame)."""
    if frames < 1:
        raise ValueError(f"frames must be >= 1, got {frames}")
    return np.linspace(0.0, 1.0, frames) if frames > 1 else np.zeros(1)


def _basis(up) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(a, b, up): ``a`` is world +X made perpendicular to ``up``, ``b = a × up``.

    Orbit angle 0° puts the eye on +X and 90° on ``b`` (+Z on a Y-up stage, −Y on a Z-up one).
    """
    up = _unit(up)
    ref = np.array([1.0, 0.0, 0.0]) if abs(up[0]) < 0.9 else np.array([0.0, 0.0, 1.0])
    a = _unit(ref - np.dot(ref, up) * up)
    b = np.cross(a, up)
    return a, b, up


def static(eye, target, frames: int, up=(0.0, 1.0, 0.0)) -> np.ndarray:
    """The same pose at every frame."""
    return np.stack([look_at(eye, target, up)] * len(_frame_params(frames)))


def orbit(
    center,
    radius: float,
    height: float,
    start_deg: float,
    sweep_deg: float,
    frames: int,
    up=(0.0, 1.0, 0.0),
    target=None,
) -> np.ndarray:
    """Circle ``center`` at ``radius`` and ``height`` above it, sweeping ``sweep_deg`` over the sequence."""
    center = np.asarray(center, dtype=np.float64)
    target = center if target is None else np.asarray(target, dtype=np.float64)
    a, b, u = _basis(up)
    poses = []
    for t in _frame_params(frames):
        ang = np.deg2rad(start_deg + sweep_deg * t)
        eye = center + radius * (np.cos(ang) * a + np.sin(ang) * b) + height * u
        poses.append(look_at(eye, target, up))
    return np.stack(poses)


def dolly(eye_start, eye_end, target, frames: int, up=(0.0, 1.0, 0.0), ease: bool = True) -> np.ndarray:
    """Move the eye from ``eye_start`` to ``eye_end`` while looking at ``target``."""
    e0, e1 = np.asarray(eye_start, dtype=np.float64), np.asarray(eye_end, dtype=np.float64)
    poses = []
    for t in _frame_params(frames):
        s = 0.5 - 0.5 * np.cos(np.pi * t) if ease else t
        poses.append(look_at(e0 + (e1 - e0) * s, target, up))
    return np.stack(poses)


def pan(eye, target_start, target_end, frames: int, up=(0.0, 1.0, 0.0)) -> np.ndarray:
    """Turn a camera standing at ``eye`` from ``target_start`` to ``target_end`` (constant speed)."""
    t0, t1 = np.asarray(target_start, dtype=np.float64), np.asarray(target_end, dtype=np.float64)
    return np.stack([look_at(eye, t0 + (t1 - t0) * t, up) for t in _frame_params(frames)])


def truck(eye_start, eye_end, view_dir, frames: int, up=(0.0, 1.0, 0.0)) -> np.ndarray:
    """Slide the camera from ``eye_start`` to ``eye_end`` looking along a fixed ``view_dir``."""
    e0, e1 = np.asarray(eye_start, dtype=np.float64), np.asarray(eye_end, dtype=np.float64)
    d = _unit(view_dir)
    return np.stack([look_at(e0 + (e1 - e0) * t, e0 + (e1 - e0) * t + d, up) for t in _frame_params(frames)])


def fast_pan(
    eye,
    target,
    frames: int,
    yaw_deg_per_frame: float,
    slide_per_frame=(0.0, 0.0, 0.0),
    up=(0.0, 1.0, 0.0),
) -> np.ndarray:
    """A whip pan: the view direction turns ``yaw_deg_per_frame`` about ``up`` each frame
    while the eye slides ``slide_per_frame`` (world units) each frame. Centered on frame (F-1)/2."""
    eye = np.asarray(eye, dtype=np.float64)
    slide = np.asarray(slide_per_frame, dtype=np.float64)
    u = _unit(up)
    d0 = np.asarray(target, dtype=np.float64) - eye
    mid = 0.5 * (frames - 1)
    poses = []
    for f in range(len(_frame_params(frames))):
        ang = np.deg2rad(yaw_deg_per_frame * (f - mid))
        d = _rotate(d0, u, ang)
        e = eye + slide * (f - mid)
        poses.append(look_at(e, e + d, up))
    return np.stack(poses)


def _rotate(v: np.ndarray, axis: np.ndarray, angle: float) -> np.ndarray:
    """Rodrigues rotation of ``v`` about unit ``axis`` by ``angle`` radians."""
    c, s = np.cos(angle), np.sin(angle)
    return v * c + np.cross(axis, v) * s + axis * np.dot(axis, v) * (1.0 - c)


def handheld_shake(
    poses: np.ndarray,
    rng: np.random.Generator,
    translate_amp: float,
    rotate_amp_deg: float,
) -> np.ndarray:
    """Add a seeded, smooth handheld wobble to ``poses`` (in the camera's own frame).

    Each of the three translation and three rotation channels is a sum of three sinusoids with
    random frequencies (0.05–0.4 cycles per frame) and phases, scaled to the given amplitudes.
    """
    frames = poses.shape[0]
    f = np.arange(frames, dtype=np.float64)
    freqs = rng.uniform(0.05, 0.4, size=(6, 3))
    phases = rng.uniform(0.0, 2.0 * np.pi, size=(6, 3))
    weights = rng.uniform(0.5, 1.0, size=(6, 3))
    weights /= weights.sum(axis=1, keepdims=True)
    signal = np.einsum("cs,csf->cf", weights, np.sin(2.0 * np.pi * freqs[..., None] * f + phases[..., None]))
    out = np.empty_like(poses)
    for i in range(frames):
        rx, ry, rz = np.deg2rad(rotate_amp_deg * signal[3:, i])
        local = _euler_xyz(rx, ry, rz)
        local[3, :3] = translate_amp * signal[:3, i]
        out[i] = local @ poses[i]
    return out


def _euler_xyz(rx: float, ry: float, rz: float) -> np.ndarray:
    """Row-vector rotation matrix applying X, then Y, then Z (USD's rotateXYZ)."""
    cx, sx, cy, sy, cz, sz = np.cos(rx), np.sin(rx), np.cos(ry), np.sin(ry), np.cos(rz), np.sin(rz)
    rxm = np.array([[1, 0, 0, 0], [0, cx, sx, 0], [0, -sx, cx, 0], [0, 0, 0, 1]], dtype=np.float64)
    rym = np.array([[cy, 0, -sy, 0], [0, 1, 0, 0], [sy, 0, cy, 0], [0, 0, 0, 1]], dtype=np.float64)
    rzm = np.array([[cz, sz, 0, 0], [-sz, cz, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1]], dtype=np.float64)
    return rxm @ rym @ rzm


def per_frame_motion(poses: np.ndarray) -> tuple[float, float]:
    """Largest per-frame eye translation (world units) and view-direction turn (degrees)."""
    if poses.shape[0] < 2:
        return 0.0, 0.0
    eyes = poses[:, 3, :3]
    fwd = -poses[:, 2, :3]
    step = float(np.max(np.linalg.norm(np.diff(eyes, axis=0), axis=1)))
    cosang = np.clip(np.sum(fwd[1:] * fwd[:-1], axis=1), -1.0, 1.0)
    turn = float(np.rad2deg(np.max(np.arccos(cosang))))
    return step, turn
