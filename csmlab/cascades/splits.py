"""Split schemes: where along the view depth each cascade ends.

References: NVIDIA, "Cascaded Shadow Maps" (2007), seed 000 — the logarithmic and practical
(PSSM) schemes; Zhang et al., "Practical Cascaded Shadow Maps", seed 003; Unreal Engine
``FDirectionalLightSceneProxy::GetSplitDistance`` (``CascadeDistributionExponent``); Bevy
``bevy_light/src/cascade.rs`` ``calculate_cascade_bounds`` (``first_cascade_far_bound``); Godot 4
``renderer_scene_cull.cpp`` ``_light_instance_setup_directional_shadow`` and MJP's ``Shadows`` sample
(``MeshRenderer.cpp``), which place fractions over the range from the near plane (``manual_range``).

Every scheme returns the ``C + 1`` boundaries ``z_0 = n < z_1 < … < z_C = f`` in metres of
view depth. Schemes are registered by name in :data:`SPLIT_METHODS`; :func:`split_distances`
dispatches on ``method=``.
"""

from __future__ import annotations

from typing import TYPE_CHECKING
from collections.abc import Callable

import numpy as np

from csmlab.cascades.bounds import shadow_end
from csmlab.registry import check_name, dispatch

if TYPE_CHECKING:
    from csmlab.settings import ShadowSettings

__all__ = ["SPLIT_METHODS", "count_one_two_or_four", "fractions_of_far", "fractions_of_range", "split_boundaries",
           "split_distances", "splits_exponent", "splits_geometric", "splits_log", "splits_manual",
           "splits_manual_range", "splits_practical", "splits_uniform", "ue_split_fractions"]


def splits_uniform(*, near: float, far: float, count: int) -> np.ndarray:
    """``z_i = n + (f - n) i / C``."""
    i = np.arange(count + 1, dtype=np.float64)
    return near + (far - near) * i / count


def splits_log(*, near: float, far: float, count: int) -> np.ndarray:
    """``z_i = n (f / n)^(i / C)`` — the scheme that gives each cascade the same texel-to-pixel ratio."""
    i = np.arange(count + 1, dtype=np.float64)
    return near * (far / near) ** (i / count)


def splits_practical(*, near: float, far: float, count: int, lambda_: float) -> np.ndarray:
    """``z_i = λ · log_i + (1 - λ) · uniform_i`` (PSSM, seed 000)."""
    return lambda_ * splits_log(near=near, far=far, count=count) + (1.0 - lambda_) * splits_uniform(
        near=near, far=far, count=count
    )


def splits_manual(*, near: float, far: float, count: int, splits=()) -> np.ndarray:
    """User-given far end of each cascade: ``count`` increasing values ending at ``far``.

    Values that are all ≤ 1 are fractions of ``far`` (the shadow distance); otherwise metres.
    """
    ends = np.asarray(splits, dtype=np.float64).reshape(-1)
    if ends.shape[0] != count:
        raise ValueError(f"splits: expected {count} far ends (one per cascade), got {ends.shape[0]}")
    if ends.size and np.all(ends <= 1.0):
        ends = ends * far
    z = np.concatenate([[near], ends])
    if not np.all(np.isfinite(z)) or np.any(np.diff(z) <= 0):
        raise ValueError(f"splits: expected increasing distances above near = {near} m, got {ends.tolist()}")
    if not np.isclose(z[-1], far, rtol=1e-9):
        raise ValueError(f"splits: expected the last cascade to end at the shadow distance {far} m, got {z[-1]}")
    z[-1] = far
    return z


def splits_manual_range(*, near: float, far: float, count: int, splits=()) -> np.ndarray:
    """User-given fractions of the range from the near plane: ``z_i = n + s_i (f - n)``, ``s_C = 1``.

    Godot 4 (``RendererSceneCull::_light_instance_setup_directional_shadow``: ``distances[i + 1] =
    min_distance + split · range`` with ``range = max_distance - min_distance`` and ``min_distance``
    the camera's near plane) and MJP's ``Shadows`` sample (``MeshRenderer::RenderShadowMap``:
    ``camera.NearClip() + splitDist · (FarClip - NearClip)``); :func:`splits_manual` scales the
    fractions by ``f`` alone.
    """
    s = np.asarray(splits, dtype=np.float64).reshape(-1)
    if s.shape[0] != count:
        raise ValueError(f"splits: expected {count} fractions (one per cascade), got {s.shape[0]}")
    if not (np.all(np.isfinite(s)) and np.all(s > 0) and np.all(np.diff(s) > 0) and np.isclose(s[-1], 1.0, rtol=1e-9)):
        raise ValueError(f"splits: expected increasing fractions of the range in (0, 1] ending at 1.0, "
                         f"got {s.tolist()}")
    z = np.concatenate([[near], near + s * (far - near)])
    z[-1] = far
    return z


def splits_exponent(*, near: float, far: float, count: int, distribution_exponent: float = 3.0) -> np.ndarray:
    """Unreal's distribution exponent: each cascade ``e`` times deeper than the one before.

    ``z_i = n + (f - n) (e^i - 1) / (e^C - 1)``, the geometric series of
    ``FDirectionalLightSceneProxy::GetSplitDistance`` (``CascadeDistributionExponent``, default
    3); ``e = 1`` is the uniform scheme.
    """
    i = np.arange(count + 1, dtype=np.float64)
    e = float(distribution_exponent)
    if e == 1.0:
        return splits_uniform(near=near, far=far, count=count)
    return near + (far - near) * np.expm1(i * np.log(e)) / np.expm1(count * np.log(e))


