"""The ranges a frame's cascades divide and cover: view depth (SDSM, hysteresis) and light depth (pancaking).

View depth, :data:`BOUNDS_METHODS` (``[shadow] bounds``):

- ``frustum`` — the splits divide ``[near, shadow_distance]`` of the camera, every frame the same.
- ``sdsm`` — sample distribution shadow maps (Lauritzen, Salvi, Lefohn, I3D 2011): the splits
  divide the frame's *visible* depth range, the minimum and maximum view depth of the G-buffer
  (clamped to ``[near, shadow_distance]``). Tight, but every change of that range moves every split
  and every box: the "flashing" SDSM is known for. Stride's automatic depth range does the same
  (``LightDirectionalShadowMapRenderer.ComputeCascadeSplits``, ``DepthRange.IsAutomatic``, default on).
  With ``hysteresis = h`` the range is *held* (:func:`held_depth_ranges`): it grows at once and
  shrinks only when the visible range lies a fraction ``h`` inside it. ``hold = "stepped"`` holds it
  as Stride does instead (:func:`stepped_depth_ranges`): the far end grows in steps of 1.1ᵏ and
  shrinks in steps of 2⁻ᵏ of the held one, and so does the held range's depth (:data:`HOLD_METHODS`).

Where the shadow ends, :data:`SHADOW_DISTANCE_METHODS` (``[shadow] shadow_distance_from``; TOML also
takes ``shadow_distance = "camera_far"`` or ``"farthest_visible"`` for it), :func:`shadow_end`:

- ``fixed`` — ``shadow_distance`` metres, clamped to the camera's far plane (Unity, Godot, Bevy, Unreal).
- ``camera_far`` — the camera's far plane of each frame, at most ``max_shadow_distance`` when that is
  set (three.js ``CSM._getBreaks``: ``Math.min(camera.far, this.maxFar)``, maxFar 100000; Filament
  ``ShadowOptions::shadowFar = 0``: the camera's far; MJP ``MaxCascadeDistance`` 1.0 of the clip range).
- ``farthest_visible`` — the farthest visible point of each frame (the held far end of ``bounds =
  "sdsm"``'s visible range), at most ``max_shadow_distance`` when set, not clamped to ``shadow_distance``
  (Stride ``LightDirectionalShadowMapRenderer.ComputeCascadeSplits``: ``maxDistance`` of the visible
  objects, ``VisibilityGroup.CalculateMinMaxDistance``, with no cap).

Light depth, :data:`DEPTH_RANGE_METHODS` (``[shadow] depth_range``), the box's extent along the light:

- ``scene`` — the near side pushed toward the light to the scene's bounds (NVIDIA's z-range
  extension, seed 000; DirectX CSM11's near/far from the scene AABB, seed 002): every caster is in.
- ``slice`` — the slice's own depth range, its near side pulled ``pancake`` metres toward the light
  (Godot ``directional_shadow_pancake_size``, default 20; ogldev tutorial 49, seed 001, uses 0).
  Casters nearer than that are flattened onto it (``depth_clamp``: pancaking, Godot, Unreal, Bevy's
  unclipped depth) or clipped away (their shadows lost).
- ``sphere`` — the light-depth range of the sphere about the slice corners' centroid, centre ± its
  radius, the near side pulled ``pancake`` metres toward the light (Godot 4
  ``RendererSceneCull::_light_instance_setup_directional_shadow``: ``z_min_cam = z_vec.dot(center) -
  radius``, ``z_max = z_vec.dot(center) + radius + pancake_size``; Stride
  ``LightDirectionalShadowMapRenderer``: the shadow camera ``r`` behind the sphere's centre, near 0,
  far ``2r``). Always at least the corners' range. Godot's radius is also widened by ``T / (T - 2)``
  (one texel, < 0.1 % at 2048), which this range leaves out.
- ``scene_clipped`` — the light-depth range of the scene's bounding box clipped to the cascade's
  box on x and y (DirectX CascadedShadowMaps11 ``FIT_NEARFAR_SCENE_AABB``:
  ``CascadedShadowsManager::ComputeNearAndFar`` clips the AABB's 12 triangles against the box's four
  sides and takes the clipped vertices' minimum and maximum light depth). Every caster in the box's
  x/y range lies inside it, as with ``scene``; where the box misses the scene's box, the scene's range.
- ``light_camera`` — a light camera ``pancake`` metres toward the light from the slice's corner
  nearest the light, clipping at ``light_near`` and ``light_far`` metres in front of it (three.js
  ``CSM.update()``: ``_center.z = _bbox.max.z + lightMargin``, the shadow camera's ``near =
  lightNear`` 1 and ``far = lightFar`` 2000, ``CSM`` constructor): the range is ``[s − pancake +
  light_near, s − pancake + light_far]``, ``s`` the slice's nearest light depth, whatever the slice's
  depth. Casters in front of it are clamped or clipped (``depth_clamp``); a caster beyond the far side
  is still rasterized (a unorm format stores it at the far side, as the engine's cleared map holds
  where it clips the caster).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from csmlab.registry import check_name

__all__ = ["BOUNDS_METHODS", "Bounds", "DEPTH_RANGE_METHODS", "DepthRange", "HOLD_METHODS", "Hold",
           "SHADOW_DISTANCE_METHODS", "held_depth_ranges", "scene_box_depth", "scene_clipped_box_depth",
           "shadow_end", "slice_box_depth", "split_range", "stepped_depth_ranges", "visible_depth_range"]


@dataclass(frozen=True)
class Bounds:
    """A view-depth range the splits divide.

    Attributes
    ----------
    description : str
    visible : bool
        The range is the frame's visible depth range, read from its G-buffer (and, held with
        hysteresis, from every earlier frame's).
    """

    description: str
    visible: bool


BOUNDS_METHODS: dict[str, Bounds] = {
    "frustum": Bounds("the splits divide [near, shadow_distance] of the camera", visible=False),
    "sdsm": Bounds("the splits divide the frame's visible depth range from the G-buffer (sample distribution shadow "
                   "maps)", visible=True),
}
"""View-depth ranges the splits divide, by name."""


def scene_box_depth(slice_depth: np.ndarray, scene_depth: np.ndarray, *, pancake: float,
                    corners=None) -> tuple[float, float]:
    """``scene``: the slice's light-depth range widened to the scene's, so every caster in the box's
    x/y range is captured whatever the slice's own depth range is (``pancake`` plays no part)."""
    return float(min(slice_depth.min(), scene_depth.min())), float(max(slice_depth.max(), scene_depth.max()))


