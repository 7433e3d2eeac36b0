"""The light projection of a cascade: orthographic, or warped by a perspective (LiSPSM).

A cascade maps light-space x/y (metres, :attr:`csmlab.cascades.CascadeSet.basis` rows 0 and 1) to
its texels. Orthographic boxes do it with a scale and an offset (``texel_size``, ``origin``); a
warped cascade with a plane projective map, a 3×3 homography ``H``:

    (i·w, j·w, w) = H · (x, y, 1),

``(i, j)`` the local texel coordinates (texel ``(i, j)`` spans ``[i, i + 1) × [j, j + 1)``). Light
rays are parallel to ``d``, so every point of a ray has one ``(x, y)`` and lands on one texel: the
warp moves where rays meet the map, never which surface a ray meets first. The full 4×4 of a
cascade (:meth:`csmlab.cascades.Cascade.projection`) adds the depth row; ortho is the special case
``H = [[1/tx, 0, −ox], [0, 1/ty, −oy], [0, 0, 1]]``.

``warp = "lispsm"`` builds ``H`` as Filament's ``ShadowMap::updateDirectional`` does (google/filament
``filament/src/ShadowMap.cpp`` @0362f36, ``applyLISPSM``, ``computeLightRotation``,
``warpFrustum``, ``computeFocusParams``), after Wimmer, Scherzer, Purgathofer, "Light Space
Perspective Shadow Maps", EGSR 2004:

1. ``L``: a rotation about the light axis turning light-space y to the camera's forward vector as
   seen from the light (``computeLightRotation``; identity when ``|d·f| ≥ 0.9997``).
2. The warp frustum looks along that y: its near plane at the receiver volume's smallest y (``n``)
   less ``n_opt``, its depth ``δ`` the volume's y extent, with
   ``n_opt = max((z0 + sqrt(vz0 · vz1)) / sin γ, dzn / (2 − 3 dzn / (zf − zn)))`` (γ the angle
   between light and view, ``z0 = zn`` the volume's nearest view depth, ``z1 = z0 + δ sin γ``,
   ``vz0, vz1`` those clamped to the virtual near and far planes of ``shadowNearHint`` and
   ``shadowFarHint``; ``dzn = max(0, near_hint − camera near)``, ``dzf = max(0, camera far −
   far_hint)``; the camera's near and far are the cascade's split, as
   ``ShadowMapManager::updateCascadeShadowMaps`` sets ``cameraInfo.zn``/``zf`` per cascade). Its eye
   sits at the camera's x. ``warpFrustum(n_opt, n_opt + δ)``:
   ``x' = n_opt x / y``, ``y' = (A y + B) / y``, ``A = (f + n)/(f − n)``, ``B = −2 f n/(f − n)``.
3. Filament falls back to no warp (``W`` identity: the rotated orthographic map) when ``sin γ``
   ≤ 0.02 (light along the view, ``n_opt → ∞``), when the volume has no y extent, or when
   ``3 dzn / (zf − zn) ≥ 2`` (the virtual near plane past ⅔ of the depth range).
4. Focus: the volume's warped x/y bounds are scaled onto the map, ``margin`` texels inside each
   edge (Filament's 1-texel border is a margin of 1).

Depth: Filament stores the warped clip depth ``n_opt · z / y`` after the divide (linear along each
light ray, its scale changing across the map; 16-bit unorm by default). csmlab stores the linear
light depth ``d·X − zref`` at each texel's ray instead (:mod:`csmlab.render` rasterizes ``z / w``,
exact across a warped triangle, and multiplies by the texel centre's ``w``), so every depth format,
bias and filter reads warped maps in the same unit as orthographic ones.
"""

from __future__ import annotations

from dataclasses import dataclass
from collections.abc import Callable

import numpy as np

from csmlab.camera import CameraPose
from csmlab.registry import check_name, dispatch

__all__ = ["WARP_METHODS", "Warp", "lispsm_parameter", "warp_lispsm", "warp_none", "warped_texels",
           "warped_texel_jacobian"]

# Filament's thresholds (ShadowMap.cpp): |d·f| above which computeLightRotation keeps identity, and
# sin γ below which applyLISPSM leaves the map unwarped ("very roughly 1 degree").
_ROTATION_LIMIT = 0.9997
_SIN_LIMIT = 0.02


