"""The looked-up texel count against a NumPy count of the same floors (csmlab.texels.texel_coordinates)."""

from __future__ import annotations

import numpy as np
import pytest

from csmlab.cascades import Cascade, CascadeSet
from csmlab.geometry import light_basis
from csmlab.kernels.usage import looked_up_texels
from csmlab.texels import texel_coordinates

_BOXES = ((0.05, (-2.0, 1.0), 64), (0.4, (-7.5, 2.0), 40), (1.5, (30.0, -3.0), 72))
"""Texel size (m), box centre in light x/y (m) and resolution of three cascades (sides that are not whole
words of 32 bits among them)."""


def _cascades(far):
    """Three boxes centred ``far`` metres from the origin in light x/y (fractional origins, as ``none`` has)."""
    cascades = tuple(Cascade(split_near=0.1, split_far=50.0, slice_near=0.1, slice_far=50.0,
                             texel_size=np.array([t, 1.25 * t]),
                             origin=(np.array(centre) + far) / np.array([t, 1.25 * t]) - r / 2, resolution=r,
                             depth_near=-1e3, depth_far=1e3)
                     for t, centre, r in _BOXES)
    return CascadeSet(basis=light_basis([0.3, -0.8, 0.2]), zref=0.0, splits=np.array([0.1, 5.0, 20.0, 50.0]),
                      cascades=cascades, margin_texels=2)


def _numpy_count(cs, points, selected):
    counts = []
    for c, cascade in enumerate(cs.cascades):
        texel = np.floor(texel_coordinates(cs, c, points[selected == c])).astype(np.int64)
        r = cascade.resolution
        inside = np.all((texel >= 0) & (texel < r), axis=1)
        counts.append(len({(i, j) for i, j in texel[inside]}))
    return np.array(counts)


@pytest.mark.parametrize("far", [0.0, 1.0e5])
def test_looked_up_texels_count_the_distinct_floors_of_each_cascade(far, device):
    cs = _cascades(far)
    rng = np.random.default_rng(4)
    # Points spread around each box (some outside it, many sharing a texel), a few with no cascade.
    light = np.concatenate([np.column_stack([np.array(centre) + far + rng.normal(scale=0.4 * r * t, size=(3000, 2)),
                                             rng.normal(size=3000)]) for t, centre, r in _BOXES])
    points = light @ cs.basis
    selected = np.repeat(np.arange(3), 3000)
    selected[::17] = -1
    args = dict(basis=cs.basis, texel_size=[c.texel_size for c in cs.cascades], origin=[c.origin for c in cs.cascades],
                resolution=[c.resolution for c in cs.cascades], device=device)
    expected = _numpy_count(cs, points, selected)
    np.testing.assert_array_equal(looked_up_texels(points, selected, **args), expected)
    assert np.all(expected > 50) and np.all(expected < [r * r for _, _, r in _BOXES])


def test_no_points_look_up_no_texels_and_bad_shapes_are_refused(device):
    cs = _cascades(0.0)
    args = dict(basis=cs.basis, texel_size=[c.texel_size for c in cs.cascades], origin=[c.origin for c in cs.cascades],
                resolution=[c.resolution for c in cs.cascades], device=device)
    np.testing.assert_array_equal(looked_up_texels(np.zeros((0, 3)), np.zeros(0, int), **args), [0, 0, 0])
    with pytest.raises(ValueError, match="expected indices below 3"):
        looked_up_texels(np.zeros((2, 3)), [0, 3], **args)
    with pytest.raises(ValueError, match="expected shapes"):
        looked_up_texels(np.zeros((2, 2)), [0, 1], **args)
