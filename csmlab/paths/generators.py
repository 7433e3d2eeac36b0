"""Procedural camera paths, each a plain function registered by name in :data:`PATH_GENERATORS`.

They are laid out for csmlab's procedural scenes, which keep a clear ring road of radius
20 ± 2 m around the origin and a clear disc of radius 4 m at the origin, with the ground at
y ≈ 0 and the casters near the ring:

==========  ================================================================================
name        motion
==========  ================================================================================
dolly       straight line at constant speed, along the ring's tangent (a chord at 19 m)
pan         stands in the origin disc and turns about the vertical at a constant rate
orbit       circles a target (12 m around the origin, 3 m up) looking at it
walk        walks the ring at eye height with head bob, sway and slow look-around
flyover     crosses the scene 40 m up, looking down 35°
jitter      stands on the ring; random sub-texel moves (~1 mm) and turns (~0.01°) each frame
dueling     faces the light (the sun's horizontal direction) while drifting along the ring
zoom        a slow dolly along the ring while the field of view narrows (a scope or cinematic zoom)
==========  ================================================================================

Every generator takes ``frames`` (≥ 1) and ``fps`` (Hz) and returns frame ``i`` at time
``i / fps``; its own parameters are keyword-only with defaults; ``seed`` (when it has one) makes
it deterministic: the same arguments give bit-identical paths. Orientations come from csmlab's
yaw/pitch/roll (:func:`~csmlab.paths.conventions.orientation_from_yaw_pitch_roll`), computed for
all frames at once. :func:`make_path` dispatches on the name and sets the projection.

A level that is not csmlab's own (a mesh or glTF file: its ground 5–12 m up, its centre anywhere)
gets the same generators placed in it by :func:`fitted_path` (``make_path(..., level=)``,
``[camera] fit_level``): coordinates from the level's centre, heights above its ground found by ray
casts (:class:`csmlab.scene.level.Level`), the ring scaled to the level, an orbit about its centre
at ``orbit_height`` and a flyover across it at ``flight_height`` above the terrain. Without a level
every generator gives exactly the path it gave before.
"""

from __future__ import annotations

import dataclasses
import inspect
from collections.abc import Callable

import numpy as np

from csmlab.camera import CameraPath
from csmlab.geometry import normalized
from csmlab.paths.conventions import orientation_from_yaw_pitch_roll
from csmlab.registry import check_name, dispatch, parameters

__all__ = [
    "PATH_GENERATORS",
    "dolly_path",
    "dueling_path",
    "fitted_path",
    "flyover_path",
    "jitter_path",
    "make_path",
    "orbit_path",
    "pan_path",
    "walk_path",
    "zoom_path",
]


def _frame_times(frames, fps) -> np.ndarray:
    """Times ``(frames,)`` in seconds, ``i / fps``, after checking both."""
    if isinstance(frames, bool) or not isinstance(frames, (int, np.integer)) or frames < 1:
        raise ValueError(f"frames: expected a whole number ≥ 1, got {frames!r}")
    if not np.isfinite(fps) or fps <= 0:
        raise ValueError(f"fps: expected a positive frame rate in Hz, got {fps}")
    return np.arange(int(frames), dtype=np.float64) / fps


def _finite(**values) -> None:
    for name, value in values.items():
        if not np.all(np.isfinite(np.asarray(value, dtype=np.float64))):
            raise ValueError(f"{name}: expected finite numbers, got {value!r}")


def _positive(**values) -> None:
    _finite(**values)
    for name, value in values.items():
        if value <= 0:
            raise ValueError(f"{name}: expected a positive value, got {value}")


def _point(value, *, name: str) -> np.ndarray:
    p = np.asarray(value, dtype=np.float64)
    if p.shape != (3,) or not np.all(np.isfinite(p)):
        raise ValueError(f"{name}: expected 3 finite coordinates in metres, got {value!r}")
    return p


def _heading(yaw_deg) -> np.ndarray:
    """Horizontal unit directions ``(..., 3)`` a camera with ``yaw_deg`` looks along (yaw 0 → -Z)."""
    yaw = np.radians(np.asarray(yaw_deg, dtype=np.float64))
    return np.stack([-np.sin(yaw), np.zeros_like(yaw), -np.cos(yaw)], axis=-1)