@dataclass(frozen=True)
class Warp:
    """A cascade's warped projection: the homography to its texels and what it was built from.

    Attributes
    ----------
    homography : ndarray, shape (3, 3), float64
        Light-space ``(x, y, 1)`` in metres to ``(i·w, j·w, w)``, local texel coordinates times
        ``w > 0`` (``w`` the distance in metres from the warp's eye along the warp axis; 1 where
        the warp fell back to orthographic).
    n_opt : float
        The warp frustum's near distance in metres; ``inf`` where Filament falls back to ortho.
    texel_size : ndarray, shape (2,)
        Metres per texel along the map's axes at the camera's eye (Filament's
        ``texelSizeAtOneMeterWs``, from the Jacobian at the world origin, where it puts the camera):
        what the normal offset is scaled by. The slope and receiver-plane biases take each
        receiver's own texel instead (:func:`csmlab.texels.receiver_lookup`).
    """

    homography: np.ndarray
    n_opt: float
    texel_size: np.ndarray


def warped_texels(homography: np.ndarray, light_xy) -> tuple[np.ndarray, np.ndarray]:
    """Local texel coordinates ``(..., 2)`` and ``w`` ``(...)`` of light-space x/y ``(..., 2)`` metres."""
    q = np.asarray(light_xy, dtype=np.float64)
    h = q[..., 0, None] * homography[:, 0] + q[..., 1, None] * homography[:, 1] + homography[:, 2]
    w = h[..., 2]
    with np.errstate(divide="ignore", invalid="ignore"):
        return h[..., :2] / w[..., None], w


def warped_texel_jacobian(homography: np.ndarray, light_xy) -> np.ndarray:
    """∂(i, j)/∂(x, y) ``(..., 2, 2)`` texels per metre of the homography at light-space x/y ``(..., 2)``.

    The quotient rule of ``(i, j) = (h0, h1) / h2``: ``(H[:2, :2] − (i, j) ⊗ H[2, :2]) / w`` (the
    2-D form of Filament's ``jacobian`` in ShadowMap.cpp).
    """
    texel, w = warped_texels(homography, light_xy)
    return (homography[:2, :2] - texel[..., :, None] * homography[2, :2]) / w[..., None, None]


def lispsm_parameter(*, sin_gamma: float, z_near: float, z_far: float, camera_near: float, camera_far: float,
                     depth_extent: float, near_hint: float, far_hint: float) -> float:
    """Filament's ``n_opt`` in metres (``applyLISPSM``), or ``inf`` where it keeps the map orthographic.

    Parameters
    ----------
    sin_gamma : float
        sin of the angle between the light direction and the camera's forward vector.
    z_near, z_far : float
        View depths in metres of the receiver volume's nearest and farthest points (clamped to the
        camera's planes here, as Filament does).
    camera_near, camera_far : float
        The camera's (the cascade's) near and far view depths, metres.
    depth_extent : float
        δ: the volume's extent in metres along the warp axis (light-space y after ``L``).
    near_hint, far_hint : float
        ``shadowNearHint`` and ``shadowFarHint``, metres from the camera.
    """
    dzn = max(0.0, near_hint - camera_near)
    dzf = max(0.0, camera_far - far_hint)
    zn = max(camera_near, z_near)
    zf = min(camera_far, z_far)
    if not (depth_extent > 0.0 and sin_gamma > _SIN_LIMIT and zf > zn and 3.0 * (dzn / (zf - zn)) < 2.0):
        return float("inf")
    z0 = zn
    z1 = z0 + depth_extent * sin_gamma
    vz0 = max(0.0, zn, camera_near + dzn, z0)
    vz1 = max(0.0, min(zf, camera_far - dzf, z1))
    nopt0 = (z0 + np.sqrt(vz0 * vz1)) / sin_gamma
    nopt1 = dzn / (2.0 - 3.0 * (dzn / (zf - zn)))
    return float(max(nopt0, nopt1))


def _light_rotation(forward_light: np.ndarray) -> np.ndarray:
    """Filament's ``computeLightRotation`` on light x/y: rows (x̂, ŷ), ŷ the camera's forward seen from the light."""
    if abs(forward_light[2]) >= _ROTATION_LIMIT:
        return np.eye(2)
    vp = forward_light[:2] / np.hypot(forward_light[0], forward_light[1])
    # L[0] = cross(vp, ẑ) = (vp.y, −vp.x): a right-handed (x̂, ŷ, ẑ) about the light axis.
    return np.array([[vp[1], -vp[0]], [vp[0], vp[1]]])