def slice_box_depth(slice_depth: np.ndarray, scene_depth: np.ndarray, *, pancake: float,
                    corners=None) -> tuple[float, float]:
    """``slice``: the slice's own light-depth range, its near side pulled ``pancake`` metres toward the light."""
    return float(slice_depth.min() - pancake), float(slice_depth.max())


def sphere_box_depth(slice_depth: np.ndarray, scene_depth: np.ndarray, *, pancake: float,
                     corners=None) -> tuple[float, float]:
    """``sphere``: the centroid sphere of the slice's light-space ``corners`` ``(8, 3)``, centre ± radius along
    the light, its near side pulled ``pancake`` metres toward the light (Godot 4, Stride)."""
    points = np.asarray(corners, dtype=np.float64).reshape(-1, 3)
    centre = points.mean(axis=0)
    radius = float(np.sqrt(np.max(np.sum((points - centre) ** 2, axis=1))))
    return float(centre[2] - radius - pancake), float(centre[2] + radius)


@dataclass(frozen=True)
class DepthRange:
    """A light-depth range of a cascade's box.

    Attributes
    ----------
    description : str
    box_depth : callable
        ``box_depth(slice_depth, scene_depth, *, pancake, ...) -> (near, far)``: the box's near and
        far light depth in metres from the light depths of the slice's corners and of the scene's
        bounds; it declares what else it reads of ``corners`` (the corners' light-space positions
        ``(8, 3)``), ``light_near`` and ``light_far``.
    cuts_casters : bool
        The box's near side may lie behind casters: they are flattened onto it (``depth_clamp``,
        pancaking) or clipped away. False: every caster lies behind the near side.
    """

    description: str
    box_depth: Callable[..., tuple[float, float]]
    cuts_casters: bool


