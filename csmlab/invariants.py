"""The invariants a method promises, derived from its settings: what ``csmlab regress`` holds exactly.

A method promises **zero same-cascade flicker** (``flicker_same`` exactly 0.0, bit for bit; the
design's "Exact zero by construction") only when every texel it stores and every lookup it makes
is fixed in the world, so that a point seen in the same cascade in two frames reads the same bits.
Each condition below is one row of :data:`_CONDITIONS`; the promise holds when all do:

1. **A static light** (workload): a moving light changes the shadow itself.
2. **World-locked snapping**: ``stabilization = "exact"`` (``quantized`` rounds the box's extent
   to steps of the camera's footprint and ``none`` follows it, so their texel sizes change) with a
   *fixed extent* — ``bounds = "frustum"`` (SDSM moves the splits with the visible depth range),
   a camera whose field of view never changes (each slice's extent follows it; a zoom path
   changes it every frame), or one that stays below a ``zoom_policy = "min_fov"`` floor, and an extent of
   :data:`FIXED_EXTENTS` — and the box snapped to whole texels (:data:`WHOLE_TEXEL_SNAPS`: every snap of
   :mod:`csmlab.cascades.stabilize` moves the box by whole texels, ``view`` in steps of four, ``nearest2`` — Godot's
   edges rounded to the nearest 2-texel unit — in steps of two: its texel size is the fixed radius's, its origin a whole
   texel index, so rounding to nearest rather than down changes only when the box steps; so does
   ``centre_nearest``, Stride's centre rounded to the nearest texel). The
   ``centroid`` extent (Godot, Stride) is fixed like ``sphere``: its centre's depth and its radius
   are closed forms of the projection and the slice depths; so are ``body_diagonal`` (DirectX CSM11's
   fit to scene) and ``diagonal_unrounded`` (three.js) like ``diagonal``, and ``centre_full`` (the
   whole map as the box, texel D/R) snaps by whole texels like ``centre``.
3. **Float64 texel math** (``engine_precision``): csmlab's global texel coordinates depend on the
   world point and the texel size only, and the box origin is an integer shift, so the rule holds
   at any distance from the world origin (up to the fixed-point clip of :mod:`csmlab.texels`,
   ~10¹⁰ texels, where every point is clipped alike). An engine's float32 light view is rounded at
   each box's centre instead: every texel coordinate carries an error that depends on where the
   box lies — about R·2⁻²⁴ texels near the origin, centimetres 10⁶ m from it — and any error can
   tip a fixed-point rounding at 2⁻ᵇⁱᵗˢ texels. Measured on 200,000 random points in a 100 m cube,
   256² boxes of 30 m moved by (3, −2) texels at 8 sub-texel bits: 0.3 % of the coordinates tip
   with the cube at the origin, 13 % 10³ m from it, all 10⁶ m from it. No coordinate range makes that
   exactly zero, only rarer (a tipped vertex changes a stored texel only where an edge passes
   that close to its centre), so ``float32`` promises nothing: a run that measures 0.0 is luck,
   not construction. Nor does ``camera_relative``: its positions are small, so its errors are
   micrometres at any distance, but its matrix is still rounded where the box lies.
4. **No screen-space input**: the filter's record reads only :data:`WORLD_LOCKED_READS`
   (:meth:`csmlab.lookup_choices.Filter.reads_of`): a disk rotated per screen pixel (``pixels``)
   turns with the camera, and a mipmapped moment lookup (``mips``) takes its level of detail and
   probes from the pixel quad's derivatives, which change with the camera and with the cascades of
   neighbouring pixels.
5. **A world-locked depth**: ``depth_range = "scene"`` or ``"scene_clipped"`` (every caster in the
   box's x/y range lies inside either, and stored depths do not depend on it; a ``slice`` box's near side follows the
   camera, and casters nearer than it are clamped onto it or clipped) in a depth format of
   :data:`WORLD_LOCKED_DEPTH_FORMATS` (quantized over the scene's fixed light-space span in
   power-of-two steps, :mod:`csmlab.storage`), and a unorm format quantized that way
   (``depth_quantization = "scene"``): ``"cascade"`` divides each box's own near/far, which moves
   with the slice wherever the slice reaches past the scene's bounds.

A **virtual clipmap** (``shadow_map = "virtual_clipmap"``, :mod:`csmlab.clipmaps`) has no boxes to
stabilize: its levels are the global texel grids of fixed texel sizes, placed on whole pages, its
texel math float64 on the host, and its depth offset fixed per light, so of the conditions above
only 1, 4 and the depth format of 5 are its own (the others are marked ``cascades`` below); the
level each point reads follows its distance to the camera, which, like a selection, only decides
which grid it reads.

Face culling (``cull``, :mod:`csmlab.culling`) keeps the promise: the triangles it drops are
chosen by their facing to the light direction alone, the same in every frame of a static light,
whatever the camera or the boxes.

Selection, blend bands and the fade-out — whatever their ``transition``, ``blend_curve`` or
``fade`` shape (a band placed forward or at the far bound, a smoothstep, a radial distance) — decide
only *which* cascade a point reads or how much a camera-dependent weight counts; the temporal metric files those points
under "cascade changed" (:mod:`csmlab.metrics.temporal`), so they keep the promise.

The promise is written into ``summary.json`` (``invariants``, :func:`summary_invariants`) and
read back by the gate, which holds exactly what was promised and nothing more.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from csmlab.lookup_choices import FILTER_METHODS
from csmlab.settings import ShadowSettings
from csmlab.shadow_policies import shadow_fov_deg

__all__ = ["FIXED_EXTENTS", "FLICKER_SAME_ZERO", "Promise", "SCREEN_READS", "WHOLE_TEXEL_SNAPS",
           "WORLD_LOCKED_DEPTH_FORMATS", "WORLD_LOCKED_READS", "WorkloadFacts", "promised_invariants",
           "summary_invariants"]

FLICKER_SAME_ZERO = "flicker_same_zero"
"""The name of the one invariant: ``flicker_same`` is exactly 0.0."""

FIXED_EXTENTS = ("sphere", "diagonal", "centroid", "body_diagonal", "diagonal_unrounded")
"""``extent`` choices whose box size depends on the projection and the slice depths only
(:mod:`csmlab.cascades.extent`); a new one promises nothing until it is listed here."""

WHOLE_TEXEL_SNAPS = ("origin", "centre", "view", "nearest2", "centre_nearest", "centre_full")
"""``snap`` choices that move an exact box by whole texels (:data:`csmlab.cascades.stabilize.SNAP_METHODS`)."""

WORLD_LOCKED_DEPTH_FORMATS = ("float32", "unorm24", "unorm16")
"""``depth_format`` choices whose stored levels are fixed per light and scene (:mod:`csmlab.storage`)."""

WORLD_LOCKED_READS = ("depth", "moments")
"""What a filter may read (:attr:`csmlab.lookup_choices.Filter.reads`) and keep the promise: texels of the maps."""

SCREEN_READS = {
    "pixels": "each receiver's screen pixel, so its taps turn with the camera",
    "mips": "the moments' mips at a level of detail from each receiver's pixel quad, which follows the camera",
}
"""What a filter may read that follows the screen, and why it breaks the promise."""


@dataclass(frozen=True)
class WorkloadFacts:
    """What the promise needs of the workload, beyond the method's settings.

    Attributes
    ----------
    light_static : bool
        The light's direction is the same in every frame.
    fov_fixed : bool
        The field of view the cascades are fitted to is the same in every frame: the camera's, or
        under ``zoom_policy = "min_fov"`` the floored one (:func:`csmlab.shadow_policies.shadow_fov_deg`).
    """

    light_static: bool
    fov_fixed: bool


@dataclass(frozen=True)
class Promise:
    """Whether a method promises an invariant, and why (or why not).

    Attributes
    ----------
    promised : bool
    metric : str
        The ``metrics.csv`` column it holds.
    value : float
        The value that column keeps, exactly.
    why : str
        What makes it hold, or every condition that fails.
    """

    promised: bool
    metric: str
    value: float
    why: str

    def as_dict(self) -> dict:
        """The record ``summary.json`` keeps (``promised``, ``metric``, ``value``, ``why``)."""
        return {"promised": self.promised, "metric": self.metric, "value": self.value, "why": self.why}


def _screen_reads(settings: ShadowSettings) -> list[str]:
    """What the filter reads under ``settings`` beyond :data:`WORLD_LOCKED_READS`, sorted."""
    reads = FILTER_METHODS[settings.filter].reads_of(settings)
    if settings.selection == "sphere_dither":
        # HDRP's dithered borders pick a cascade by each pixel's noise.
        reads = reads | {"pixels"}
    return sorted(reads - set(WORLD_LOCKED_READS))


def _screen_reads_text(settings: ShadowSettings) -> str:
    reads = [SCREEN_READS.get(read, f"{read}, not known to be world-locked") for read in _screen_reads(settings)]
    return f"filter = {settings.filter!r} reads " + " and ".join(reads)


@dataclass(frozen=True)
class _Condition:
    """One condition of the promise: a test of the settings and workload, and what fails when it does not hold."""

    holds: Callable[[ShadowSettings, WorkloadFacts], bool]
    broken: Callable[[ShadowSettings, WorkloadFacts], str]
    cascades: bool = False
    """The condition is on the cascades' boxes or texel math: a virtual clipmap has none to test."""