def _focused(projective: np.ndarray, volume_xy: np.ndarray, *, resolution: int, margin: int) -> np.ndarray:
    """``projective`` followed by the scale and offset taking the volume's bounds onto the map, ``margin`` texels in."""
    mapped, _ = warped_texels(projective, volume_xy)
    lo, hi = mapped.min(axis=0), mapped.max(axis=0)
    scale = (resolution - 2 * margin) / np.maximum(hi - lo, 1e-12)
    focus = np.array([[scale[0], 0.0, margin - scale[0] * lo[0]],
                      [0.0, scale[1], margin - scale[1] * lo[1]],
                      [0.0, 0.0, 1.0]])
    return focus @ projective


def _eye_texel_size(homography: np.ndarray, eye_xy: np.ndarray) -> np.ndarray:
    """Metres per texel ``(2,)`` along the map's axes at ``eye_xy``: the columns' lengths of the inverse Jacobian."""
    inverse = np.linalg.inv(warped_texel_jacobian(homography, eye_xy))
    return np.linalg.norm(inverse, axis=0)


def warp_none(*, basis: np.ndarray, volume: np.ndarray, pose: CameraPose, resolution: int, margin: int,
              z_near: float, z_far: float, near_hint: float, far_hint: float) -> Warp | None:
    """No warp: the cascade keeps its orthographic box (``texel_size``, ``origin``)."""
    return None


def warp_lispsm(*, basis: np.ndarray, volume: np.ndarray, pose: CameraPose, resolution: int, margin: int,
                z_near: float, z_far: float, near_hint: float, far_hint: float) -> Warp:
    """Filament's LiSPSM warp of one cascade (the module's steps 1–4).

    Parameters
    ----------
    basis : ndarray, shape (3, 3)
        Light basis, rows (right, up, d).
    volume : ndarray, shape (K, 3)
        Light-space points (metres) whose convex hull is the receiver volume the map must cover
        (the slice's corners, or its focused hull: :mod:`csmlab.cascades.focus`).
    pose : CameraPose
    resolution, margin : int
        Texels per side R and texels kept free inside each edge.
    z_near, z_far : float
        The cascade's slice in metres of view depth (Filament's camera near and far of a cascade).
    near_hint, far_hint : float
        ``shadowNearHint``, ``shadowFarHint`` in metres.
    """
    light = np.asarray(volume, dtype=np.float64)
    forward = np.asarray(pose.forward, dtype=np.float64)
    rotation = _light_rotation(basis @ forward)
    rotated = light[:, :2] @ rotation.T
    n, f = float(rotated[:, 1].min()), float(rotated[:, 1].max())
    cos_gamma = float(np.clip(np.dot(forward, basis[2]), -1.0, 1.0))
    view_depth = pose.view_depth(light @ basis)
    nopt = lispsm_parameter(sin_gamma=float(np.sqrt(max(0.0, 1.0 - cos_gamma * cos_gamma))),
                            z_near=float(view_depth.min()), z_far=float(view_depth.max()), camera_near=z_near,
                            camera_far=z_far, depth_extent=f - n, near_hint=near_hint, far_hint=far_hint)
    rotate = np.array([[*rotation[0], 0.0], [*rotation[1], 0.0], [0.0, 0.0, 1.0]])
    if np.isfinite(nopt):
        eye = (basis @ np.asarray(pose.position, dtype=np.float64))[:2] @ rotation.T
        near, far = nopt, nopt + (f - n)
        a = (far + near) / (far - near)
        b = -2.0 * far * near / (far - near)
        # warpFrustum(n_opt, n_opt + δ) after translation(−p), p = (eye x, n − n_opt): rows x', y', w.
        frustum = np.array([[near, 0.0, -near * eye[0]],
                            [0.0, a, b - a * (n - nopt)],
                            [0.0, 1.0, -(n - nopt)]])
        projective = frustum @ rotate
    else:
        projective = rotate
    homography = _focused(projective, light[:, :2], resolution=resolution, margin=margin)
    eye_xy = (basis @ np.asarray(pose.position, dtype=np.float64))[:2]
    return Warp(homography=homography, n_opt=nopt, texel_size=_eye_texel_size(homography, eye_xy))


WARP_METHODS: dict[str, Callable[..., Warp | None]] = {
    "none": warp_none,
    "lispsm": warp_lispsm,
}
"""A cascade's light projection by name (``[shadow] warp``): ``none`` (orthographic boxes) or ``lispsm``."""


def cascade_warp(name: str, **params) -> Warp | None:
    """The warp ``name`` of one cascade (:data:`WARP_METHODS`), with the keywords of :func:`warp_lispsm`."""
    return dispatch(WARP_METHODS, check_name(name, WARP_METHODS, field="warp"), field="warp", **params)