def scene_clipped_box_depth(slice_depth: np.ndarray, scene_depth: np.ndarray, *, scene_corners: np.ndarray,
                            basis: np.ndarray, box_lo: np.ndarray, box_hi: np.ndarray) -> tuple[float, float]:
    """``scene_clipped``: the light-depth range of the scene's world AABB inside the box's x/y prism (DirectX CSM11).

    The AABB of ``scene_corners`` ``(K, 3)`` (world metres) cut by ``box_lo <= (x, y) <= box_hi`` in
    light space (rows of ``basis`` ``(3, 3)``) is a convex polytope; its extreme light depths lie at
    its vertices: the AABB's corners inside the prism, its edges' crossings of the prism's four
    walls, and the prism's four edges (lines along ``d``) where they pass through the AABB. The same
    range as clipping the AABB's triangles (``ComputeNearAndFar``).
    """
    world = np.asarray(scene_corners, dtype=np.float64).reshape(-1, 3)
    lo_w, hi_w = world.min(axis=0), world.max(axis=0)
    corners = np.array([[x, y, z] for x in (lo_w[0], hi_w[0]) for y in (lo_w[1], hi_w[1]) for z in (lo_w[2], hi_w[2])])
    lo, hi = np.asarray(box_lo, dtype=np.float64), np.asarray(box_hi, dtype=np.float64)
    slack = 1e-9 * max(1.0, float(np.max(np.abs(np.concatenate([lo, hi])))))
    # AABB edges: corner pairs differing in one coordinate (corner index bits 2, 1, 0 = x, y, z).
    edges = np.array([(a, a | bit) for bit in (4, 2, 1) for a in range(8) if not a & bit])
    light = corners @ basis.T
    p0, p1 = light[edges[:, 0]], light[edges[:, 1]]
    candidates = [light]
    for axis in (0, 1):
        for wall in (lo[axis], hi[axis]):
            span = p1[:, axis] - p0[:, axis]
            crossing = span != 0.0
            t = np.where(crossing, (wall - p0[:, axis]) / np.where(crossing, span, 1.0), -1.0)
            on = crossing & (t >= 0.0) & (t <= 1.0)
            candidates.append(p0[on] + t[on, None] * (p1[on] - p0[on]))
    points = np.concatenate(candidates)
    inside = np.all((points[:, :2] >= lo - slack) & (points[:, :2] <= hi + slack), axis=1)
    depths = list(points[inside, 2])
    # The prism's edges: the lines x·right + y·up + s·d, s their light depth, through the AABB (slabs).
    for x in (lo[0], hi[0]):
        for y in (lo[1], hi[1]):
            origin, d = x * basis[0] + y * basis[1], basis[2]
            with np.errstate(divide="ignore", invalid="ignore"):
                a, b = (lo_w - origin) / d, (hi_w - origin) / d
            flat = d == 0.0
            if np.any(flat & ((origin < lo_w) | (origin > hi_w))):
                continue
            enter = np.max(np.where(flat, -np.inf, np.minimum(a, b)))
            leave = np.min(np.where(flat, np.inf, np.maximum(a, b)))
            if enter <= leave:
                depths += [float(enter), float(leave)]
    if not depths:
        return scene_box_depth(slice_depth, scene_depth, pancake=0.0)
    return float(min(depths)), float(max(depths))


def light_camera_box_depth(slice_depth: np.ndarray, scene_depth: np.ndarray, *, pancake: float, light_near: float,
                           light_far: float) -> tuple[float, float]:
    """``light_camera``: ``light_near`` to ``light_far`` metres in front of a light ``pancake`` metres toward the
    light from the slice's nearest light depth (three.js CSM)."""
    light = float(slice_depth.min()) - pancake
    return light + light_near, light + light_far


DEPTH_RANGE_METHODS: dict[str, DepthRange] = {
    "scene": DepthRange("box near side pushed toward the light to the scene bounds (every caster captured)",
                        scene_box_depth, cuts_casters=False),
    "slice": DepthRange("box depth from the slice only, near side pulled `pancake` metres toward the light",
                        slice_box_depth, cuts_casters=True),
    "sphere": DepthRange("box depth from the sphere about the slice corners' centroid (centre ± radius), near side "
                         "pulled `pancake` metres toward the light (Godot 4, Stride)", sphere_box_depth,
                         cuts_casters=True),
    "scene_clipped": DepthRange("the scene's bounding box clipped to the cascade's box on x and y, its light-depth "
                                "range (DirectX CSM11 ComputeNearAndFar)", scene_clipped_box_depth, cuts_casters=False),
    "light_camera": DepthRange("a light camera `pancake` metres toward the light from the slice, clipping at "
                               "`light_near` and `light_far` in front of it (three.js CSM)", light_camera_box_depth,
                               cuts_casters=True),
}
"""Light-depth ranges of a cascade's box, by name."""


