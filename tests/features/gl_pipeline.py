"""A real float32 rasterizer (OpenGL 4.5 through moderngl, headless EGL) fed csmlab's cascades: the test oracle.

What runs here on the GPU side is OpenGL's, not csmlab's: the vertex transform of float32 positions
by the cascade's float32 matrix in GLSL, the rasterizer's own sub-pixel snapping, fill rule and
depth interpolation into a 32-bit float depth buffer, and a single hardware depth compare
(``sampler2DShadow``, ``GL_LEQUAL``, nearest) at each receiver. What csmlab hands it is what an
engine's host hands its GPU: the cascade boxes, the float32 matrices built on the host
(:func:`csmlab.texels.engine_matrix`), the mesh's and the G-buffer's positions as float32
(:func:`csmlab.texels.engine_positions`, relative to :func:`csmlab.texels.engine_origin`). The
receivers are a deferred renderer's: one fragment per pixel reads its float32 world position and
normal from textures (a G-buffer), moves along the normal by the normal offset, transforms by the
cascade's matrix in float32 and compares. Bias, normal offset and cascade choice are written out
here from docs/design.md's ``[shadow]`` table (constant + slope · texel · tan θ, offset in texels of
the larger side), not read from csmlab's lookup.

Needs ``moderngl`` and an EGL driver (Mesa's llvmpipe here): :func:`gl_context` raises
:class:`GLUnavailable` with the reason otherwise, and the tests skip on it.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from csmlab.cascades import CascadeSet
from csmlab.texels import engine_matrix, engine_origin, engine_positions

GL_DEPTH_CLAMP = 0x864F
MAX_TAN = 10.0

DEPTH_VERTEX = """
#version 450
uniform mat4 light_matrix;
in vec3 position;
void main() {
    vec4 clip = light_matrix * vec4(position, 1.0);
    // csmlab's matrices give depth in [0, 1]; GL's default clip depth is [-1, 1].
    gl_Position = vec4(clip.xy, clip.z * 2.0 - 1.0, 1.0);
}
"""

DEPTH_FRAGMENT = """
#version 450
out float covered;
void main() { covered = 1.0; }
"""

QUAD_VERTEX = """
#version 450
in vec2 corner;
void main() { gl_Position = vec4(corner, 0.0, 1.0); }
"""

LOOKUP_FRAGMENT = """
#version 450
uniform sampler2DShadow depth_map;
uniform sampler2D receivers;     // xyz: float32 position; w: 1 for a receiver
uniform sampler2D offsets;       // xyz: normal offset vector (metres); w: bias (metres), NaN: turned away
uniform mat4 light_matrix;
uniform float depth_range;
uniform float resolution;
out float lit;
void main() {
    ivec2 pixel = ivec2(gl_FragCoord.xy);
    vec4 receiver = texelFetch(receivers, pixel, 0);
    vec4 offset = texelFetch(offsets, pixel, 0);
    if (receiver.w == 0.0 || isnan(offset.w)) { lit = -2.0; return; }
    vec4 clip = light_matrix * vec4(receiver.xyz + offset.xyz, 1.0);
    vec2 window = clip.xy * (0.5 * resolution) + 0.5 * resolution;
    if (any(lessThan(window, vec2(0.0))) || any(greaterThanEqual(window, vec2(resolution)))) { lit = -1.0; return; }
    float reference = clip.z - offset.w / depth_range;
    lit = texture(depth_map, vec3(window / resolution, reference));
}
"""


class GLUnavailable(RuntimeError):
    """No OpenGL 4.5 context could be made here (no moderngl, no EGL driver)."""


def gl_context():
    """A headless OpenGL 4.5 context on EGL; raises :class:`GLUnavailable` saying why there is none."""
    try:
        import moderngl
    except ImportError as exc:
        raise GLUnavailable(f"moderngl is not installed ({exc}): pip install -e '.[gl]'") from None
    try:
        return moderngl.create_standalone_context(backend="egl", require=450)
    except Exception as exc:  # moderngl raises plain Exception for a missing libEGL or driver
        raise GLUnavailable(f"no EGL OpenGL 4.5 context ({exc}): apt-get install libegl1 libegl-mesa0 "
                            "libgl1-mesa-dri") from None


@dataclass(frozen=True)
class GLMaps:
    """One frame's cascades rendered by OpenGL.

    Attributes
    ----------
    depth : list of ndarray, shape (R_c, R_c), float32
        Window depth in [0, 1] per texel, row j = light y; 1.0 where nothing was drawn.
    covered : list of ndarray, shape (R_c, R_c), bool
        Texels a fragment was written to.
    cascades : CascadeSet
    origin : ndarray, shape (3,)
        The float32 positions' origin, world metres.
    matrices : list of ndarray, shape (3, 4), float32
    """

    depth: list
    covered: list
    cascades: CascadeSet
    origin: np.ndarray
    matrices: list


class GLPipeline:
    """A mesh uploaded once per float32 origin; depth maps and lookups rendered per frame."""

    def __init__(self, ctx, vertices: np.ndarray, triangles: np.ndarray):
        self.ctx = ctx
        self.vertices = np.asarray(vertices, dtype=np.float64)
        self.index = ctx.buffer(np.ascontiguousarray(triangles, dtype=np.int32).tobytes())
        self.depth_program = ctx.program(vertex_shader=DEPTH_VERTEX, fragment_shader=DEPTH_FRAGMENT)
        self.lookup_program = ctx.program(vertex_shader=QUAD_VERTEX, fragment_shader=LOOKUP_FRAGMENT)
        quad = np.array([[-1.0, -1.0], [3.0, -1.0], [-1.0, 3.0]], dtype=np.float32)
        self.quad = ctx.vertex_array(self.lookup_program, [(ctx.buffer(quad.tobytes()), "2f", "corner")])
        self._uploaded = None

    def _mesh(self, origin: np.ndarray):
        key = origin.tobytes()
        if self._uploaded is None or self._uploaded[0] != key:
            buffer = self.ctx.buffer(engine_positions(self.vertices, origin).tobytes())
            array = self.ctx.vertex_array(self.depth_program, [(buffer, "3f", "position")], index_buffer=self.index,
                                          index_element_size=4)
            self._uploaded = (key, array)
        return self._uploaded[1]

    def depth_maps(self, cascades: CascadeSet, *, precision: str, rebase_distance: float = 0.0) -> GLMaps:
        """Every cascade's depth map, both faces drawn, nearest fragment kept (``GL_LESS``)."""
        import moderngl

        origin = engine_origin(cascades.eye, precision=precision, rebase_distance=rebase_distance)
        mesh = self._mesh(origin)
        depth, covered, matrices = [], [], []
        self.ctx.enable_only(moderngl.DEPTH_TEST)
        self.ctx.enable_direct(GL_DEPTH_CLAMP)
        self.ctx.depth_func = "<"
        for c, cascade in enumerate(cascades.cascades):
            size = cascade.resolution
            matrix = engine_matrix(cascades, c, origin=origin)
            target = self.ctx.depth_texture((size, size))
            colour = self.ctx.texture((size, size), 1, dtype="f4")
            fbo = self.ctx.framebuffer(color_attachments=[colour], depth_attachment=target)
            fbo.use()
            self.ctx.viewport = (0, 0, size, size)
            fbo.clear(0.0, 0.0, 0.0, 0.0, depth=1.0)
            self.depth_program["light_matrix"].write(_mat4(matrix).T.copy().tobytes())
            mesh.render(moderngl.TRIANGLES)
            self.ctx.finish()
            depth.append(np.frombuffer(target.read(), dtype=np.float32).reshape(size, size).copy())
            covered.append(np.frombuffer(colour.read(), dtype=np.float32).reshape(size, size) > 0.5)
            matrices.append(matrix)
            fbo.release()
            colour.release()
            target.release()
        return GLMaps(depth=depth, covered=covered, cascades=cascades, origin=origin, matrices=matrices)

    def lit(self, maps: GLMaps, points: np.ndarray, normals: np.ndarray, *, normal_offset: float,
            bias_constant: float, bias_slope: float) -> np.ndarray:
        """Hard-compare lit value ``(C, H, W)`` float32 of G-buffer receivers in every cascade of ``maps``.

        ``points (H, W, 3)`` float64 world metres, NaN on a miss; ``normals (H, W, 3)``. 1 lit, 0
        shadowed, -1 outside the cascade's box, -2 no receiver or turned from the light.
        """
        import moderngl

        height, width = points.shape[:2]
        valid = np.all(np.isfinite(points), axis=-1)
        receivers = np.zeros((height, width, 4), dtype=np.float32)
        receivers[..., :3] = np.where(valid[..., None], engine_positions(points, maps.origin), 0.0)
        receivers[..., 3] = valid
        n = np.asarray(normals, dtype=np.float64)
        cos = -(n @ maps.cascades.direction)
        with np.errstate(divide="ignore", invalid="ignore"):
            tan = np.minimum(np.sqrt(np.maximum(1.0 - cos * cos, 0.0)) / cos, MAX_TAN)
        out = np.empty((len(maps.cascades), height, width), dtype=np.float32)
        self.ctx.disable(moderngl.DEPTH_TEST)
        for c, cascade in enumerate(maps.cascades.cascades):
            texel = float(np.max(cascade.texel_size))
            offsets = np.empty((height, width, 4), dtype=np.float32)
            offsets[..., :3] = n.astype(np.float32) * np.float32(normal_offset * texel)
            offsets[..., 3] = np.where(cos > 0.0, bias_constant + bias_slope * texel * tan, np.nan)
            size = cascade.resolution
            shadow = self.ctx.depth_texture((size, size), data=maps.depth[c].tobytes())
            shadow.compare_func = "<="
            shadow.filter = (moderngl.NEAREST, moderngl.NEAREST)
            positions = self.ctx.texture((width, height), 4, data=receivers.tobytes(), dtype="f4")
            moved = self.ctx.texture((width, height), 4, data=offsets.tobytes(), dtype="f4")
            for texture in (positions, moved):
                texture.filter = (moderngl.NEAREST, moderngl.NEAREST)
            result = self.ctx.texture((width, height), 1, dtype="f4")
            fbo = self.ctx.framebuffer(color_attachments=[result])
            fbo.use()
            self.ctx.viewport = (0, 0, width, height)
            shadow.use(0)
            positions.use(1)
            moved.use(2)
            program = self.lookup_program
            program["depth_map"].value = 0
            program["receivers"].value = 1
            program["offsets"].value = 2
            program["light_matrix"].write(_mat4(maps.matrices[c]).T.copy().tobytes())
            program["depth_range"].value = float(np.float32(cascade.depth_far - cascade.depth_near))
            program["resolution"].value = float(size)
            self.quad.render(moderngl.TRIANGLES)
            self.ctx.finish()
            out[c] = np.frombuffer(result.read(), dtype=np.float32).reshape(height, width)
            for resource in (fbo, result, moved, positions, shadow):
                resource.release()
        return out


def _mat4(matrix: np.ndarray) -> np.ndarray:
    """A ``(3, 4)`` world-to-clip matrix as a ``(4, 4)`` float32 with ``w = 1``."""
    out = np.zeros((4, 4), dtype=np.float32)
    out[:3] = matrix
    out[3, 3] = 1.0
    return out
