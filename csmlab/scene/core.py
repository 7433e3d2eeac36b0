"""The :class:`Scene` record: an indexed triangle mesh with per-triangle normals and albedo, and its alpha masks.

Alpha-tested casters (leaf cards, chain-link fences: glTF ``alphaMode = MASK``, an OBJ material's
``map_d``) carry texture coordinates per vertex and an :class:`AlphaMask` per vertex: a triangle
takes the mask of its vertices (all three the same, so the depth pass, the camera pass and the
reference need no triangle order: culling and reordering triangles keep it). Where the mask's
nearest texel to the interpolated coordinates is below the mask's cutoff the surface is a hole,
in every pass (:mod:`csmlab.kernels.alpha`).

Blended casters (glTF ``alphaMode = BLEND``) keep, per vertex, the mask an alpha test of their
material would use (``vertex_blend``) beside the mask the level reads them with (``vertex_mask``:
that mask or none, ``[scene] blend_casters``), so that a depth pass can cast them by its own rule
(:meth:`Scene.casters`, ``[shadow] blend_casters``) while the camera sees the level's.

Base-colour textures (glTF ``baseColorTexture``) follow the same rule: a :class:`ColourTextures`
holds coordinates and a texture index per vertex (all three of a triangle the same) and the
textures' linear RGB; the shaded views multiply the triangle's albedo (the material's base colour
factor) by the texture sampled at the hit (:mod:`csmlab.kernels.texture`).
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

__all__ = ["AlphaMask", "ColourTexture", "ColourTextures", "Scene"]


@dataclass(frozen=True)
class AlphaMask:
    """One alpha-mask texture and its cutoff.

    Attributes
    ----------
    alpha : ndarray, shape (H, W), float32
        Coverage in [0, 1]; row 0 is texture coordinate v = 0 (glTF's convention, the image's top
        row), column 0 is u = 0; coordinates repeat outside [0, 1).
    cutoff : float
        A texel is opaque where ``alpha ≥ cutoff`` (glTF ``alphaCutoff``, default 0.5), in (0, 1].
    source : str
        Where it came from (a file, or the generator that drew it).
    """

    alpha: np.ndarray
    cutoff: float = 0.5
    source: str = "mask"

    def __post_init__(self) -> None:
        a = np.ascontiguousarray(self.alpha, dtype=np.float32)
        if a.ndim != 2 or a.size == 0 or not np.all((a >= 0.0) & (a <= 1.0)):
            raise ValueError(f"{self.source}: alpha: expected a non-empty (H, W) array of values in [0, 1], "
                             f"got shape {a.shape}")
        if not 0.0 < float(self.cutoff) <= 1.0:
            raise ValueError(f"{self.source}: cutoff: expected a value in (0, 1], got {self.cutoff!r}")
        a.setflags(write=False)
        object.__setattr__(self, "alpha", a)
        object.__setattr__(self, "cutoff", float(self.cutoff))


@dataclass(frozen=True)
class ColourTexture:
    """One base-colour texture as its image stores it: 8-bit sRGB-encoded texels.

    Attributes
    ----------
    srgb : ndarray, shape (H, W, 3), uint8
        sRGB-encoded RGB (the shading decodes each texel to linear RGB, :mod:`csmlab.kernels.texture`);
        row 0 is v = 0 (the image's top row), column 0 is u = 0; coordinates repeat outside [0, 1).
    source : str
        Where it came from (a file, or the glTF file that embeds it).
    """

    srgb: np.ndarray
    source: str = "texture"

    def __post_init__(self) -> None:
        if np.asarray(self.srgb).dtype != np.uint8:
            raise ValueError(f"{self.source}: srgb: expected 8-bit texels, got {np.asarray(self.srgb).dtype}")
        texels = np.ascontiguousarray(self.srgb)
        if texels.ndim != 3 or texels.shape[2] != 3 or texels.shape[0] * texels.shape[1] == 0:
            raise ValueError(f"{self.source}: srgb: expected a non-empty (H, W, 3) array, got shape {texels.shape}")
        texels.setflags(write=False)
        object.__setattr__(self, "srgb", texels)


@dataclass(frozen=True)
class ColourTextures:
    """The base-colour textures of a scene and where each vertex samples them.

    Attributes
    ----------
    uv : ndarray, shape (V, 2), float64
        Texture coordinates per vertex (``KHR_texture_transform`` already applied).
    vertex_texture : ndarray, shape (V,), int32
        Index into ``textures`` of each vertex's texture, −1 for none (the albedo alone); a
        triangle's three vertices hold the same value.
    textures : tuple of ColourTexture
    """

    uv: np.ndarray
    vertex_texture: np.ndarray
    textures: tuple

    def __post_init__(self) -> None:
        uv = np.ascontiguousarray(self.uv, dtype=np.float64)
        index = np.ascontiguousarray(self.vertex_texture, dtype=np.int32)
        textures = tuple(self.textures)
        if index.ndim != 1 or uv.shape != (index.shape[0], 2) or not np.all(np.isfinite(uv)):
            raise ValueError(f"colour textures: expected finite uv (V, 2) beside vertex_texture (V,), got "
                             f"{uv.shape} and {index.shape}")
        if index.size and (index.min() < -1 or index.max() >= len(textures)):
            raise ValueError(f"colour textures: vertex_texture: expected indices in [-1, {len(textures)})")
        if not all(isinstance(t, ColourTexture) for t in textures):
            raise ValueError("colour textures: textures: expected ColourTexture records")
        for name, value in (("uv", uv), ("vertex_texture", index)):
            value.setflags(write=False)
            object.__setattr__(self, name, value)
        object.__setattr__(self, "textures", textures)

    @classmethod
    def none(cls, vertex_count: int) -> ColourTextures:
        """No texture on any of ``vertex_count`` vertices."""
        return cls(np.zeros((vertex_count, 2)), np.full(vertex_count, -1, np.int32), ())

    def merged(self, other: ColourTextures) -> ColourTextures:
        """These vertices' textures, then ``other``'s (its indices shifted past these textures)."""
        theirs = np.where(other.vertex_texture >= 0, other.vertex_texture + len(self.textures), -1)
        return ColourTextures(np.concatenate([self.uv, other.uv]), np.concatenate([self.vertex_texture, theirs]),
                              self.textures + other.textures)


@dataclass(frozen=True)
class Scene:
    """Geometry lit by the directional light and seen by the camera.

    Attributes
    ----------
    vertices : ndarray, shape (V, 3), float64
        World positions in metres (Y up).
    triangles : ndarray, shape (T, 3), int32
        Vertex indices, counter-clockwise seen from the side the normal points to.
    normals : ndarray, shape (T, 3), float64
        Unit geometric normal of each triangle.
    albedo : ndarray, shape (T, 3), float32
        Linear RGB reflectance in [0, 1] per triangle.
    name : str
        Where the scene came from (generator name or file).
    uv : ndarray, shape (V, 2), float64, or None
        Texture coordinates per vertex (read only where a mask applies).
    vertex_mask : ndarray, shape (V,), int32, or None
        Index into ``alpha`` of each vertex's mask, −1 for opaque; a triangle's three vertices
        hold the same value. None: every triangle opaque.
    alpha : tuple of AlphaMask
        The masks ``vertex_mask`` indexes.
    colour : ColourTextures or None
        Base-colour textures multiplying ``albedo`` where the camera sees them; None: none.
    vertex_blend : ndarray, shape (V,), int32, or None
        For each vertex of a blended (glTF ``BLEND``) material, the index into ``alpha`` of the
        mask its alpha test would use; −1 for every other vertex; a triangle's three vertices hold
        the same value, and ``vertex_mask`` there is −1 (cast solid) or the same mask. None: no
        blended triangle. Needs ``vertex_mask``.

    Raises
    ------
    ValueError
        On an empty scene, non-finite vertices, out-of-range indices, or no triangle of
        non-zero area; the message names the scene and what was expected.
    """

    vertices: np.ndarray
    triangles: np.ndarray
    normals: np.ndarray
    albedo: np.ndarray
    name: str = "scene"
    uv: np.ndarray | None = None
    vertex_mask: np.ndarray | None = None
    alpha: tuple = ()
    colour: ColourTextures | None = None
    vertex_blend: np.ndarray | None = None

    def __post_init__(self) -> None:
        v = np.ascontiguousarray(self.vertices, dtype=np.float64)
        t = np.ascontiguousarray(self.triangles, dtype=np.int32)
        if v.ndim != 2 or v.shape[1] != 3 or v.shape[0] == 0:
            raise ValueError(f"{self.name}: vertices: expected a non-empty (V, 3) array, got shape {v.shape}")
        if t.ndim != 2 or t.shape[1] != 3 or t.shape[0] == 0:
            raise ValueError(f"{self.name}: triangles: expected at least one triangle, got shape {t.shape}")
        if not np.all(np.isfinite(v)):
            raise ValueError(f"{self.name}: vertices: expected finite coordinates, found NaN or inf")
        if t.min() < 0 or t.max() >= v.shape[0]:
            raise ValueError(f"{self.name}: triangles: expected indices in [0, {v.shape[0]}), "
                             f"got [{t.min()}, {t.max()}]")
        n = np.ascontiguousarray(self.normals, dtype=np.float64)
        a = np.ascontiguousarray(self.albedo, dtype=np.float32)
        if n.shape != t.shape or a.shape != t.shape:
            raise ValueError(f"{self.name}: normals and albedo: expected shape {t.shape}, got {n.shape} and {a.shape}")
        for name, value in (("vertices", v), ("triangles", t), ("normals", n), ("albedo", a)):
            value.setflags(write=False)
            object.__setattr__(self, name, value)
        self._check_masks(v.shape[0], t)
        self._check_colour(v.shape[0], t)
        self._check_blend(v.shape[0], t)

    def _check_blend(self, vertex_count: int, t: np.ndarray) -> None:
        if self.vertex_blend is None:
            return
        b = np.ascontiguousarray(self.vertex_blend, dtype=np.int32)
        if self.vertex_mask is None or b.shape != (vertex_count,) or b.min() < -1 or b.max() >= len(self.alpha):
            raise ValueError(f"{self.name}: vertex_blend: expected ({vertex_count},) indices in "
                             f"[-1, {len(self.alpha)}) beside vertex_mask")
        if np.any(b[t] != b[t][:, :1]):
            raise ValueError(f"{self.name}: vertex_blend: expected the three vertices of a triangle to share it")
        if np.any((b >= 0) & (self.vertex_mask >= 0) & (self.vertex_mask != b)):
            raise ValueError(f"{self.name}: vertex_mask: expected a blended vertex's mask to be -1 or its vertex_blend")
        b.setflags(write=False)
        object.__setattr__(self, "vertex_blend", b)

    def _check_colour(self, vertex_count: int, t: np.ndarray) -> None:
        if self.colour is None:
            return
        if not isinstance(self.colour, ColourTextures) or self.colour.vertex_texture.shape != (vertex_count,):
            raise ValueError(f"{self.name}: colour: expected ColourTextures of {vertex_count} vertices")
        per_corner = self.colour.vertex_texture[t]
        if np.any(per_corner != per_corner[:, :1]):
            raise ValueError(f"{self.name}: colour: expected the three vertices of a triangle to share a texture")

    def _check_masks(self, vertex_count: int, t: np.ndarray) -> None:
        if self.vertex_mask is None:
            if self.uv is not None or self.alpha:
                raise ValueError(f"{self.name}: uv and alpha: expected vertex_mask with them")
            return
        m = np.ascontiguousarray(self.vertex_mask, dtype=np.int32)
        uv = np.ascontiguousarray(self.uv, dtype=np.float64) if self.uv is not None else None
        masks = tuple(self.alpha)
        if m.shape != (vertex_count,) or m.min() < -1 or m.max() >= len(masks):
            raise ValueError(f"{self.name}: vertex_mask: expected ({vertex_count},) indices in [-1, {len(masks)})")
        if uv is None or uv.shape != (vertex_count, 2) or not np.all(np.isfinite(uv)):
            raise ValueError(f"{self.name}: uv: expected finite texture coordinates of shape ({vertex_count}, 2)")
        if not all(isinstance(mask, AlphaMask) for mask in masks):
            raise ValueError(f"{self.name}: alpha: expected AlphaMask records")
        per_corner = m[t]
        if np.any(per_corner != per_corner[:, :1]):
            raise ValueError(f"{self.name}: vertex_mask: expected the three vertices of a triangle to share a mask "
                             f"(give masked triangles vertices of their own)")
        for name, value in (("vertex_mask", m), ("uv", uv)):
            value.setflags(write=False)
            object.__setattr__(self, name, value)
        object.__setattr__(self, "alpha", masks)

    @property
    def textured(self) -> bool:
        """Whether any triangle has a base-colour texture."""
        return self.colour is not None and bool(np.any(self.colour.vertex_texture >= 0))

    @property
    def blended(self) -> bool:
        """Whether any triangle is of a blended (glTF ``BLEND``) material."""
        return self.vertex_blend is not None and bool(np.any(self.vertex_blend >= 0))

    def casters(self, rule: str) -> Scene:
        """The scene as a depth pass casts it under ``rule`` for its blended triangles (``[shadow] blend_casters``).

        ``"opaque"``: solid; ``"masked"``: alpha-tested with their ``vertex_blend`` mask; ``"none"``:
        dropped (the vertices stay, unreferenced). This scene itself where the rule changes nothing
        (no blended triangle, or they already cast so), so a level without them is cast bit for bit
        as before.

        Raises
        ------
        ValueError
            On a rule not one of ``opaque``, ``masked``, ``none``.
        """
        if rule not in ("opaque", "masked", "none"):
            raise ValueError(f"blend_casters: expected one of ['opaque', 'masked', 'none'], got {rule!r}")
        if not self.blended:
            return self
        blend = self.vertex_blend >= 0
        if rule == "none":
            keep = ~blend[self.triangles[:, 0]]
            if not np.any(keep):
                raise ValueError(f"{self.name}: blend_casters = \"none\" leaves no caster: every triangle is blended")
            return replace(self, triangles=self.triangles[keep], normals=self.normals[keep],
                           albedo=self.albedo[keep], vertex_blend=None)
        mask = np.where(blend, self.vertex_blend if rule == "masked" else -1, self.vertex_mask)
        return self if np.array_equal(mask, self.vertex_mask) else replace(self, vertex_mask=mask)

    @property
    def masked(self) -> bool:
        """Whether any triangle is alpha-tested."""
        return self.vertex_mask is not None and bool(np.any(self.vertex_mask >= 0))

    @classmethod
    def from_triangles(cls, vertices, triangles, *, albedo=(0.6, 0.6, 0.6), name: str = "scene") -> Scene:
        """Build a scene, computing each triangle's normal from its winding.

        Degenerate (zero-area) triangles are dropped; a scene left with none raises ``ValueError``.
        ``albedo`` is one RGB triple or a ``(T, 3)`` array.
        """
        v = np.asarray(vertices, dtype=np.float64)
        t = np.asarray(triangles, dtype=np.int64).reshape(-1, 3)
        alb = np.broadcast_to(np.asarray(albedo, dtype=np.float32), t.shape)
        if v.ndim != 2 or v.shape[-1] != 3 or v.shape[0] == 0 or t.shape[0] == 0:
            raise ValueError(f"{name}: expected vertices (V, 3) and at least one triangle, got {v.shape} and {t.shape}")
        if not np.all(np.isfinite(v)):
            raise ValueError(f"{name}: vertices: expected finite coordinates, found NaN or inf")
        if t.min() < 0 or t.max() >= v.shape[0]:
            raise ValueError(f"{name}: triangles: expected indices in [0, {v.shape[0]}), got [{t.min()}, {t.max()}]")
        cross = np.cross(v[t[:, 1]] - v[t[:, 0]], v[t[:, 2]] - v[t[:, 0]])
        length = np.linalg.norm(cross, axis=1)
        scale = max(float(np.ptp(v, axis=0).max()), 1e-30)
        keep = length > 1e-12 * scale * scale
        if not np.any(keep):
            raise ValueError(f"{name}: triangles: expected at least one triangle of non-zero area, "
                             f"all {t.shape[0]} are degenerate")
        return cls(v, t[keep], cross[keep] / length[keep, None], alb[keep], name=name)

    @property
    def triangle_count(self) -> int:
        return self.triangles.shape[0]

    @property
    def bounds(self) -> np.ndarray:
        """Axis-aligned bounds ``(2, 3)``: min and max corner in metres."""
        return np.stack([self.vertices.min(axis=0), self.vertices.max(axis=0)])

    def corners(self) -> np.ndarray:
        """The eight corners ``(8, 3)`` of :attr:`bounds`."""
        lo, hi = self.bounds
        return np.array([[x, y, z] for x in (lo[0], hi[0]) for y in (lo[1], hi[1]) for z in (lo[2], hi[2])])

    def merged(self, other: Scene, *, name: str | None = None) -> Scene:
        """This scene and ``other`` as one (their masks side by side)."""
        masks = {}
        if self.vertex_mask is not None or other.vertex_mask is not None:
            def mask_of(scene, first):
                if scene.vertex_mask is None:
                    return np.full(len(scene.vertices), -1, np.int32), np.zeros((len(scene.vertices), 2))
                return np.where(scene.vertex_mask >= 0, scene.vertex_mask + first, -1), scene.uv
            own, own_uv = mask_of(self, 0)
            theirs, their_uv = mask_of(other, len(self.alpha))
            masks = dict(uv=np.concatenate([own_uv, their_uv]), vertex_mask=np.concatenate([own, theirs]),
                         alpha=self.alpha + other.alpha)
        if self.vertex_blend is not None or other.vertex_blend is not None:
            def blend_of(scene, first):
                if scene.vertex_blend is None:
                    return np.full(len(scene.vertices), -1, np.int32)
                return np.where(scene.vertex_blend >= 0, scene.vertex_blend + first, -1)
            masks["vertex_blend"] = np.concatenate([blend_of(self, 0), blend_of(other, len(self.alpha))])
        if self.colour is not None or other.colour is not None:
            masks["colour"] = (self.colour or ColourTextures.none(len(self.vertices))).merged(
                other.colour or ColourTextures.none(len(other.vertices)))
        return Scene(
            np.concatenate([self.vertices, other.vertices]),
            np.concatenate([self.triangles, other.triangles + self.vertices.shape[0]]),
            np.concatenate([self.normals, other.normals]),
            np.concatenate([self.albedo, other.albedo]),
            name=name or self.name,
            **masks,
        )
