"""Error of a method's shadow against the ray-traced reference of the same frame.

Definitions (docs/design.md, "Metrics", a contract). A pixel is *compared* where it is visible, the
method has a shadow value (some cascade contains it) and the reference is defined. Its state is
shadowed when ``S <= 0.5`` (the method) or ``R <= 0.5`` (the reference).

- false shadow: the method says shadow where the reference is lit (acne, over-shadowing);
- false light: the method says lit where the reference is shadowed (leaks, peter-panning);
  both as fractions of the compared pixels.
- acne and peter-panning (``acne``, ``peter_panning``): the false shadow and the false light that
  the map's resolution cannot explain, as fractions of the compared pixels. Near a shadow boundary
  the texel grid and the filter decide the state, whatever the bias: a pixel is in the
  *resolution band* when, in the light's view (its position projected on the plane normal to the
  light), it lies within ``margin_texels`` (the filter's radius + 1, :attr:`ShadowSettings.margin_texels`)
  texels of its selected cascade — the larger of the two texel sides — of a reference boundary
  point: the light-space projection of a compared pixel whose 4-neighbour has the other reference
  state (both sides of the boundary). Acne is false shadow outside the band (self-shadowing of a
  surface the reference lights), peter-panning false light outside it (a shadow pulled off its
  caster by the bias, or any other leak). Pixels the far fade reaches (weight above 0,
  :mod:`csmlab.fades`, from the pixel's view depth or distance to the camera) are counted in
  neither: there the fade, not the bias, lights the shadow. Only the boundaries the camera sees are
  known, so a pixel near a hidden one may be counted; with no reference boundary in view no pixel
  is in the band.
- boundary distance: the shadow boundary of an image is the set of its shadowed compared pixels
  with a lit compared 4-neighbour. ``ref_boundary_px`` is the average symmetric boundary distance
  (ASSD, as in image segmentation): the Euclidean distance in pixels from every boundary pixel of
  each image to the nearest boundary pixel of the other, averaged over both sets together. It is
  0 when neither image has a boundary and NaN when only one has.
- seam error (``ref_seam_error``): the mean |S − R| over the compared pixels next to a split
  boundary — those with a pixel of another selected cascade among their 8 neighbours — NaN where
  the image holds no boundary. Both sides of a boundary count, so every pixel of a 2×2 quad that
  straddles it does: the seam of a mipmapped lookup with hardware quad derivatives
  (:mod:`csmlab.quads`; seed 003, "Filtering across splits") is this figure's to show.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property

import numpy as np
from scipy.spatial import cKDTree

from csmlab.fades import FADE_METHODS
from csmlab.frame import Frame, View
from csmlab.registry import check_name

__all__ = ["ReferenceMaps", "bias_errors", "boundary_pixels", "mean_boundary_distance", "reference_boundary",
           "reference_maps", "reference_summary", "seam_error", "split_boundary_pixels"]


@dataclass(frozen=True)
class ReferenceMaps:
    """Per-pixel agreement of a method's shadow state with the reference.

    Attributes
    ----------
    diff : ndarray, shape (H, W), int8
        +1 false shadow, −1 false light, 0 agreement or not compared.
    compared : ndarray, shape (H, W), bool
    shadowed, reference_shadowed : ndarray, shape (H, W), bool
        ``S <= 0.5`` and ``R <= 0.5`` at compared pixels; False elsewhere.
    """

    diff: np.ndarray
    compared: np.ndarray
    shadowed: np.ndarray
    reference_shadowed: np.ndarray


def reference_boundary(reference_shadowed, compared) -> np.ndarray:
    """``(H, W)`` bool: compared pixels with a compared 4-neighbour of the other reference state (both sides)."""
    compared = np.asarray(compared, dtype=bool)
    shadowed = np.asarray(reference_shadowed, dtype=bool) & compared
    return boundary_pixels(shadowed, compared) | boundary_pixels(compared & ~shadowed, compared)


def _fading(frame: Frame) -> np.ndarray:
    """``(H, W)`` bool: the far fade's weight is above 0 at the pixel (all False without a fade)."""
    settings = frame.settings
    g = frame.view.gbuffer
    if settings.fade_out <= 0.0:
        return np.zeros(g.shape, dtype=bool)
    record = FADE_METHODS[check_name(settings.fade, FADE_METHODS, field="fade")]
    # The pixels' distances to the camera are the view's alone: taken once for every method with a radial fade.
    distance = frame.view.shared(("camera_distance",), lambda: np.linalg.norm(
        g.position - frame.view.pose.position, axis=-1)) if record.radial else None
    with np.errstate(invalid="ignore"):
        weight = record.weight(g.view_depth, distance, far=float(frame.maps.cascades.splits[-1]),
                               fade_out=settings.fade_out)
        return np.asarray(weight > 0.0)