def _yaw_pitch_toward(direction: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Yaw and pitch in degrees ``(N,)`` of cameras looking along ``direction`` ``(N, 3)``; roll is zero."""
    d = np.asarray(direction, dtype=np.float64)
    yaw = np.degrees(np.arctan2(-d[:, 0], -d[:, 2]))
    pitch = np.degrees(np.arctan2(d[:, 1], np.hypot(d[:, 0], d[:, 2])))
    return yaw, pitch


def _smooth_noise(t: np.ndarray, rng: np.random.Generator, *, frequency: float) -> np.ndarray:
    """A smooth random signal in [-1, 1] ``(N,)``: three sines at 0.5–1.5 × ``frequency`` Hz, random phases."""
    f = frequency * rng.uniform(0.5, 1.5, size=3)
    phase = rng.uniform(0.0, 2.0 * np.pi, size=3)
    weight = rng.uniform(0.5, 1.0, size=3)
    weight /= weight.sum()
    return np.sin(2.0 * np.pi * f * t[:, None] + phase) @ weight


def _camera_path(name: str, times, positions, *, yaw_deg, pitch_deg, roll_deg=0.0) -> CameraPath:
    n = times.shape[0]
    angles = [np.broadcast_to(np.asarray(a, dtype=np.float64), (n,)) for a in (yaw_deg, pitch_deg, roll_deg)]
    orientations = orientation_from_yaw_pitch_roll(yaw_deg=angles[0], pitch_deg=angles[1], roll_deg=angles[2])
    return CameraPath(times=times, positions=np.broadcast_to(positions, (n, 3)), orientations=orientations,
                      fov_y_deg=60.0, name=name)


def _straight_path(name: str, *, frames: int, fps: float, start, heading_deg: float, speed: float,
                   pitch_deg: float) -> CameraPath:
    """A straight move at constant speed along the heading, the view yawed with it and pitched."""
    t = _frame_times(frames, fps)
    _finite(heading_deg=heading_deg, speed=speed, pitch_deg=pitch_deg)
    if speed < 0:
        raise ValueError(f"speed: expected metres per second ≥ 0, got {speed}")
    positions = _point(start, name="start") + (speed * t)[:, None] * _heading(heading_deg)
    return _camera_path(name, t, positions, yaw_deg=heading_deg, pitch_deg=pitch_deg)


def dolly_path(*, frames: int, fps: float = 30.0, start=(19.0, 1.7, 6.0), heading_deg: float = 0.0,
               speed: float = 1.5, pitch_deg: float = 0.0) -> CameraPath:
    """A straight move at constant speed, looking where it goes.

    Parameters
    ----------
    frames, fps : int, float
        Frame count and rate (Hz).
    start : array_like, shape (3,)
        First position, metres. The default lies on a chord 19 m from the origin along the
        ring's tangent: with ``heading_deg = 0`` it stays on the ring road (19–22 m from the
        origin) for the first 17 m, 11 s at the default speed.
    heading_deg : float
        Yaw of the motion and of the view, degrees (0 → -Z, 90 → -X).
    speed : float
        Metres per second, ≥ 0.
    pitch_deg : float
        View pitch, degrees (negative looks down); the motion stays horizontal.
    """
    return _straight_path("dolly", frames=frames, fps=fps, start=start, heading_deg=heading_deg, speed=speed,
                          pitch_deg=pitch_deg)


def pan_path(*, frames: int, fps: float = 30.0, position=(0.0, 1.7, 0.0), start_yaw_deg: float = 0.0,
             yaw_rate_deg: float = 20.0, pitch_deg: float = 0.0) -> CameraPath:
    """Stands still (in the origin disc by default) and turns about the vertical.

    Parameters
    ----------
    position : array_like, shape (3,)
        Metres.
    start_yaw_deg : float
        Yaw of the first frame, degrees (0 looks along -Z).
    yaw_rate_deg : float
        Degrees per second, counter-clockwise seen from above (turning left) when positive.
    pitch_deg : float
        Degrees, negative looks down.
    """
    t = _frame_times(frames, fps)
    _finite(start_yaw_deg=start_yaw_deg, yaw_rate_deg=yaw_rate_deg, pitch_deg=pitch_deg)
    return _camera_path("pan", t, _point(position, name="position"), yaw_deg=start_yaw_deg + yaw_rate_deg * t,
                        pitch_deg=pitch_deg)


def orbit_path(*, frames: int, fps: float = 30.0, target=(0.0, 0.0, 0.0), radius: float = 12.0,
               height: float = 3.0, angular_speed_deg: float = 10.0, start_deg: float = 0.0) -> CameraPath:
    """Circles ``target`` at ``radius`` metres and world height ``height``, always looking at it.

    Parameters
    ----------
    target : array_like, shape (3,)
        The point looked at, metres.
    radius : float
        Horizontal distance from the target, metres (> 0).
    height : float
        World y of the camera, metres.
    angular_speed_deg : float
        Degrees per second, counter-clockwise seen from above when positive.
    start_deg : float
        Angle of the first position about the target's vertical, from +X toward -Z, degrees.
    """
    t = _frame_times(frames, fps)
    _positive(radius=radius)
    _finite(height=height, angular_speed_deg=angular_speed_deg, start_deg=start_deg)
    centre = _point(target, name="target")
    angle = np.radians(start_deg + angular_speed_deg * t)
    positions = np.stack([centre[0] + radius * np.cos(angle), np.full_like(t, height),
                          centre[2] - radius * np.sin(angle)], axis=1)
    yaw, pitch = _yaw_pitch_toward(centre - positions)
    return _camera_path("orbit", t, positions, yaw_deg=yaw, pitch_deg=pitch)


def walk_path(*, frames: int, fps: float = 30.0, seed: int = 1, radius: float = 20.0, eye_height: float = 1.7,
              speed: float = 1.4, start_deg: float = 0.0, step_frequency: float = 2.0, bob_amplitude: float = 0.03,
              sway_amplitude: float = 0.02, roll_amplitude_deg: float = 0.5, pitch_deg: float = -5.0,
              look_yaw_deg: float = 20.0, look_pitch_deg: float = 5.0, look_frequency: float = 0.15) -> CameraPath:
    """Walks counter-clockwise (seen from above) around the ring road, looking ahead and around.

    At angle ``φ = start + speed·t / radius`` the eye is at
    ``(r cos φ, eye_height + bob·sin(2π f t), -r sin φ)`` with ``r = radius + sway·sin(π f t)``:
    the head rises and falls once per step (``f`` Hz) and sways sideways once per stride (two
    steps), rolling with the sway. The view yaw is the walking direction plus a slow random
    look-around of up to ``look_yaw_deg``; pitch is ``pitch_deg`` plus up to ``look_pitch_deg``.
    With the defaults the eye stays within 20 ± 0.02 m of the origin's vertical and at y in
    1.7 ± 0.03 m.

    Parameters
    ----------
    seed : int
        Seeds the look-around.
    radius, eye_height : float
        Metres.
    speed : float
        Metres per second along the ring, ≥ 0.
    start_deg : float
        Angle of the first position, from +X toward -Z, degrees.
    step_frequency : float
        Steps per second (Hz).
    bob_amplitude, sway_amplitude : float
        Vertical and sideways head motion, metres.
    roll_amplitude_deg, pitch_deg, look_yaw_deg, look_pitch_deg : float
        Degrees.
    look_frequency : float
        Typical frequency of the look-around, Hz.
    """
    t = _frame_times(frames, fps)
    _positive(radius=radius)
    _finite(eye_height=eye_height, speed=speed, start_deg=start_deg, step_frequency=step_frequency,
            bob_amplitude=bob_amplitude, sway_amplitude=sway_amplitude, roll_amplitude_deg=roll_amplitude_deg,
            pitch_deg=pitch_deg, look_yaw_deg=look_yaw_deg, look_pitch_deg=look_pitch_deg,
            look_frequency=look_frequency)
    if speed < 0:
        raise ValueError(f"speed: expected metres per second ≥ 0, got {speed}")
    rng = np.random.default_rng(seed)
    phi = np.radians(start_deg) + speed * t / radius
    stride = np.sin(np.pi * step_frequency * t)
    r = radius + sway_amplitude * stride
    positions = np.stack([r * np.cos(phi), eye_height + bob_amplitude * np.sin(2.0 * np.pi * step_frequency * t),
                          -r * np.sin(phi)], axis=1)
    yaw = np.degrees(phi) + look_yaw_deg * _smooth_noise(t, rng, frequency=look_frequency)
    pitch = pitch_deg + look_pitch_deg * _smooth_noise(t, rng, frequency=look_frequency)
    return _camera_path("walk", t, positions, yaw_deg=yaw, pitch_deg=pitch, roll_deg=roll_amplitude_deg * stride)


def flyover_path(*, frames: int, fps: float = 30.0, start=(-50.0, 40.0, 0.0), heading_deg: float = -90.0,
                 speed: float = 10.0, pitch_deg: float = -35.0) -> CameraPath:
    """Flies straight and level across the scene, looking ahead and down.

    Parameters
    ----------
    start : array_like, shape (3,)
        First position, metres; by default 50 m west of the origin and 40 m up, so the default
        heading (+X) crosses over the origin after 5 s.
    heading_deg : float
        Yaw of the motion and view, degrees (-90 → +X).
    speed : float
        Metres per second, ≥ 0.
    pitch_deg : float
        Degrees; -35 looks down 35° below the horizon.
    """
    return _straight_path("flyover", frames=frames, fps=fps, start=start, heading_deg=heading_deg, speed=speed,
                          pitch_deg=pitch_deg)


def jitter_path(*, frames: int, fps: float = 30.0, seed: int = 1, position=(20.0, 1.7, 0.0), yaw_deg: float = 0.0,
                pitch_deg: float = 0.0, translation_amplitude: float = 1e-3,
                rotation_amplitude_deg: float = 0.01) -> CameraPath:
    """Stands still on the ring with independent random sub-texel motion in every frame.

    Each frame adds to the base pose a translation uniform in ``±translation_amplitude`` metres
    per axis and yaw, pitch and roll each uniform in ``±rotation_amplitude_deg`` — far below a
    shadow texel, so any change in the shadow is shimmer that a stable method must not show.

    Parameters
    ----------
    seed : int
        Seeds the motion.
    position : array_like, shape (3,)
        Base position, metres; the default stands on the ring looking along its tangent.
    yaw_deg, pitch_deg : float
        Base view, degrees.
    translation_amplitude : float
        Metres, ≥ 0.
    rotation_amplitude_deg : float
        Degrees, ≥ 0.
    """
    t = _frame_times(frames, fps)
    _finite(yaw_deg=yaw_deg, pitch_deg=pitch_deg, translation_amplitude=translation_amplitude,
            rotation_amplitude_deg=rotation_amplitude_deg)
    if translation_amplitude < 0 or rotation_amplitude_deg < 0:
        raise ValueError("translation_amplitude, rotation_amplitude_deg: expected amplitudes ≥ 0, got "
                         f"{translation_amplitude}, {rotation_amplitude_deg}")
    rng = np.random.default_rng(seed)
    moves = rng.uniform(-translation_amplitude, translation_amplitude, size=(t.shape[0], 3))
    turns = rng.uniform(-rotation_amplitude_deg, rotation_amplitude_deg, size=(t.shape[0], 3))
    return _camera_path("jitter", t, _point(position, name="position") + moves, yaw_deg=yaw_deg + turns[:, 0],
                        pitch_deg=pitch_deg + turns[:, 1], roll_deg=turns[:, 2])


def dueling_path(*, frames: int, fps: float = 30.0, light_direction=None, radius: float = 20.0,
                 eye_height: float = 1.7, speed: float = 0.5, start_deg: float = 0.0,
                 pitch_deg: float = 0.0) -> CameraPath:
    """Faces the light — the horizontal part of ``-light_direction`` — while drifting along the ring.

    The view direction is then opposite the light's, the "dueling frusta" case where shadow
    texels stretch most across the screen. With the light straight down there is no horizontal
    part and the camera faces along -Z.

    Parameters
    ----------
    light_direction : array_like, shape (3,)
        From the light toward the scene (required).
    radius, eye_height : float
        Metres.
    speed : float
        Metres per second along the ring, counter-clockwise seen from above.
    start_deg : float
        Angle of the first position, from +X toward -Z, degrees.
    pitch_deg : float
        Degrees (positive looks up toward the sun).
    """
    t = _frame_times(frames, fps)
    if light_direction is None:
        raise ValueError("light_direction: dueling faces the light; expected its direction (3,), got None")
    d = normalized(light_direction, name="light_direction")
    _positive(radius=radius)
    _finite(eye_height=eye_height, speed=speed, start_deg=start_deg, pitch_deg=pitch_deg)
    toward_sun = -d
    horizontal = np.hypot(toward_sun[0], toward_sun[2])
    yaw = float(np.degrees(np.arctan2(-toward_sun[0], -toward_sun[2]))) if horizontal > 1e-9 else 0.0
    phi = np.radians(start_deg) + speed * t / radius
    positions = np.stack([radius * np.cos(phi), np.full_like(t, eye_height), -radius * np.sin(phi)], axis=1)
    return _camera_path("dueling", t, positions, yaw_deg=yaw, pitch_deg=pitch_deg)


def zoom_path(*, frames: int, fps: float = 30.0, fov_y_deg: float = 60.0, zoom: float = 4.0,
              start=(19.0, 1.7, 6.0), heading_deg: float = 0.0, speed: float = 0.5,
              pitch_deg: float = -5.0) -> CameraPath:
    """A slow dolly whose field of view narrows: magnification 1 at the first frame, ``zoom`` at the last.

    The magnification grows geometrically, ``m(s) = zoom^s`` for ``s`` from 0 to 1 over the run,
    and ``fov(s) = 2 atan(tan(fov_y_deg / 2) / m(s))`` — every cascade's slice narrows with it, the
    case that makes fixed-extent (sphere) methods waste the most and refitting ones swim.

    Parameters
    ----------
    fov_y_deg : float
        The camera's field of view at magnification 1, degrees (``[camera] fov_y_deg``).
    zoom : float
        Magnification at the last frame (> 0; below 1 zooms out).
    start, heading_deg, speed, pitch_deg
        As :func:`dolly_path`.
    """
    t = _frame_times(frames, fps)
    _positive(zoom=zoom)
    _finite(fov_y_deg=fov_y_deg, heading_deg=heading_deg, speed=speed, pitch_deg=pitch_deg)
    path = dolly_path(frames=frames, fps=fps, start=start, heading_deg=heading_deg, speed=speed, pitch_deg=pitch_deg)
    s = t / t[-1] if t[-1] > 0 else np.zeros_like(t)
    fov = 2.0 * np.degrees(np.arctan(np.tan(np.radians(fov_y_deg) / 2.0) / zoom ** s))
    return dataclasses.replace(path, fov_y_deg=fov, name="zoom")


PATH_GENERATORS: dict[str, Callable[..., CameraPath]] = {
    "dolly": dolly_path,
    "pan": pan_path,
    "orbit": orbit_path,
    "walk": walk_path,
    "flyover": flyover_path,
    "jitter": jitter_path,
    "dueling": dueling_path,
    "zoom": zoom_path,
}
"""Path generators by name; add an entry to register a new one."""


LEVEL_RING_SHARE = 0.5
"""In a fitted level, the ring's radius (walk, dueling, jitter, orbit; dolly's and zoom's chord) as a share
of the level's smaller horizontal half-extent."""