def visible_depth_range(view_depth) -> tuple[float, float] | None:
    """Minimum and maximum finite view depth ``(z_min, z_max)`` in metres of a G-buffer; None if nothing is visible.

    Parameters
    ----------
    view_depth : array_like, shape (H, W)
        ``-z_view`` of every pixel's hit, metres; +inf (or NaN) where the ray missed.
    """
    z = np.asarray(view_depth, dtype=np.float64)
    z = z[np.isfinite(z)]
    if z.size == 0:
        return None
    return float(z.min()), float(z.max())


def held_depth_ranges(ranges, *, hysteresis: float) -> np.ndarray:
    """The range an SDSM with hysteresis uses in each frame, from the visible range of every frame so far.

    Frame 0 holds its own visible range. Later, the held far end grows at once to a farther visible
    far end and falls to it only when it lies below ``(1 - h)`` of the held one; the held near end
    falls at once and grows to the visible near end only when that lies beyond ``held / (1 - h)``.
    ``h = 0`` gives the visible ranges themselves.

    Parameters
    ----------
    ranges : array_like, shape (N, 2)
        Visible ``(z_min, z_max)`` per frame in metres; NaN rows (nothing visible) keep the held range.
    hysteresis : float
        ``h`` in ``[0, 1)``.

    Returns
    -------
    ndarray, shape (N, 2), float64
    """
    r = np.asarray(ranges, dtype=np.float64).reshape(-1, 2)
    if not 0.0 <= hysteresis < 1.0:
        raise ValueError(f"hysteresis: expected a fraction in [0, 1), got {hysteresis}")
    keep = 1.0 - hysteresis
    out = r.copy()
    for i in range(1, r.shape[0]):
        lo, hi = out[i - 1]
        z0, z1 = r[i]
        if np.isnan(z0) or np.isnan(lo):
            out[i] = out[i - 1] if np.isnan(z0) else r[i]
            continue
        out[i, 1] = z1 if (z1 > hi or z1 < keep * hi) else hi
        out[i, 0] = z0 if (z0 < lo or keep * z0 > lo) else lo
    return out


def _log_ceiling(value: float, base: float) -> float:
    """``base^ceil(log_base value)`` (Stride's ``LogCeiling``)."""
    return float(base ** np.ceil(np.log(value) / np.log(base)))


def stepped_depth_ranges(ranges, *, near: float = 0.0, grow: float = 1.1, shrink: float = 2.0) -> np.ndarray:
    """The range Stride's automatic depth range holds in each frame (``LightDirectionalShadowMapRenderer.
    ComputeCascadeSplits``, ``DepthIncreaseThreshold = 1.1``, ``DepthDecreaseThreshold = 2.0``).

    Frame 0 holds its own visible range. Later the held far end becomes ``LogCeiling(z_max / held,
    base) · held`` (base ``grow`` when the visible far end lies beyond the held one, else ``shrink``):
    it grows in steps of 1.1ᵏ past the visible far end and shrinks in steps of 2⁻ᵏ, only once the
    visible far end is at most half the held one. The held depth ``far - near`` is stepped the same
    way from ``far_new - z_min`` against ``far_new - near_held``, and the near end is ``far_new`` less
    it (at least ``near``, the camera's near plane).

    Parameters
    ----------
    ranges : array_like, shape (N, 2)
        Visible ``(z_min, z_max)`` per frame in metres; NaN rows (nothing visible) keep the held range.
    near : float
        The camera's near plane in metres.

    Returns
    -------
    ndarray, shape (N, 2), float64
    """
    r = np.asarray(ranges, dtype=np.float64).reshape(-1, 2)
    out = r.copy()
    held = None
    for i in range(r.shape[0]):
        z0, z1 = r[i]
        if np.isnan(z0) or np.isnan(z1):
            if held is not None:
                out[i] = held
            continue
        low, high = max(z0, near), max(z1, z0, near)
        if held is None:
            held = (low, high)
            out[i] = held
            continue
        held_low, held_high = held
        high = _log_ceiling(high / held_high, grow if high > held_high else shrink) * held_high
        depth, held_depth = high - low, high - held_low
        if held_depth > 0.0 and depth > 0.0:
            low = high - _log_ceiling(depth / held_depth, grow if depth > held_depth else shrink) * held_depth
        held = (max(low, near), high)
        out[i] = held
    return out