def bias_errors(frame: Frame, maps: ReferenceMaps) -> dict[str, float]:
    """``acne`` and ``peter_panning``: false shadow and false light outside the resolution band.

    Parameters
    ----------
    frame : Frame
        Its G-buffer positions (world metres) and view depths, selected cascades and their texel
        sizes, and its far fade.
    maps : ReferenceMaps
        :func:`reference_maps` of ``frame``.

    Returns
    -------
    dict of str to float
        Fractions of the compared pixels (module docstring); NaN when no pixel is compared.
    """
    count = int(np.count_nonzero(maps.compared))
    if count == 0:
        return dict.fromkeys(("acne", "peter_panning"), float("nan"))
    wrong = (maps.diff != 0) & ~_fading(frame)
    cascades = frame.maps.cascades
    boundary, tree = _reference_boundary_tree(frame.view, maps, cascades)
    # A wrong pixel that is itself a boundary point is 0 from the boundary, inside the band: only
    # the others are queried (with no boundary in view, every wrong pixel is outside).
    outside = wrong & ~boundary
    # The queried pixels by flat index (a 2-D boolean mask gathers on NumPy's slow path): the same points.
    query = np.flatnonzero(outside) if boundary.any() else np.zeros(0, dtype=np.intp)
    if query.size:
        texel = np.array([float(np.max(c.texel_size)) for c in cascades.cascades])
        selected = np.take(frame.shadow.cascade.reshape(-1), query).astype(np.int64)
        band = cascades.margin_texels * texel[selected]
        distance = tree().query(np.take(_light_xy(frame.view, cascades).reshape(-1, 2), query, axis=0))[0]
        outside.reshape(-1)[query] = distance > band
    return {
        "acne": float(np.count_nonzero(outside & (maps.diff == 1))) / count,
        "peter_panning": float(np.count_nonzero(outside & (maps.diff == -1))) / count,
    }


def _light_xy(view: View, cascades) -> np.ndarray:
    """Light-space x/y ``(H, W, 2)`` of the view's positions: the plane the map is indexed in, where
    resolution errors live. The same for every method whose maps share the light's basis: taken once
    per view and basis. Contiguous: its pixels are taken by flat index."""
    return view.shared(("light_xy", cascades.basis.tobytes()),
                       lambda: np.ascontiguousarray(cascades.to_light(view.gbuffer.position)[..., :2]))


def _pixels_key(maps: ReferenceMaps) -> tuple[bytes, bytes]:
    """What the reference's side of ``maps`` depends on, as a key of the view's shared values."""
    return np.packbits(maps.compared).tobytes(), np.packbits(maps.reference_shadowed).tobytes()


def _reference_boundary_tree(view: View, maps: ReferenceMaps, cascades):
    """:func:`reference_boundary` of ``maps`` and a function that gives the k-d tree of its points'
    light-space x/y, built once: the same for every method of the view that compares the same pixels
    (the default run's three methods, every frame), kept by the view (:meth:`View.shared`)."""
    pixels = _pixels_key(maps)
    boundary = view.shared(("reference_boundary", *pixels),
                           lambda: reference_boundary(maps.reference_shadowed, maps.compared))
    tree_key = ("reference_boundary_tree", cascades.basis.tobytes(), *pixels)
    return boundary, lambda: view.shared(tree_key, lambda: cKDTree(np.take(
        _light_xy(view, cascades).reshape(-1, 2), np.flatnonzero(boundary), axis=0),
        balanced_tree=False, compact_nodes=False))