LEVEL_FIT_SAMPLES = 64
"""Points along an orbit's circle or a flyover's track where the fitted height looks for the highest ground."""


def _level_reach(level) -> float:
    """The level's smaller horizontal half-extent in metres, or a twentieth of the larger for a level thin along one
    axis."""
    half = np.asarray(level.half_extent, dtype=np.float64)
    return max(float(half.min()), 0.05 * float(half.max()), 1e-3)


def _ground(level, x, z) -> np.ndarray:
    """Ground heights ``(N,)`` under ``(x, z)``; the level's lowest point where there is none."""
    y = level.ground_heights(x, z)
    return np.where(np.isnan(y), level.bounds[0, 1], y)


def _fitted_orbit(level, *, frames, fps, params, orbit_height) -> CameraPath:
    """:func:`orbit_path` about the level's centre, ``orbit_height`` above the highest ground under its circle."""
    centre = level.centre
    radius = params.pop("radius", LEVEL_RING_SHARE * _level_reach(level))
    _positive(radius=radius)
    offset = _point(params.pop("target", (0.0, 0.0, 0.0)), name="target")
    tx, tz = centre[0] + offset[0], centre[2] + offset[2]
    target = np.array([tx, _ground(level, [tx], [tz])[0] + offset[1], tz])
    height = 0.5 * radius if orbit_height is None else orbit_height
    _finite(orbit_height=height)
    angle = np.linspace(0.0, 2.0 * np.pi, LEVEL_FIT_SAMPLES, endpoint=False)
    ground = _ground(level, np.append(tx + radius * np.cos(angle), tx), np.append(tz - radius * np.sin(angle), tz))
    return orbit_path(frames=frames, fps=fps, target=target, radius=radius, height=float(ground.max()) + height,
                      **params)


