"""csmlab's depth pass and float32 emulations against a real OpenGL float32 pipeline (tests/features/gl_pipeline.py).

One short walk over a small terrain, 8 frames, a hard shadow (``filter = "none"``: one depth compare,
the one the GL pipeline's ``sampler2DShadow`` makes, of the receiver's own biased depth: no
receiver-plane bias), rendered by csmlab and, from the same cascades,
matrices, mesh and G-buffer, by OpenGL on Mesa's llvmpipe. At the world origin both must agree texel
for texel on which texels the depth maps cover and pixel for pixel on the shadow (≥ 99.9 %), and
``exact`` must not flicker in either. Far from the origin (10⁵, 10⁶ m) csmlab's ``float32`` and
``camera_relative`` emulations must swim as much as the GL pipeline fed the same float32 positions
and matrices: same-cascade flicker within a factor 1.5, for exact, quantized and none.
"""

from __future__ import annotations

import functools

import numpy as np
import pytest

from csmlab.config import load_experiment
from csmlab.experiment import build_workload
from csmlab.metrics.temporal import temporal_maps
from csmlab.render import prepare_scene, render_shadow, render_view

from tests.features.gl_pipeline import GLPipeline, GLUnavailable, gl_context

pytestmark = [pytest.mark.gl, pytest.mark.slow]

FRAMES = 8

WALK = """
name = "gl_oracle"
extends = ["scenes/terrain", "paths/walk", "lights/sun_40"]

[scene]
offset = [{offset}, 0.0, {offset}]

[camera]
frames = {frames}
width = 128
height = 72

[shadow]
cascades = 3
resolution = 256
filter = "none"
receiver_plane_bias = false
"""

STABILIZATIONS = ("exact", "quantized", "none")


@functools.lru_cache(maxsize=1)
def _context():
    return gl_context()


@pytest.fixture(scope="module")
def ctx():
    try:
        return _context()
    except GLUnavailable as exc:
        pytest.skip(str(exc))


@functools.cache
def _workload(offset: float, tmp: str):
    path = f"{tmp}/walk_{int(offset)}.toml"
    with open(path, "w") as file:
        file.write(WALK.format(offset=repr(float(offset)), frames=FRAMES))
    experiment = load_experiment(path)
    workload = build_workload(experiment)
    return experiment, workload, prepare_scene(workload.scene)


def _runs(ctx, offset: float, tmp: str, precision: str, stabilization: str) -> dict:
    """csmlab's and GL's lit values, cascades and flicker over the walk for one method."""
    import dataclasses

    experiment, workload, dscene = _workload(offset, tmp)
    settings = dataclasses.replace(experiment.methods[0].settings, stabilization=stabilization,
                                   engine_precision=precision).validated()
    gl = GLPipeline(ctx, workload.scene.vertices, workload.scene.triangles)
    out = {"coverage_equal": True, "agree": 0, "pixels": 0, "csm_change": 0.0, "gl_change": 0.0, "same": 0}
    previous = None
    for index in range(len(workload.path)):
        view = render_view(dscene, workload.path.pose(index), workload.light.direction(index), width=workload.width,
                           height=workload.height, index=index)
        frame = render_shadow(dscene, view, settings)
        maps = gl.depth_maps(frame.maps.cascades, precision=precision)
        for c, cascade in enumerate(frame.maps.cascades.cascades):
            size = cascade.resolution
            mine = np.isfinite(frame.maps.depth[c, :size, :size])
            out["coverage_equal"] &= bool(np.array_equal(mine, maps.covered[c]))
        g = view.gbuffer
        bias = dict(normal_offset=settings.normal_offset, bias_constant=settings.bias_constant,
                    bias_slope=settings.bias_slope)
        lit = gl.lit(maps, g.position, g.normal, **bias)
        chosen = _selected(lit, frame.shadow.cascade)
        counted = np.isfinite(frame.shadow.lit) & (chosen >= 0)
        out["agree"] += int(np.sum((frame.shadow.lit[counted] > 0.5) == (chosen[counted] > 0.5)))
        out["pixels"] += int(counted.sum())
        if previous is not None:
            temporal = temporal_maps(frame, previous[0])
            same = temporal.same_cascade
            earlier = _selected(gl.lit(previous[1], g.position, g.normal, **bias), _cascade_of(temporal, frame))
            same &= (earlier >= 0) & (chosen >= 0)
            out["csm_change"] += float(np.abs(temporal.change[same]).sum())
            out["gl_change"] += float(np.abs(chosen[same] - earlier[same]).sum())
            out["same"] += int(same.sum())
        previous = (frame, maps)
    out["csm_flicker"] = out["csm_change"] / out["same"]
    out["gl_flicker"] = out["gl_change"] / out["same"]
    return out


def _cascade_of(temporal, frame) -> np.ndarray:
    """The cascade frame t−1 selected at frame t's pixels: frame t's where the two agree (same-cascade pixels)."""
    return np.where(temporal.same_cascade, frame.shadow.cascade, -1)


def _selected(lit: np.ndarray, cascade: np.ndarray) -> np.ndarray:
    """``lit (C, H, W)`` at each pixel's cascade ``(H, W)``; -1 where none or outside it."""
    c = np.clip(cascade, 0, lit.shape[0] - 1).astype(np.int64)
    value = np.take_along_axis(lit, c[None], axis=0)[0]
    return np.where(cascade >= 0, value, -1.0)


@pytest.fixture(scope="module")
def tmp(tmp_path_factory):
    return str(tmp_path_factory.mktemp("gl_oracle"))


@pytest.mark.parametrize("stabilization", STABILIZATIONS)
def test_at_the_origin_gl_covers_the_same_texels_and_agrees_on_the_shadow(ctx, tmp, stabilization):
    run = _runs(ctx, 0.0, tmp, "float32", stabilization)
    assert run["coverage_equal"]
    assert run["agree"] >= 0.999 * run["pixels"]
    if stabilization == "exact":
        assert run["csm_flicker"] == 0.0 and run["gl_flicker"] == 0.0


@pytest.mark.parametrize("offset", [1e5, 1e6])
@pytest.mark.parametrize("precision", ["float32", "camera_relative"])
@pytest.mark.parametrize("stabilization", STABILIZATIONS)
def test_far_from_the_origin_the_emulation_swims_as_much_as_gl(ctx, tmp, offset, precision, stabilization):
    run = _runs(ctx, offset, tmp, precision, stabilization)
    low, high = sorted((run["csm_flicker"], run["gl_flicker"]))
    assert high <= 1.5 * low, run


def test_without_moderngl_the_oracle_says_what_to_install(monkeypatch):
    """Where the GL stack is missing the tests skip, and the reason names what to install."""
    import sys

    monkeypatch.setitem(sys.modules, "moderngl", None)
    with pytest.raises(GLUnavailable, match=r"moderngl is not installed .*pip install -e '\.\[gl\]'"):
        gl_context()