def reference_maps(frame: Frame) -> ReferenceMaps:
    """Compare ``frame``'s shadow state ``S > 0.5`` with its view's reference R per pixel."""
    lit = frame.shadow.lit
    reference = frame.view.reference
    compared = frame.view.gbuffer.valid & np.isfinite(lit) & np.isfinite(reference)
    shadowed = compared & (lit <= 0.5)
    reference_shadowed = compared & (reference <= 0.5)
    diff = (shadowed & ~reference_shadowed).astype(np.int8) - (~shadowed & reference_shadowed).astype(np.int8)
    return ReferenceMaps(diff=diff, compared=compared, shadowed=shadowed, reference_shadowed=reference_shadowed)


def boundary_pixels(shadowed, compared) -> np.ndarray:
    """``(H, W)`` bool: shadowed compared pixels with a lit compared pixel among their 4 neighbours."""
    shadowed = np.asarray(shadowed, dtype=bool)
    lit = np.asarray(compared, dtype=bool) & ~shadowed
    padded = np.pad(lit, 1)
    lit_neighbour = padded[:-2, 1:-1] | padded[2:, 1:-1] | padded[1:-1, :-2] | padded[1:-1, 2:]
    return shadowed & lit_neighbour


def mean_boundary_distance(a, b) -> float:
    """Average symmetric distance in pixels between two boundary masks ``(H, W)`` bool.

    Each pixel of ``a`` contributes its distance to the nearest pixel of ``b`` and vice versa; the
    mean is over both sets together. 0 when both are empty, NaN when exactly one is.
    """
    return _mean_boundary_distance(np.asarray(a, dtype=bool), _Boundary(np.asarray(b, dtype=bool)))