def _fitted_flyover(level, *, frames, fps, params, flight_height) -> CameraPath:
    """:func:`flyover_path` across the level's longer horizontal axis through its centre, ``flight_height``
    above the highest ground under the track, crossing the level over the run unless ``speed`` is given."""
    t = _frame_times(frames, fps)
    half = np.asarray(level.half_extent, dtype=np.float64)
    along_x = half[0] >= half[1]
    start = _point(params.pop("start", (-half[0], 0.0, 0.0) if along_x else (0.0, 0.0, half[1])), name="start")
    heading = params.pop("heading_deg", -90.0 if along_x else 0.0)
    speed = params.pop("speed", 2.0 * float(half.max()) / max(float(t[-1]), 1.0 / fps))
    _finite(heading_deg=heading, speed=speed)
    begin = level.centre[[0, 2]] + start[[0, 2]]
    end = begin + speed * float(t[-1]) * _heading(heading)[[0, 2]]
    track = begin + np.linspace(0.0, 1.0, LEVEL_FIT_SAMPLES)[:, None] * (end - begin)
    height = 0.5 * float(half.max()) if flight_height is None else flight_height
    _finite(flight_height=height)
    altitude = float(_ground(level, track[:, 0], track[:, 1]).max()) + height
    return flyover_path(frames=frames, fps=fps, start=(begin[0], altitude, begin[1]), heading_deg=heading, speed=speed,
                        **params)


