"""Per-pixel images: the colour coding of shaded views, cascades, ρ, |ΔS| and reference error.

Every colour choice of the report's pictures lives here, so that the strips, the animations and
the 3D view agree. Colour maps are perceptually uniform and colour-blind safe: viridis for
|ΔS|, ColorBrewer's RdBu (diverging) for ρ on a log2 scale centred on the 1:1 ideal, and the
Okabe–Ito palette for categories (cascades, methods, false shadow / false light).

References
----------
M. Okabe and K. Ito, "Color Universal Design (CUD): how to make figures and presentations that
are friendly to colorblind people", 2008.
"""

from __future__ import annotations

import matplotlib
import numpy as np
from matplotlib.cm import ScalarMappable
from matplotlib.colors import Normalize, PowerNorm
from matplotlib.figure import Figure
from matplotlib.patches import Patch

from csmlab.report.png import save_figure
from csmlab.srgb import srgb_encoded

__all__ = [
    "CATEGORY_COLOURS",
    "RHO_LOG2_LIMIT",
    "cascade_overlay_image",
    "change_image",
    "change_norm",
    "difference_image",
    "difference_norm",
    "rho_ratio_image",
    "rho_ratio_norm",
    "reference_diff_image",
    "rho_image",
    "rho_norm",
    "shaded_image",
    "snapshot_strip_figures",
]

CATEGORY_COLOURS = np.array([
    [0.000, 0.447, 0.698],  # blue
    [0.902, 0.624, 0.000],  # orange
    [0.000, 0.620, 0.451],  # bluish green
    [0.800, 0.475, 0.655],  # reddish purple
    [0.337, 0.706, 0.914],  # sky blue
    [0.835, 0.369, 0.000],  # vermillion
    [0.941, 0.894, 0.259],  # yellow
    [0.000, 0.000, 0.000],  # black
])
"""Okabe–Ito colours ``(8, 3)`` in sRGB [0, 1]: cascade ``i`` and method ``i`` get row ``i % 8``."""
RHO_LOG2_LIMIT = 4.0
"""ρ maps are clipped to ``2^±4`` texels per pixel: 1/16 (blocky) to 16 (wasted)."""
NO_SURFACE = np.array([0.78, 0.84, 0.92])
"""sRGB colour of pixels with no value (no surface hit, or no temporal change defined)."""
FALSE_SHADOW = CATEGORY_COLOURS[5]
FALSE_LIGHT = CATEGORY_COLOURS[4]
RHO_CMAP = matplotlib.colormaps["RdBu"]
CHANGE_CMAP = matplotlib.colormaps["viridis"]
CHANGE_GAMMA = 0.5
"""|ΔS| is coloured on a square-root scale: a PCF step of 1/9 already shows, a full flip is yellow."""
_OVERLAY_ALPHA = 0.45
_DIFF_BACKGROUND = 0.35


def _u8(rgb: np.ndarray) -> np.ndarray:
    return np.rint(np.clip(rgb, 0.0, 1.0) * 255.0).astype(np.uint8)


def _with_background(rgb: np.ndarray, defined: np.ndarray) -> np.ndarray:
    return _u8(np.where(defined[..., None], rgb, NO_SURFACE))


def shaded_image(shaded, valid) -> np.ndarray:
    """The shaded view: ``(H, W, 3)`` uint8 sRGB of linear RGB ``shaded`` (H, W, 3); NO_SURFACE where undefined."""
    shaded = np.asarray(shaded, dtype=np.float64)
    return _with_background(srgb_encoded(np.nan_to_num(shaded)), _shaded_defined(shaded, valid))


def _shaded_defined(shaded: np.ndarray, valid) -> np.ndarray:
    """Pixels with a surface and a shading (beyond the shadow distance there is none)."""
    return np.asarray(valid, dtype=bool) & np.all(np.isfinite(shaded), axis=-1)