def _pixels(mask: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The set pixels of ``mask`` ``(H, W)`` bool: their flat indices ``(N,)`` and ``(row, column)`` ``(N, 2)`` int64,
    in row-major order — ``np.argwhere(mask)``, from the flat indices at an eighth of its cost."""
    flat = np.flatnonzero(mask)
    return flat, np.stack(np.divmod(flat, mask.shape[1]), axis=1)


def _pixel_tree(points: np.ndarray) -> cKDTree:
    """A k-d tree of pixel positions ``(N, 2)`` int64, split at the middle of each box rather than at the median
    (half the build). Its nearest-neighbour distances are the same: √ of the same exact integer sums, whatever
    tree finds them."""
    return cKDTree(points, balanced_tree=False, compact_nodes=False)


class _Boundary:
    """A boundary mask ``(H, W)`` bool, its pixels (flat indices ``(N,)``, (row, column) ``(N, 2)``) and their k-d
    tree, built when first queried: the reference's side of :func:`mean_boundary_distance`, which every method of
    a view comparing the same pixels queries."""

    def __init__(self, mask: np.ndarray):
        self.mask = mask
        self.flat, self.points = _pixels(mask)

    @cached_property
    def tree(self) -> cKDTree:
        return _pixel_tree(self.points)


def _mean_boundary_distance(a: np.ndarray, b: _Boundary) -> float:
    flat, pa = _pixels(a)
    pb = b.points
    if not flat.size and not pb.size:
        return 0.0
    if not flat.size or not pb.size:
        return float("nan")
    # Nearest-neighbour queries between the two pixel sets (a k-d tree of each), not a distance
    # transform of the whole image per set: the same exact distances, √(integer), from the
    # boundaries' few thousand pixels instead of every pixel of the image. A pixel in both sets is
    # 0 from the other: only the others are queried (a method's boundary mostly lies on the
    # reference's — nine in ten pixels of the default walk), and every distance keeps its place in
    # the array that is averaged, so that the sum is taken in the same order.
    distances = np.zeros(len(pa) + len(pb), dtype=np.float64)
    only_a, only_b = ~np.take(b.mask.reshape(-1), flat), ~np.take(a.reshape(-1), b.flat)
    if only_a.any():
        distances[:len(pa)][only_a] = b.tree.query(pa[only_a])[0]
    if only_b.any():
        distances[len(pa):][only_b] = _pixel_tree(pa).query(pb[only_b])[0]
    return float(np.mean(distances, dtype=np.float64))


def reference_summary(maps: ReferenceMaps, *, view: View | None = None) -> dict[str, float]:
    """``ref_false_shadow``, ``ref_false_light`` (fractions of compared pixels) and ``ref_boundary_px``.

    All NaN when no pixel is compared. With ``view`` (the view ``maps`` compares with), the
    reference's boundary and its k-d tree are kept by the view for the other methods that compare
    the same pixels (:meth:`View.shared`): the same values.
    """
    count = int(np.count_nonzero(maps.compared))
    if count == 0:
        return dict.fromkeys(("ref_false_shadow", "ref_false_light", "ref_boundary_px"), float("nan"))

    def reference_side() -> _Boundary:
        return _Boundary(boundary_pixels(maps.reference_shadowed, maps.compared))

    side = reference_side() if view is None else view.shared(("reference_boundary_px", *_pixels_key(maps)),
                                                             reference_side)
    return {
        "ref_false_shadow": float(np.count_nonzero(maps.diff == 1)) / count,
        "ref_false_light": float(np.count_nonzero(maps.diff == -1)) / count,
        "ref_boundary_px": _mean_boundary_distance(boundary_pixels(maps.shadowed, maps.compared), side),
    }


def split_boundary_pixels(cascade) -> np.ndarray:
    """``(H, W)`` bool: pixels with a cascade (≥ 0) that have another cascade (≥ 0) among their 8 neighbours."""
    c = np.asarray(cascade)
    # Cascade indices are small: compared in int16 (or the lookup's own int8), not int64, the same tests on an
    # eighth of the bytes or less.
    if c.size and (c.min() < -1 or c.max() > np.iinfo(np.int16).max):
        raise ValueError(f"cascade: expected indices in -1..{np.iinfo(np.int16).max}, got {c.min()}..{c.max()}")
    if c.dtype != np.int8:
        c = c.astype(np.int16)
    height, width = c.shape
    out = np.zeros(c.shape, dtype=bool)
    # Being 8-neighbours of another cascade is symmetric: each of the 4 neighbour directions is
    # compared once and marks both pixels of a pair that differ, instead of 8 shifted comparisons.
    for dy, dx in ((0, 1), (1, 0), (1, 1), (1, -1)):
        rows = slice(0, height - dy)
        first, second = ((slice(0, width - dx), slice(dx, width)) if dx >= 0
                         else (slice(-dx, width), slice(0, width + dx)))
        a, b = c[rows, first], c[dy:, second]
        pair = (a >= 0) & (b >= 0) & (a != b)
        out[rows, first] |= pair
        out[dy:, second] |= pair
    return out


def seam_error(frame: Frame) -> dict[str, float]:
    """``ref_seam_error``: mean |S − R| in float64 over compared pixels next to a split boundary; NaN if none."""
    lit = frame.shadow.lit
    reference = frame.view.reference
    compared = frame.view.gbuffer.valid & np.isfinite(lit) & np.isfinite(reference)
    # The seam's flat indices found once for both arrays: the same values in the same order.
    seam = np.flatnonzero(compared & split_boundary_pixels(frame.shadow.cascade))
    if not seam.size:
        return {"ref_seam_error": float("nan")}
    error = np.abs(np.take(lit.reshape(-1), seam).astype(np.float64)
                   - np.take(reference.reshape(-1), seam).astype(np.float64))
    return {"ref_seam_error": float(np.mean(error, dtype=np.float64))}