def _ring_defaults(name: str, radius: float) -> dict:
    """A fitted ground-level generator's placement of csmlab's ring (20 m; dolly's and zoom's chord at 19 m,
    6 m along) scaled to the level's ring ``radius``; keywords the experiment gives win."""
    if name in ("walk", "dueling"):
        return {"radius": radius}
    if name == "jitter":
        return {"position": (radius, 1.7, 0.0)}
    if name in ("dolly", "zoom"):
        return {"start": (0.95 * radius, 1.7, 0.3 * radius)}
    return {}


def _fitted_on_ground(name, level, *, frames, fps, offered, params) -> CameraPath:
    """A ground-level generator in the level's frame: x and z from its centre, y above the ground under the eye."""
    defaults = _ring_defaults(name, LEVEL_RING_SHARE * _level_reach(level))
    path = dispatch(PATH_GENERATORS, name, field="path", frames=frames, fps=fps, offered=offered,
                    **{**defaults, **params})
    x = path.positions[:, 0] + level.centre[0]
    z = path.positions[:, 2] + level.centre[2]
    positions = np.stack([x, _ground(level, x, z) + path.positions[:, 1], z], axis=1)
    return dataclasses.replace(path, positions=positions)


def fitted_path(name: str, level, *, frames: int, fps: float = 30.0, seed: int = 1, fov_y_deg: float = 60.0,
                light_direction=None, orbit_height: float | None = None, flight_height: float | None = None,
                **params) -> CameraPath:
    """Generator ``name``'s path placed in ``level`` (``[camera] fit_level``), before the projection is set.

    Every generator's coordinates are taken in the level's frame: x and z from the centre of its
    bounds, y above the ground under the point (:meth:`csmlab.scene.level.Level.ground_heights`, the
    level's lowest point where there is none). The ring that csmlab's own scenes keep clear at 20 m
    becomes :data:`LEVEL_RING_SHARE` of the level's smaller half-extent (walk, dueling, jitter and
    orbit radius, dolly's and zoom's start, scaled alike), and

    * ``orbit`` circles the level's centre (on its ground, plus ``target``) ``orbit_height`` metres
      above the highest ground under its circle (default half the radius), looking at it;
    * ``flyover`` crosses the level along its longer horizontal axis through the centre (``start``
      and ``heading_deg`` may move it; ``start``'s y is not used), ``flight_height`` metres above the
      highest ground under its track (default half the longer half-extent), at the speed that
      crosses the level over the run unless ``speed`` is given.

    Parameters
    ----------
    name : str
        A key of :data:`PATH_GENERATORS`.
    level : csmlab.scene.level.Level
        Bounds and ground of the scene.
    orbit_height, flight_height : float, optional
        Metres above the ground (orbit, flyover).
    frames, fps, seed, fov_y_deg, light_direction, **params
        As :func:`make_path`.
    """
    offered = {"seed": seed, "light_direction": light_direction, "fov_y_deg": fov_y_deg}
    unknown = sorted(set(params) - set(parameters(PATH_GENERATORS[check_name(name, PATH_GENERATORS, field="path")])))
    if unknown:
        raise ValueError(f"{name}: unknown parameter(s) {unknown}; expected some of "
                         f"{sorted(parameters(PATH_GENERATORS[name]))}")
    params = dict(params)
    if name == "orbit":
        orbit_height = params.pop("height", orbit_height)
        return _fitted_orbit(level, frames=frames, fps=fps, params=params, orbit_height=orbit_height)
    if name == "flyover":
        return _fitted_flyover(level, frames=frames, fps=fps, params=params, flight_height=flight_height)
    return _fitted_on_ground(name, level, frames=frames, fps=fps, offered=offered, params=params)


