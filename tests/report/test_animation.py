"""The flicker animations: a fixed palette, frames in order, the colour coding as documented."""

import math

import imageio.v3 as iio
import matplotlib
import numpy as np

from csmlab.report.animation import ANIMATION_PALETTE, write_animation
from csmlab.report.images import NO_SURFACE


def _frames(n=5, h=6, w=8, seed=0):
    rng = np.random.default_rng(seed)
    shadow = rng.integers(0, 256, (n, h, w)).astype(np.uint8)
    dS = rng.integers(0, 256, (n, h, w)).astype(np.uint8)
    shadow[:, 0, 0], shadow[:, 0, 1], shadow[:, 0, 2] = 0, 254, 255
    dS[:, 0, 0], dS[:, 0, 1], dS[:, 0, 2] = 0, 254, 255
    return shadow, dS


def test_gif_frames_show_grey_shadow_beside_viridis_change(tmp_path):
    shadow, dS = _frames()
    write_animation(tmp_path / "a.gif", shadow=shadow, dS=dS, fps=30)
    frames = iio.imread(tmp_path / "a.gif", index=None)[..., :3].astype(int)
    assert frames.shape == (5, 6, 2 * 8 + 4, 3)
    viridis = np.rint(np.asarray(matplotlib.colormaps["viridis"]([0.0, 1.0]))[:, :3] * 255).astype(int)
    no_value = np.rint(NO_SURFACE * 255).astype(int)
    for k, f in enumerate(frames):
        left, right = f[:, :8], f[:, 12:]
        assert left[0, 0].tolist() == [0, 0, 0] and left[0, 1].tolist() == [255, 255, 255]
        assert left[0, 2].tolist() == no_value.tolist() and right[0, 2].tolist() == no_value.tolist()
        assert right[0, 0].tolist() == viridis[0].tolist() and right[0, 1].tolist() == viridis[1].tolist()
        grey = left[shadow[k] != 255]
        assert np.all(grey[:, 0] == grey[:, 1]) and np.all(grey[:, 1] == grey[:, 2])


def test_gif_grey_levels_follow_the_lit_fraction_monotonically(tmp_path):
    shadow = np.tile(np.arange(0, 255, dtype=np.uint8)[None, None, :], (2, 1, 1))
    write_animation(tmp_path / "ramp.gif", shadow=shadow, dS=np.zeros_like(shadow), fps=10)
    grey = iio.imread(tmp_path / "ramp.gif", index=None)[0, 0, :255, 0].astype(int)
    assert np.all(np.diff(grey) >= 0)
    assert np.all(np.abs(grey - np.arange(255) * 255 / 254) <= 255 / 127 / 2 + 1)


def test_every_frame_uses_the_one_fixed_palette(tmp_path):
    shadow, dS = _frames(n=4, seed=1)
    write_animation(tmp_path / "a.gif", shadow=shadow, dS=dS, fps=30)
    frames = iio.imread(tmp_path / "a.gif", index=None)[..., :3]
    palette = {tuple(c) for c in ANIMATION_PALETTE.tolist()}
    assert {tuple(c) for c in frames.reshape(-1, 3).tolist()} <= palette


def test_same_frames_give_the_same_gif_bytes(tmp_path):
    shadow, dS = _frames(seed=2)
    write_animation(tmp_path / "a.gif", shadow=shadow, dS=dS, fps=24)
    write_animation(tmp_path / "b.gif", shadow=shadow, dS=dS, fps=24)
    assert (tmp_path / "a.gif").read_bytes() == (tmp_path / "b.gif").read_bytes()


def test_every_code_pair_maps_to_the_documented_palette_index():
    """Grey ``round(127 · S)``, viridis ``128 + round(126 · sqrt(|ΔS|))`` with v = code / 254; 255 no value."""
    from csmlab.report.animation import animation_indices

    codes = np.arange(256, dtype=np.uint8)
    indices = animation_indices(codes[None, None, :], codes[None, None, :])[0, 0]
    grey = [255 if c == 255 else round(127 * c / 254) for c in range(256)]
    change = [255 if c == 255 else 128 + round(126 * math.sqrt(c / 254)) for c in range(256)]
    assert indices[:256].tolist() == grey
    assert indices[256:260].tolist() == [255] * 4
    assert indices[260:].tolist() == change