def cascade_overlay_image(shaded, cascade, valid) -> np.ndarray:
    """The shaded view tinted by cascade index: ``(H, W, 3)`` uint8 sRGB; cascade ``i`` tinted ``CATEGORY_COLOURS[i]``.

    Parameters
    ----------
    shaded : array_like, shape (H, W, 3)
        Linear RGB.
    cascade : array_like, shape (H, W), int
        Selected cascade, -1 where none (left untinted).
    valid : array_like, shape (H, W), bool
    """
    shaded = np.asarray(shaded, dtype=np.float64)
    base = srgb_encoded(np.nan_to_num(shaded))
    return _with_background(_cascade_tint(base, cascade), _shaded_defined(shaded, valid))


def _cascade_tint(base: np.ndarray, cascade) -> np.ndarray:
    """sRGB ``base`` (H, W, 3) blended with each pixel's cascade colour."""
    cascade = np.asarray(cascade)
    tint = CATEGORY_COLOURS[np.mod(cascade, len(CATEGORY_COLOURS))]
    alpha = np.where(cascade >= 0, _OVERLAY_ALPHA, 0.0)[..., None]
    return (1.0 - alpha) * base + alpha * tint


def rho_image(rho) -> np.ndarray:
    """ρ heat map ``(H, W, 3)`` uint8: RdBu over ``log2 ρ`` clipped to ``±RHO_LOG2_LIMIT``.

    Red: under-sampled (blocky); blue: resolution wasted; white: the 1:1 ideal.
    """
    rho = np.asarray(rho, dtype=np.float64)
    defined = np.isfinite(rho) & (rho > 0)
    log2 = np.log2(np.where(defined, rho, 1.0))
    rgb = RHO_CMAP(rho_norm()(log2))[..., :3]
    return _with_background(rgb, defined)


def rho_norm() -> Normalize:
    """The normalisation of ``log2 ρ`` shared by :func:`rho_image` and its colour bar."""
    return Normalize(vmin=-RHO_LOG2_LIMIT, vmax=RHO_LOG2_LIMIT, clip=True)


def change_norm() -> PowerNorm:
    """The square-root normalisation of |ΔS| in [0, 1] shared by :func:`change_image`, its colour bar and the GIFs."""
    return PowerNorm(gamma=CHANGE_GAMMA, vmin=0.0, vmax=1.0, clip=True)


def change_image(dS) -> np.ndarray:
    """|ΔS| heat map ``(H, W, 3)`` uint8: viridis over [0, 1] (lit fraction, square-root scale); NaN NO_SURFACE."""
    dS = np.abs(np.asarray(dS, dtype=np.float64))
    rgb = CHANGE_CMAP(change_norm()(np.nan_to_num(dS)))[..., :3]
    return _with_background(rgb, np.isfinite(dS))


def reference_diff_image(shaded, ref_diff, valid) -> np.ndarray:
    """Where the shadow disagrees with the ray-traced reference: ``(H, W, 3)`` uint8.

    The shaded view, darkened, with false shadow (+1) in vermillion and false light (-1) in sky blue.
    """
    shaded = np.asarray(shaded, dtype=np.float64)
    base = srgb_encoded(np.nan_to_num(shaded))
    return _with_background(_reference_diff(base, ref_diff), _shaded_defined(shaded, valid))


def _reference_diff(base: np.ndarray, ref_diff) -> np.ndarray:
    """sRGB ``base`` (H, W, 3) darkened, false shadow and false light painted over."""
    ref_diff = np.asarray(ref_diff)[..., None]
    return np.where(ref_diff > 0, FALSE_SHADOW, np.where(ref_diff < 0, FALSE_LIGHT, _DIFF_BACKGROUND * base))