_CONDITIONS = (
    _Condition(lambda s, w: w.light_static, lambda s, w: "the light moves, so the shadow itself changes"),
    _Condition(lambda s, w: s.stabilization == "exact",
               lambda s, w: f"stabilization = {s.stabilization!r}: the box's texel size follows the camera",
               cascades=True),
    _Condition(lambda s, w: s.bounds == "frustum",
               lambda s, w: f"bounds = {s.bounds!r}: the splits, and so each box's extent, follow the visible depths",
               cascades=True),
    _Condition(lambda s, w: w.fov_fixed,
               lambda s, w: "the camera's field of view changes, and each box's extent with it",
               cascades=True),
    _Condition(lambda s, w: s.extent in FIXED_EXTENTS,
               lambda s, w: f"extent = {s.extent!r} is not known to be fixed",
               cascades=True),
    _Condition(lambda s, w: s.snap in WHOLE_TEXEL_SNAPS,
               lambda s, w: f"snap = {s.snap!r} is not known to move the box by whole texels",
               cascades=True),
    _Condition(lambda s, w: s.engine_precision == "float64",
               lambda s, w: f"engine_precision = {s.engine_precision!r}: the float32 light view is rounded at "
                            "each box's centre, so a whole-texel move can tip a fixed-point rounding",
               cascades=True),
    _Condition(lambda s, w: not _screen_reads(s), lambda s, w: _screen_reads_text(s)),
    _Condition(lambda s, w: s.depth_range in ("scene", "scene_clipped"),
               lambda s, w: f"depth_range = {s.depth_range!r}: the box's near side follows the camera, and casters "
                            "in front of it are clamped or clipped there",
               cascades=True),
    _Condition(lambda s, w: s.depth_format in WORLD_LOCKED_DEPTH_FORMATS,
               lambda s, w: f"depth_format = {s.depth_format!r} is not known to be world-locked"),
    _Condition(lambda s, w: s.depth_format == "float32" or s.depth_quantization == "scene",
               lambda s, w: f"depth_quantization = {s.depth_quantization!r}: each box's levels divide its own "
                            "near/far, which may follow the camera"),
)

