"""The unorm quantization of only some rectangles of the maps equals the whole maps' there, bit for bit."""

import numpy as np
import pytest

from csmlab.kernels.depth_storage import unorm_stored_depth
from tests.features.test_depth_quantization import unorm16_stored


def depth_maps(seed: int) -> np.ndarray:
    """``(3, 24, 24)`` float32 depths across and beyond a near/far, with empty texels and signed zeros."""
    rng = np.random.default_rng(seed)
    z = rng.uniform(-30.0, 400.0, (3, 24, 24)).astype(np.float32)
    z[:, 0] = np.inf
    z[:, 1, :4] = [-0.0, 0.0, np.nan, -np.inf]
    return z


# Strips as a scrolled frame rasterizes them (a band of rows, a band of columns), a whole map, an empty rectangle.
REGIONS = np.array([[0, 0, 24, 0, 3], [0, 20, 24, 3, 24], [1, 0, 24, 0, 24], [2, 5, 9, 7, 19], [2, 4, 4, 0, 24]])


def inside(regions, shape) -> np.ndarray:
    mask = np.zeros(shape, dtype=bool)
    for c, i0, i1, j0, j1 in regions:
        mask[c, j0:j1, i0:i1] = True
    return mask


@pytest.mark.parametrize("scheme", ["scene", "cascade"])
@pytest.mark.parametrize("seed", range(3))
def test_regions_are_quantized_as_the_whole_maps_and_the_other_texels_keep_outs_values(scheme, seed):
    z = depth_maps(seed)

    def stored(maps, **how):
        return unorm16_stored(maps, scheme, **how)

    whole = stored(z)
    out = np.full(z.shape, 7.5, dtype=np.float32)
    result = stored(z, regions=REGIONS, out=out)
    mask = inside(REGIONS, z.shape)
    assert result is out
    assert np.array_equal(out[mask].view(np.uint32), whole[mask].view(np.uint32))
    assert np.all(out[~mask] == 7.5)
    # In place: the regions of the maps themselves, the rest of them as they were.
    own = z.copy()
    assert stored(own, regions=REGIONS, out=own) is own
    assert np.array_equal(own[mask].view(np.uint32), whole[mask].view(np.uint32))
    assert np.array_equal(own[~mask].view(np.uint32), z[~mask].view(np.uint32))


def test_regions_without_out_leave_the_maps_given_as_they_were():
    z = depth_maps(4)
    z.flags.writeable = False
    result = unorm_stored_depth(z, step=2.0**-7, top=65535.0, regions=REGIONS[:1])
    mask = inside(REGIONS[:1], z.shape)
    whole = unorm_stored_depth(z, step=2.0**-7, top=65535.0)
    assert np.array_equal(result[mask].view(np.uint32), whole[mask].view(np.uint32))
    assert np.array_equal(result[~mask].view(np.uint32), z[~mask].view(np.uint32))
    assert np.array_equal(unorm_stored_depth(z, step=2.0**-7, top=65535.0, regions=np.zeros((0, 5), int)).view(
        np.uint32), z.view(np.uint32))


@pytest.mark.parametrize("region", [[3, 0, 1, 0, 1], [0, 0, 25, 0, 1], [0, -1, 2, 0, 1], [0, 0, 1, 20, 25]])
def test_regions_beyond_the_maps_are_refused(region):
    z = depth_maps(5)
    with pytest.raises(ValueError, match="regions"):
        unorm_stored_depth(z, step=2.0**-7, top=65535.0, regions=[region], out=np.empty_like(z))


def test_a_read_only_output_is_refused():
    z = depth_maps(5)
    kept = np.empty_like(z)
    kept.flags.writeable = False
    with pytest.raises(ValueError, match="out"):
        unorm_stored_depth(z, step=2.0**-7, top=65535.0, regions=REGIONS, out=kept)


def test_threads_share_out_the_regions_rows_with_the_same_bits():
    z = depth_maps(6)
    one = unorm_stored_depth(z, step=2.0**-7, top=65535.0, lo=[-1.0, 0.0, 2.5], regions=REGIONS,
                             out=np.zeros_like(z))
    two = unorm_stored_depth(z, step=2.0**-7, top=65535.0, lo=[-1.0, 0.0, 2.5], regions=REGIONS,
                             out=np.zeros_like(z), threads=2)
    assert np.array_equal(one.view(np.uint32), two.view(np.uint32))