def snapshot_strip_figures(strips: list[tuple[list[dict], object, str]], labels: list[str]) -> None:
    """Write a picture per snapshot frame: a row per snapshot (method) of shaded, cascades, ρ, |ΔS| and reference error.

    A last, short row holds each column's colour bar or legend; the cascade legend runs to the
    highest cascade any of the frames selects (a note instead when no pixel falls in any cascade). The frames share one
    figure, built and laid out for the first; each further frame swaps in its images and title — the axes, colour bars
    and labels cost more to build and lay out than the images to paint.

    Parameters
    ----------
    strips : list of (snapshots, path, title)
        Per frame: snapshot arrays as :mod:`csmlab.report.capture` stores them, one per method, all of
        one image size; the ``.png``, or lossy ``.webp``, to write (:func:`csmlab.report.png.save_figure`); the
        figure title (frame and time).
    labels : list of str
        Row labels (method names), one per snapshot of a frame.

    Raises
    ------
    ValueError
        If the frames differ in image size or number of snapshots.
    """
    shapes = {(len(snapshots), *snapshots[0]["valid"].shape) for snapshots, _, _ in strips}
    if len(shapes) != 1:
        raise ValueError(f"snapshot strips: expected one image size and method count, got {sorted(shapes)}")
    rows, height, width = shapes.pop()
    panel_w = float(np.clip(width / 100.0, 3.2, 4.8))
    panel_h = panel_w * height / width
    fig = Figure(figsize=(5 * panel_w + 0.5, rows * (panel_h + 0.3) + 1.5), dpi=100, layout="constrained")
    grid = fig.add_gridspec(rows + 1, 5, height_ratios=[panel_h + 0.3] * rows + [0.55])
    cascades = int(max((s["cascade"].max() for snapshots, _, _ in strips for s in snapshots if s["cascade"].size),
                       default=-1)) + 1
    heading = fig.suptitle(strips[0][2])
    panels = None
    for snapshots, path, title in strips:
        # set_text keeps the title where the first layout put it (suptitle() would move it back).
        heading.set_text(title)
        images = [_strip_images(snap) for snap in snapshots]
        if panels is None:
            panels = _strip_panels(fig, grid, images, labels)
            _strip_keys(fig, grid, rows, cascades=cascades)
        else:
            for row, row_images in zip(panels, images):
                for panel, image in zip(row, row_images):
                    panel.set_data(image)
        save_figure(fig, path)
        # Laid out once: the frames differ only in pixels and title text, which move no margin.
        fig.set_layout_engine("none")


def _strip_panels(fig: Figure, grid, images: list[tuple[np.ndarray, ...]], labels: list[str]) -> list[list]:
    """The image axes of a strip, a row per method; return their images (``AxesImage``) by row."""
    columns = ("shaded view", "cascade index", "ρ (texels / pixel)", "|ΔS| (lit fraction)",
               "vs. ray-traced reference")
    panels = []
    for r, (row_images, label) in enumerate(zip(images, labels)):
        panels.append([])
        for c, image in enumerate(row_images):
            ax = fig.add_subplot(grid[r, c])
            panels[-1].append(ax.imshow(image, interpolation="antialiased"))
            ax.set_xticks([])
            ax.set_yticks([])
            if r == 0:
                ax.set_title(columns[c], fontsize=10)
            if c == 0:
                ax.set_ylabel(label, fontsize=11)
    return panels


def _strip_images(snap: dict) -> tuple[np.ndarray, ...]:
    """The five panels of a snapshot's row, ``(H, W, 3)`` uint8 each."""
    shaded = np.asarray(snap["shaded"], dtype=np.float64)
    base = srgb_encoded(np.nan_to_num(shaded))
    defined = _shaded_defined(shaded, snap["valid"])
    return (_with_background(base, defined), _with_background(_cascade_tint(base, snap["cascade"]), defined),
            rho_image(snap["rho"]), change_image(snap["dS"]),
            _with_background(_reference_diff(base, snap["ref_diff"]), defined))