@dataclass(frozen=True)
class Hold:
    """How an SDSM's visible range is held from frame to frame (``[shadow] hold``).

    Attributes
    ----------
    held : callable
        ``held(ranges, *, hysteresis, near) -> (N, 2)``: the held range of every frame from the
        visible ``ranges`` ``(N, 2)``.
    active : callable
        ``active(hysteresis) -> bool``: whether it holds anything (else each frame's own range).
    what : str
    """

    held: Callable[..., np.ndarray]
    active: Callable[[float], bool]
    what: str


HOLD_METHODS: dict[str, Hold] = {
    "fraction": Hold(lambda ranges, *, hysteresis, near: held_depth_ranges(ranges, hysteresis=hysteresis),
                     lambda hysteresis: hysteresis > 0.0,
                     "grows at once, shrinks when the visible range is `hysteresis` inside it (held_depth_ranges)"),
    "stepped": Hold(lambda ranges, *, hysteresis, near: stepped_depth_ranges(ranges, near=near),
                    lambda hysteresis: True,
                    "Stride: grows in 1.1^k and shrinks in 2^-k steps of the held range (stepped_depth_ranges)"),
}
"""Holds of an SDSM's visible range, by name."""


SHADOW_DISTANCE_METHODS: dict[str, str] = {
    "fixed": "shadow_distance metres, clamped to the camera's far plane",
    "camera_far": "the camera's far plane of each frame, at most max_shadow_distance when set (three.js maxFar, "
                  "Filament shadowFar = 0, MJP)",
    "farthest_visible": "the farthest visible point of each frame (bounds = \"sdsm\"'s held far end), at most "
                        "max_shadow_distance when set (Stride)",
}
"""Where the last cascade ends (``[shadow] shadow_distance_from``), by name."""


def shadow_end(*, method: str, shadow_distance: float, max_shadow_distance: float, camera_far: float,
               visible: tuple[float, float] | None = None) -> float:
    """The view depth in metres where the last cascade ends in one frame (:data:`SHADOW_DISTANCE_METHODS`).

    Parameters
    ----------
    method : str
        ``fixed``, ``camera_far`` or ``farthest_visible``.
    shadow_distance : float
        ``fixed``: the distance in metres.
    max_shadow_distance : float
        ``camera_far``, ``farthest_visible``: the engine's cap in metres; 0: none.
    camera_far : float
        The frame's camera far plane in metres (a glTF camera's ``zfar``, a recorded path's far).
    visible : (float, float) or None
        ``farthest_visible``: the frame's (held) visible view-depth range in metres; without one (nothing
        visible) the camera's far plane.
    """
    check_name(method, SHADOW_DISTANCE_METHODS, field="shadow_distance_from")
    if method == "fixed":
        return float(min(shadow_distance, camera_far))
    end = float(camera_far)
    if method == "farthest_visible" and visible is not None and np.all(np.isfinite(visible)):
        end = float(visible[1])
    return min(end, float(max_shadow_distance)) if max_shadow_distance > 0.0 else end


def split_range(*, near: float, far: float, visible: tuple[float, float] | None, method: str) -> tuple[float, float]:
    """The view-depth interval ``(n, f)`` in metres that the splits divide.

    ``frustum`` gives ``(near, far)``; ``sdsm`` the visible range clamped into it (the whole of it
    when nothing is visible, and at least a millimetre deep).
    """
    check_name(method, BOUNDS_METHODS, field="bounds")
    if method == "frustum" or visible is None or not np.all(np.isfinite(visible)):
        return near, far
    lo = float(np.clip(visible[0], near, far))
    hi = float(np.clip(visible[1], near, far))
    if hi - lo < 1e-3:
        return (lo, lo + 1e-3) if lo + 1e-3 <= far else (far - 1e-3, far)
    return lo, hi