def splits_geometric(*, near: float, far: float, count: int, first_cascade_far: float = 10.0) -> np.ndarray:
    """Bevy's bounds: the first cascade ends at ``b``, the others spaced geometrically up to ``f``.

    ``z_0 = n``, ``z_i = b (f / b)^((i - 1) / (C - 1))`` for ``i ≥ 1`` (``calculate_cascade_bounds``
    of ``bevy_light``, ``first_cascade_far_bound``); one cascade spans ``[n, f]``.
    """
    if count == 1:
        return np.array([near, far], dtype=np.float64)
    b = float(first_cascade_far)
    if not near < b < far:
        raise ValueError(f"first_cascade_far: expected a distance between near ({near} m) and the shadow distance "
                         f"({far} m), got {b}")
    i = np.arange(count, dtype=np.float64)
    return np.concatenate([[near], b * (far / b) ** (i / (count - 1))])


SPLIT_METHODS: dict[str, Callable[..., np.ndarray]] = {
    "uniform": splits_uniform,
    "log": splits_log,
    "practical": splits_practical,
    "manual": splits_manual,
    "manual_range": splits_manual_range,
    "exponent": splits_exponent,
    "geometric": splits_geometric,
}
"""Split schemes by name; add an entry to register a new one."""


def split_distances(*, near: float, far: float, count: int, method: str = "practical", lambda_: float = 0.75,
                    splits=(), distribution_exponent: float = 3.0, first_cascade_far: float = 10.0) -> np.ndarray:
    """Cascade boundaries ``(count + 1,)`` in metres of view depth from ``near`` to ``far``.

    Parameters
    ----------
    near, far : float
        Camera near plane and shadow distance, metres, ``0 < near < far``.
    count : int
        Number of cascades.
    method : str
        A key of :data:`SPLIT_METHODS`.
    lambda_ : float
        practical: weight of the log scheme.
    splits : sequence of float
        manual: far ends (metres, or fractions of ``far``); manual_range: fractions of ``far - near``.
    distribution_exponent : float
        exponent: depth ratio of consecutive cascades (Unreal).
    first_cascade_far : float
        geometric: far end of the first cascade, metres (Bevy).
    """
    check_name(method, SPLIT_METHODS, field="split")
    if not (np.isfinite(near) and near > 0):
        raise ValueError(f"near: expected a positive distance in metres, got {near}")
    if not (np.isfinite(far) and far > near):
        raise ValueError(f"shadow_distance: expected a distance greater than near ({near} m), got {far}")
    if count < 1:
        raise ValueError(f"cascades: expected at least 1, got {count}")
    z = dispatch(SPLIT_METHODS, method, field="split", near=near, far=far, count=count,
                 offered={"lambda_": lambda_, "splits": splits, "distribution_exponent": distribution_exponent,
                          "first_cascade_far": first_cascade_far})
    z[0], z[-1] = near, far
    return z


def split_boundaries(settings: ShadowSettings, *, near: float, far: float) -> np.ndarray:
    """Cascade boundaries ``(C + 1,)`` in metres of view depth, as the cascades are built: from the camera's
    ``near`` to where the shadow ends under a camera whose far plane is ``far`` (``min(shadow_distance, far)``,
    or ``far`` itself for ``shadow_distance_from = "camera_far"`` and, no frame being seen, ``"farthest_visible"``:
    :func:`csmlab.cascades.bounds.shadow_end`)."""
    end = shadow_end(method=settings.shadow_distance_from, shadow_distance=settings.shadow_distance,
                     max_shadow_distance=settings.max_shadow_distance, camera_far=far)
    return split_distances(near=near, far=end, count=settings.cascades,
                           method=settings.split, lambda_=settings.lambda_, splits=settings.splits,
                           distribution_exponent=settings.distribution_exponent,
                           first_cascade_far=settings.first_cascade_far)


def fractions_of_far(boundaries: np.ndarray) -> list[float]:
    """The inner boundaries ``(C - 1,)`` of ``boundaries`` ``(C + 1,)`` as fractions of the last, ``z_i / z_C``:
    the splits of engines that measure from the camera (Unity, three.js ``custom``)."""
    return [float(v / boundaries[-1]) for v in boundaries[1:-1]]


def fractions_of_range(boundaries: np.ndarray) -> list[float]:
    """The inner boundaries ``(C - 1,)`` of ``boundaries`` ``(C + 1,)`` as fractions of the range from the first,
    ``(z_i - z_0) / (z_C - z_0)``: the splits of engines that measure from the near plane (Godot, Filament)."""
    return [float((v - boundaries[0]) / (boundaries[-1] - boundaries[0])) for v in boundaries[1:-1]]


def ue_split_fractions(exponent: float, count: int) -> np.ndarray:
    """Unreal's split fractions ``(count + 1,)`` of the shadow range: ``Σ_{k<i} e^k / Σ_{k<C} e^k``."""
    powers = float(exponent) ** np.arange(count, dtype=np.float64)
    return np.concatenate([[0.0], np.cumsum(powers) / powers.sum()])


def count_one_two_or_four(count: int) -> int:
    """The cascade count an engine offering 1, 2 or 4 cascades takes for ``count``: itself when offered, 3 → 2,
    above 4 → 4 (Godot's split modes, Unity built-in's shadowCascades)."""
    return count if count in (1, 2, 4) else (2 if count < 4 else 4)