def _strip_keys(fig: Figure, grid, rows: int, *, cascades: int) -> None:
    """The strip's last row: no key for shaded, the legend of ``cascades`` cascades, ρ and |ΔS| bars, error legend."""
    keys = [fig.add_subplot(grid[rows, c]) for c in range(5)]
    for ax in (keys[0], keys[1], keys[4]):
        ax.axis("off")
    if cascades:
        keys[1].legend(handles=[Patch(color=CATEGORY_COLOURS[i % len(CATEGORY_COLOURS)], label=f"cascade {i}")
                                for i in range(cascades)], loc="upper center", ncol=min(cascades, 4), fontsize=8,
                       frameon=False)
    else:
        # No pixel of these frames falls in a cascade (the scene is outside every one): say so, not an empty key.
        keys[1].text(0.5, 0.9, "no pixel in any cascade", ha="center", va="top", fontsize=8,
                     transform=keys[1].transAxes)
    keys[4].legend(handles=[Patch(color=FALSE_SHADOW, label="false shadow"),
                            Patch(color=FALSE_LIGHT, label="false light")],
                   loc="upper center", ncol=2, fontsize=8, frameon=False)
    rho_bar = fig.colorbar(ScalarMappable(norm=rho_norm(), cmap=RHO_CMAP), cax=keys[2], orientation="horizontal")
    ticks = np.arange(-RHO_LOG2_LIMIT, RHO_LOG2_LIMIT + 1, 2)
    rho_bar.set_ticks(ticks, labels=[_power_of_two(t) for t in ticks])
    rho_bar.set_label("ρ, texels / pixel (log scale)\n< 1 blocky, > 1 wasted", fontsize=8)
    change_bar = fig.colorbar(ScalarMappable(norm=change_norm(), cmap=CHANGE_CMAP), cax=keys[3],
                              orientation="horizontal")
    change_bar.set_ticks([0, 0.05, 0.2, 0.5, 1.0])
    change_bar.set_label("|ΔS| since the previous frame\n(lit fraction, square-root scale)", fontsize=8)


def _power_of_two(exponent: float) -> str:
    e = int(exponent)
    return str(2 ** e) if e >= 0 else f"1/{2 ** -e}"


DIFFERENCE_CMAP = matplotlib.colormaps["PuOr"]
"""Signed differences B − A (ColorBrewer PuOr, diverging, colour-blind safe): orange below 0, white 0, purple above."""
RHO_RATIO_LOG2_LIMIT = 2.0
"""ρ_B / ρ_A maps are clipped to ``2^±2``: a quarter to four times the texels per pixel."""


def difference_norm(limit: float) -> Normalize:
    """The symmetric normalisation ``[-limit, limit]`` of :func:`difference_image` and its colour bar."""
    return Normalize(vmin=-limit, vmax=limit, clip=True)


def difference_image(delta, *, limit: float) -> np.ndarray:
    """A signed difference B − A as ``(H, W, 3)`` uint8: PuOr over ``[-limit, limit]``; NaN NO_SURFACE.

    Parameters
    ----------
    delta : array_like, shape (H, W)
        B − A in the quantity's units (NaN where either is undefined).
    limit : float
        The difference shown at full colour, in the same units (keyword-only).
    """
    delta = np.asarray(delta, dtype=np.float64)
    rgb = DIFFERENCE_CMAP(difference_norm(limit)(np.nan_to_num(delta)))[..., :3]
    return _with_background(rgb, np.isfinite(delta))


def rho_ratio_norm() -> Normalize:
    """The normalisation of ``log2(ρ_B / ρ_A)`` shared by :func:`rho_ratio_image` and its colour bar."""
    return Normalize(vmin=-RHO_RATIO_LOG2_LIMIT, vmax=RHO_RATIO_LOG2_LIMIT, clip=True)


def rho_ratio_image(rho_a, rho_b) -> np.ndarray:
    """ρ_B / ρ_A as ``(H, W, 3)`` uint8: RdBu over its log2, as ρ maps are coloured.

    Red: B has fewer texels per pixel than A (blockier); blue: more; white: the same.
    """
    rho_a, rho_b = np.asarray(rho_a, dtype=np.float64), np.asarray(rho_b, dtype=np.float64)
    defined = np.isfinite(rho_a) & np.isfinite(rho_b) & (rho_a > 0) & (rho_b > 0)
    log2 = np.log2(np.where(defined, rho_b, 1.0) / np.where(defined, rho_a, 1.0))
    return _with_background(RHO_CMAP(rho_ratio_norm()(log2))[..., :3], defined)
