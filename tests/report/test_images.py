"""The snapshot strips and the PNG and WebP writer of the report's figures."""

import numpy as np
from matplotlib.figure import Figure
from PIL import Image

from csmlab.report.images import snapshot_strip_figures
from csmlab.report.png import save_figure


def _snapshot(seed: int, *, height=36, width=64) -> dict:
    rng = np.random.default_rng(seed)
    valid = rng.random((height, width)) > 0.1
    cascade = np.where(valid, rng.integers(0, 3, (height, width)), -1).astype(np.int8)
    cascade[0, 0] = 2  # every frame selects cascades 0…2: the legends agree
    return {"valid": valid, "cascade": cascade,
            "shaded": np.where(valid[..., None], rng.random((height, width, 3)), np.nan).astype(np.float32),
            "rho": np.where(valid, 2.0 ** rng.normal(0, 2, (height, width)), np.nan).astype(np.float32),
            "dS": np.where(valid, rng.random((height, width)), np.nan).astype(np.float32),
            "ref_diff": rng.integers(-1, 2, (height, width)).astype(np.int8)}


def test_strips_drawn_on_one_shared_figure_have_the_pixels_of_strips_drawn_alone(tmp_path):
    frames = [[_snapshot(10 * f + m) for m in range(2)] for f in range(3)]
    labels = ["exact", "none"]
    titles = ["frame 1, t = 0.03 s", "frame 60, t = 2.00 s", "frame 119, t = 3.97 s"]
    snapshot_strip_figures([(s, tmp_path / f"shared{k}.png", t) for k, (s, t) in enumerate(zip(frames, titles))],
                           labels)
    for k, (snapshots, title) in enumerate(zip(frames, titles)):
        snapshot_strip_figures([(snapshots, tmp_path / f"alone{k}.png", title)], labels)
        shared = np.asarray(Image.open(tmp_path / f"shared{k}.png"))
        alone = np.asarray(Image.open(tmp_path / f"alone{k}.png"))
        assert shared.shape == alone.shape and np.array_equal(shared, alone), k
    assert not np.array_equal(np.asarray(Image.open(tmp_path / "shared0.png")),
                              np.asarray(Image.open(tmp_path / "shared1.png")))


def test_a_saved_figure_is_an_rgb_png_of_the_figure_size_and_the_same_bytes_twice(tmp_path):
    fig = Figure(figsize=(3, 2), dpi=100, layout="constrained")
    ax = fig.subplots()
    ax.plot([0, 1, 2], [1, 0, 1])
    ax.set_title("a title")
    save_figure(fig, tmp_path / "a.png")
    save_figure(fig, tmp_path / "b.png")
    image = Image.open(tmp_path / "a.png")
    assert image.mode == "RGB" and image.size == (300, 200)
    assert (tmp_path / "a.png").read_bytes() == (tmp_path / "b.png").read_bytes()
    pixels = np.asarray(image)
    assert pixels[0, 0].tolist() == [255, 255, 255] and pixels.min() < 100


def _smooth_snapshot(shift: int, *, height=90, width=160) -> dict:
    """A snapshot like a rendered one: smooth shading with a shadowed block, cascades in bands, ρ a gradient."""
    y, x = np.mgrid[0:height, 0:width] / np.array([height, width])[:, None, None]
    shadow = (np.abs(x - 0.3 - shift / width) < 0.15) & (y > 0.5)
    shaded = (np.stack([0.3 + 0.4 * x, 0.5 + 0.2 * y, 0.2 + 0.1 * x * y], axis=-1)
              * np.where(shadow, 0.3, 1.0)[..., None])
    valid = y > 0.2
    return {"valid": valid, "cascade": np.where(valid, np.minimum(3 * (y - 0.2) / 0.8, 2), -1).astype(np.int8),
            "shaded": np.where(valid[..., None], shaded, np.nan).astype(np.float32),
            "rho": np.where(valid, 2.0 ** (4 * y - 2), np.nan).astype(np.float32),
            "dS": np.where(valid, np.where(shadow, 0.0, 0.02) + 0.5 * (np.abs(x - 0.45) < 0.01),
                           np.nan).astype(np.float32),
            "ref_diff": np.where(shadow & (x < 0.2), 1, 0).astype(np.int8)}


def test_a_figure_saved_as_webp_is_a_lossy_webp_of_the_png_pixels_within_its_quality_and_the_same_bytes_twice(
        tmp_path):
    """A strip as ``.webp``: the pixels of the same strip as lossless PNG (the oracle), within the error of quality 90,
    in a fraction of the bytes. PSNR bound: 38.6 dB measured on taa.toml's strip of 13 methods, at frame 60."""
    labels = ["exact", "none"]
    strips = [[_smooth_snapshot(10 * m) for m in range(2)]]
    snapshot_strip_figures([(strips[0], tmp_path / "strip.png", "frame 1")], labels)
    snapshot_strip_figures([(strips[0], tmp_path / "strip.webp", "frame 1")], labels)
    snapshot_strip_figures([(strips[0], tmp_path / "again.webp", "frame 1")], labels)
    webp = Image.open(tmp_path / "strip.webp")
    assert webp.format == "WEBP" and webp.mode == "RGB"
    png = np.asarray(Image.open(tmp_path / "strip.png"), dtype=np.float64)
    lossy = np.asarray(webp, dtype=np.float64)
    assert lossy.shape == png.shape and not np.array_equal(lossy, png)
    assert 10 * np.log10(255 ** 2 / np.mean((lossy - png) ** 2)) > 35
    assert (tmp_path / "strip.webp").stat().st_size < (tmp_path / "strip.png").stat().st_size
    assert (tmp_path / "strip.webp").read_bytes() == (tmp_path / "again.webp").read_bytes()