def make_path(name: str, *, frames: int, fps: float = 30.0, seed: int = 1, fov_y_deg: float = 60.0,
              aspect: float = 16.0 / 9.0, near: float = 0.1, far: float = 400.0, light_direction=None,
              level=None, orbit_height: float | None = None, flight_height: float | None = None,
              **params) -> CameraPath:
    """The camera path of generator ``name`` with the given projection.

    Parameters
    ----------
    name : str
        A key of :data:`PATH_GENERATORS`.
    frames, fps : int, float
        Frame count (≥ 1) and rate (Hz).
    seed : int
        Passed to generators that draw random numbers (walk, jitter); the others are
        deterministic without one.
    fov_y_deg, aspect, near, far : float
        Projection of every pose (degrees, width/height, metres, metres).
    light_direction : array_like, shape (3,), optional
        Passed to generators that use it (dueling, which requires it).
    level : csmlab.scene.level.Level, optional
        Place the path in this level (:func:`fitted_path`); None: csmlab's own layout, in world
        coordinates.
    orbit_height : float, optional
        orbit: the camera's height in metres — world y without ``level`` (the generator's
        ``height``), above the ground with it.
    flight_height : float, optional
        flyover: the flight's height in metres — world y without ``level`` (``start``'s y), above
        the ground with it.
    **params
        The generator's own keyword parameters (see its docstring).

    Raises
    ------
    ValueError
        On an unknown name or parameter (listing the valid ones) or a bad value.
    """
    check_name(name, PATH_GENERATORS, field="path")
    for field, value, owner in (("orbit_height", orbit_height, "orbit"), ("flight_height", flight_height, "flyover")):
        if value is not None and name != owner:
            raise ValueError(f"{field}: expected only with path = {owner!r}, got path = {name!r}")
    if level is not None:
        path = fitted_path(name, level, frames=frames, fps=fps, seed=seed, fov_y_deg=fov_y_deg,
                           light_direction=light_direction, orbit_height=orbit_height, flight_height=flight_height,
                           **params)
    else:
        if orbit_height is not None:
            params["height"] = orbit_height
        if flight_height is not None:
            start = _point(params.get("start", inspect.signature(flyover_path).parameters["start"].default),
                           name="start")
            params["start"] = (start[0], flight_height, start[2])
        path = dispatch(PATH_GENERATORS, name, field="path", frames=frames, fps=fps,
                        offered={"seed": seed, "light_direction": light_direction, "fov_y_deg": fov_y_deg}, **params)
    # A generator that takes the field of view animates it (zoom); the others get it as it is.
    fov = path.fov_y_deg if "fov_y_deg" in parameters(PATH_GENERATORS[name]) else fov_y_deg
    return dataclasses.replace(path, fov_y_deg=fov, aspect=aspect, near=near, far=far)