_KEPT = ("exact boxes of fixed extent on whole texels, float64 texel math, no screen-space input and a "
         "world-locked depth under a static light")


_KEPT_CLIPMAP = ("clipmap levels on whole pages of global texel grids, no screen-space input and a world-locked depth "
                 "under a static light")


def promised_invariants(settings: ShadowSettings, *, workload: WorkloadFacts) -> dict[str, Promise]:
    """The invariants a method with ``settings`` promises on ``workload``, each with why.

    Parameters
    ----------
    settings : ShadowSettings
    workload : WorkloadFacts

    Returns
    -------
    dict
        :data:`FLICKER_SAME_ZERO` → :class:`Promise`: promised when every condition of the module
        docstring holds, its ``why`` then naming them; else not promised, ``why`` naming every
        condition that fails.
    """
    clipmap = settings.shadow_map == "virtual_clipmap"
    broken = [c.broken(settings, workload) for c in _CONDITIONS
              if not (c.cascades and clipmap) and not c.holds(settings, workload)]
    return {FLICKER_SAME_ZERO: Promise(promised=not broken, metric="flicker_same", value=0.0,
                                       why="; ".join(broken) or (_KEPT_CLIPMAP if clipmap else _KEPT))}


def summary_invariants(variants, *, light_static: bool, fov_y_deg) -> dict[str, dict[str, dict]]:
    """``summary.json``'s ``invariants``: method → sweep point → invariant → :meth:`Promise.as_dict`.

    Parameters
    ----------
    variants : iterable of csmlab.config.Variant
        Every method × sweep point of the run (``method``, ``point``, ``settings``).
    light_static : bool
        The light's direction is the same in every frame.
    fov_y_deg : array_like, shape (N,)
        The camera's field of view in every frame, degrees (each method's zoom policy then floors it).
    """
    fov = np.asarray(fov_y_deg, dtype=np.float64)
    out: dict[str, dict[str, dict]] = {}
    for variant in variants:
        s = variant.settings
        fitted = np.array([shadow_fov_deg(f, policy=s.zoom_policy, min_fov_deg=s.min_fov_deg) for f in fov])
        workload = WorkloadFacts(light_static=bool(light_static), fov_fixed=bool(np.all(fitted == fitted[0])))
        promises = promised_invariants(variant.settings, workload=workload)
        out.setdefault(variant.method, {})[variant.point] = {name: p.as_dict() for name, p in promises.items()}
    return out
