"""Mesh import: a user's level geometry read through PyVista/VTK and checked before use.

Formats: Wavefront OBJ, PLY, STL, legacy VTK (``.vtk``), VTK XML (``.vtp``, ``.vtu``) as far as
VTK's readers go, and glTF 2.0 (``.gltf``, ``.glb``) through :mod:`csmlab.scene.gltf` (its own parse),
which places every mesh by the node hierarchy and ``EXT_mesh_gpu_instancing`` and reads its
``alphaMode = "MASK"`` materials. Whatever a VTK
file holds — polygons, triangle strips, volume cells — becomes its outer surface, triangulated;
lines and points are ignored. Normals are recomputed per triangle from the winding (counter-clockwise seen
from outside), never taken from the file.

An OBJ file's materials with an alpha map (``map_d`` in its ``mtllib``) become alpha-tested
triangles (:class:`~csmlab.scene.core.AlphaMask`, cutoff 0.5: OBJ has none of its own): the map's
alpha channel (or luminance) read by :func:`csmlab.scene.alpha_files.read_alpha_mask`, the
material's texture coordinates (``vt``, which VTK keeps per material), ``v`` turned to run down the
image (OBJ's origin is the image's bottom-left). Each masked triangle gets vertices of its own.
A material's ``Kd`` (linear RGB) is its triangles' albedo and its ``map_Kd`` (sRGB, read by
:func:`csmlab.scene.alpha_files.read_colour_texture`) multiplies it where the camera sees it
(:class:`~csmlab.scene.core.ColourTextures`, sampled at the same ``vt``); a face without a material
colour takes the ``albedo`` given.
A glTF file's ``alphaMode = "MASK"`` materials become alpha-tested triangles the same way, read by
:mod:`csmlab.scene.gltf` (VTK's reader keeps no material).

A broken file stops here with an :class:`~csmlab.errors.InputError` naming the file and what was
expected. VTK reports failures in three ways — an exception, an error or warning event (with an
empty or partial result), or silently an empty result — and prints to stderr while doing so; all
three are caught and VTK's own output is silenced.
"""

from __future__ import annotations

import logging
import re
import warnings
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from csmlab.documents import MAX_COORDINATE, MAX_TRIANGLES, is_file, within_limit
from csmlab.errors import InputError
from csmlab.registry import check_name
from csmlab.scene.alpha_files import read_alpha_mask, read_colour_texture
from csmlab.scene.core import ColourTextures, Scene
from csmlab.scene.gltf import gltf_scene_triangles, read_gltf
from csmlab.scene.gltf_materials import BLEND_CASTERS, blend_rule_masks, read_blended_masked
from csmlab.scene.shapes import height_field, scene_from_parts

__all__ = ["GLTF_SUFFIXES", "GROUND_ALBEDO", "GROUND_SIZE_FACTOR", "MESH_FORMATS", "UP_AXES", "load_mesh"]

MESH_FORMATS: dict[str, str] = {
    ".obj": "Wavefront OBJ",
    ".ply": "PLY",
    ".stl": "STL",
    ".vtk": "legacy VTK",
    ".vtp": "VTK XML poly data",
    ".vtu": "VTK XML unstructured grid",
    ".gltf": "glTF",
    ".glb": "binary glTF",
}
"""File suffixes :func:`load_mesh` accepts, with the format each names."""
GLTF_SUFFIXES = (".gltf", ".glb")
"""Suffixes read by :mod:`csmlab.scene.gltf` (node transforms, instancing, alpha masks) instead of VTK."""

UP_AXES: dict[str, np.ndarray] = {
    "y": np.eye(3),
    "z": np.array([[1.0, 0.0, 0.0], [0.0, 0.0, 1.0], [0.0, -1.0, 0.0]]),
}
"""Rotation ``(3, 3)`` taking a file's coordinates to csmlab's Y-up world, by the file's up axis.

``"z"`` maps ``(x, y, z) → (x, z, −y)``: a −90° turn about +X, so the file's +Z becomes +Y and its
+Y (Blender's "back") becomes −Z; handedness is kept.
"""

GROUND_ALBEDO = (0.5, 0.5, 0.5)
"""Linear RGB of the optional ground plane."""
GROUND_SIZE_FACTOR = 8.0
"""Side of the optional ground plane, in multiples of the mesh's largest bounding-box side."""


def _drop_record(_record) -> bool:
    return False


@contextmanager
def _quiet_vtk():
    """Silence VTK and PyVista while reading; yield the error catcher and the warning list.

    PyVista forwards VTK errors to the root logger, whose ``logging.error`` would install a
    stderr handler on first use; a temporary null handler and a dropping filter prevent both.
    """
    import pyvista as pv

    root = logging.getLogger()
    null = logging.NullHandler()
    root.addHandler(null)
    root.addFilter(_drop_record)
    try:
        with pv.vtk_verbosity("off"), pv.VtkErrorCatcher(send_to_logging=False) as catcher, \
                warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            yield catcher, caught
    finally:
        root.removeFilter(_drop_record)
        root.removeHandler(null)


def _vtk_reason(text: str) -> str:
    """The informative line of a VTK message, without source locations and object addresses."""
    lines = [ln.strip() for ln in str(text).splitlines() if ln.strip()]
    lines = [ln for ln in lines if not re.match(r"^(ERROR|Warning|Generic Warning): In ", ln)] or lines or ["no detail"]
    return re.sub(r"\s*\(0x[0-9a-fA-F]+\)", "", lines[0])


def _read_dataset(path: Path, fmt: str):
    """Read ``path`` with VTK's reader for its suffix; any failure becomes an ``InputError``."""
    import pyvista as pv

    expected = f"expected a mesh in {fmt} format that VTK can read"
    try:
        with _quiet_vtk() as (catcher, caught):
            data = pv.get_reader(str(path)).read()
            if isinstance(data, pv.MultiBlock):
                data = data.combine()
    except Exception as exc:  # VTK and PyVista raise many unrelated types on a bad file.
        raise InputError(f"{expected}; reading failed: {_vtk_reason(exc)}", file=path, field="file") from exc
    if catcher.events:
        raise InputError(f"{expected}; VTK reported: {_vtk_reason(catcher.events[0].alert)}", file=path, field="file")
    # Deprecation notices say nothing about the file; any other warning means a doubtful read.
    doubts = [w for w in caught if not issubclass(w.category, (DeprecationWarning, PendingDeprecationWarning,
                                                               FutureWarning))]
    if doubts:
        raise InputError(f"{expected}; reading warned: {_vtk_reason(doubts[0].message)}", file=path, field="file")
    if data is None or data.n_points == 0:
        raise InputError(f"{expected}; VTK read no vertices from it", file=path, field="file")
    return data


def _line_of_first_non_finite(path: Path) -> int | None:
    """1-based line of the first NaN or infinite number in a text mesh file; None for a binary file."""
    text = path.read_bytes()
    if b"\0" in text[:8192]:
        return None
    for number, line in enumerate(text.decode("utf-8", errors="replace").splitlines(), start=1):
        tokens = line.split()
        if not tokens or tokens[0].startswith("#") or tokens[0] == "comment":
            continue
        for token in tokens:
            try:
                value = float(token)
            except ValueError:
                continue
            if not np.isfinite(value):
                return number
    return None


def _surface_triangles(data, path: Path) -> tuple[np.ndarray, np.ndarray, np.ndarray, dict]:
    """Points ``(V, 3)`` float64 and triangles ``(T, 3)`` int64 of the dataset's triangulated surface, each
    triangle's cell ``(T,)`` (of a PolyData: the file's face) and the surface's point arrays by name."""
    import pyvista as pv

    with _quiet_vtk():
        surface = data if isinstance(data, pv.PolyData) else data.extract_surface()
    points = np.asarray(surface.points, dtype=np.float64)
    bad = ~np.all(np.isfinite(points), axis=1)
    if np.any(bad):
        raise InputError(f"expected finite vertex coordinates; {int(bad.sum())} of {bad.size} vertices are NaN or "
                         f"infinite (first: vertex {int(np.argmax(bad)) + 1} in reading order)", file=path,
                         line=_line_of_first_non_finite(path), field="vertices")
    surface = surface.copy(deep=False)
    surface.cell_data["csmlab_cell"] = np.arange(surface.n_cells)
    with _quiet_vtk():
        triangulated = surface.triangulate()
    faces = np.asarray(triangulated.faces, dtype=np.int64)
    within_limit(faces.size // 4, MAX_TRIANGLES, what="triangles", file=path, field="triangles")
    if faces.size == 0:
        raise InputError(f"expected at least one polygon (triangle, quad, …); the file holds {data.n_points} "
                         f"vertices and {data.n_cells} cells, none of them a surface", file=path, field="triangles")
    return (np.asarray(triangulated.points, dtype=np.float64), faces.reshape(-1, 4)[:, 1:],
            np.asarray(triangulated.cell_data["csmlab_cell"], dtype=np.int64),
            # VTK may keep an unnamed array (a name of None): only named ones can be a material's coordinates.
            {name: np.asarray(triangulated.point_data[name]) for name in triangulated.point_data.keys()
             if isinstance(name, str)})


def _check_obj_references(path: Path) -> None:
    """Refuse an OBJ face naming a vertex (``v``) or texture coordinate (``vt``) the file does not hold.

    VTK's reader does not check them: an index past the end reads memory that is not the file's
    (seen by the fuzzer as coordinates of 1e300 one run and none the next). A positive index counts
    from the file's first ``v`` (``vt``), a negative one back from the last before the face (OBJ's
    relative form).
    """
    totals = {"v": 0, "vt": 0}
    lines = _lenient_text(path).splitlines()
    for line in lines:
        words = line.split(maxsplit=1)
        if words and words[0] in totals:
            totals[words[0]] += 1
    seen = {"v": 0, "vt": 0}
    for number, line in enumerate(lines, start=1):
        words = line.split()
        if words and words[0] in seen:
            seen[words[0]] += 1
        if not words or words[0] != "f":
            continue
        for word in words[1:]:
            for kind, reference in zip(("v", "vt"), word.split("/")[:2]):
                if kind == "vt" and reference == "":
                    continue
                try:
                    index = int(reference)
                except ValueError:
                    index = 0
                if not (0 < index <= totals[kind] or -seen[kind] <= index < 0):
                    raise InputError(f"expected {kind} references in [1, {totals[kind]}] (or back from -1 to "
                                     f"-{seen[kind]}), got {word!r}", file=path, line=number, field="f")


@dataclass(frozen=True)
class _ObjMaterials:
    """What an OBJ file's materials say, by material name.

    Attributes
    ----------
    faces : list of str
        The material of every face, in file order (``""`` before the first ``usemtl``).
    maps : dict of str to Path
        Each material's ``map_d`` image.
    diffuse : dict of str to ndarray
        Each material's ``Kd`` ``(3,)``, linear RGB in [0, 1].
    colour_maps : dict of str to Path
        Each material's ``map_Kd`` image.
    """

    faces: list
    maps: dict
    diffuse: dict
    colour_maps: dict


def _obj_materials(path: Path) -> _ObjMaterials:
    """The material of every face of an OBJ file and the ``map_d``, ``Kd`` and ``map_Kd`` of its materials.

    ``mtllib`` files are read relative to the OBJ file, their images relative to the ``.mtl`` file
    (the last word of the line: options before it are not read). A missing ``.mtl`` leaves its
    materials without maps or colours, as viewers draw them.

    Raises
    ------
    InputError
        On a ``Kd`` that is not one or three numbers in [0, 1], naming the ``.mtl`` file and line.
    """
    faces, maps, diffuse, colour_maps, current = [], {}, {}, {}, ""
    for line in _lenient_text(path).splitlines():
        words = line.split()
        if not words:
            continue
        if words[0] == "usemtl":
            current = " ".join(words[1:])
        elif words[0] == "f":
            faces.append(current)
        elif words[0] == "mtllib":
            for name in words[1:]:
                library = path.parent / name
                if not is_file(library):
                    continue
                material = ""
                for number, entry in enumerate(_lenient_text(library).splitlines(), start=1):
                    parts = entry.split()
                    if parts and parts[0] == "newmtl":
                        material = " ".join(parts[1:])
                    elif parts and parts[0] == "map_d" and len(parts) > 1:
                        maps[material] = library.parent / parts[-1]
                    elif parts and parts[0] == "map_Kd" and len(parts) > 1:
                        colour_maps[material] = library.parent / parts[-1]
                    elif parts and parts[0] == "Kd":
                        diffuse[material] = _diffuse(parts[1:], library, number)
    return _ObjMaterials(faces, maps, diffuse, colour_maps)


def _diffuse(words: list[str], library: Path, number: int) -> np.ndarray:
    """``Kd r [g b]`` as linear RGB ``(3,)`` (one number: grey, as the MTL format defines)."""
    try:
        values = np.array([float(w) for w in words], dtype=np.float64)
    except ValueError:
        values = np.array([np.nan])
    if values.size not in (1, 3) or not np.all((values >= 0.0) & (values <= 1.0)):
        raise InputError(f"expected Kd as one or three numbers in [0, 1] (linear RGB), got {' '.join(words)!r}",
                         file=library, line=number, field="Kd")
    return np.broadcast_to(values, (3,)).copy()


def _lenient_text(path: Path) -> str:
    """The text of an OBJ or MTL file, undecodable bytes replaced (names in them only have to match each other)."""
    try:
        return path.read_bytes().decode("utf-8", errors="replace")
    except OSError as exc:
        raise InputError(f"expected a readable file, got {exc.strerror or exc}", file=path) from None


def _obj_masks(materials: _ObjMaterials, cell_count: int, path: Path, points: np.ndarray, triangles: np.ndarray,
               cells: np.ndarray, point_arrays: dict):
    """Vertices, triangles and ``uv, vertex_mask, alpha`` of an OBJ mesh with ``map_d`` materials; None if it has none.

    Each masked triangle's corners become vertices of their own (appended after ``points``), so a
    vertex a masked face shares with another face keeps one mask.
    """
    faces, maps = materials.faces, materials.maps
    used = sorted({name for name in faces if name in maps})
    if not used:
        return None
    if len(faces) != cell_count:
        raise InputError(f"expected one cell per face line to match materials to faces, VTK read {cell_count} "
                         f"cells for {len(faces)} faces", file=path, field="usemtl")
    masks = tuple(read_alpha_mask(maps[name], field="map_d") for name in used)
    face_mask = np.array([used.index(name) if name in maps else -1 for name in faces], dtype=np.int32)
    mask = face_mask[cells]
    masked = np.flatnonzero(mask >= 0)
    uv = np.zeros((points.shape[0] + 3 * masked.size, 2))
    vertex_mask = np.full(uv.shape[0], -1, dtype=np.int32)
    out = triangles.copy()
    for k, name in enumerate(used):
        rows = masked[mask[masked] == k]
        if name not in point_arrays:
            raise InputError(f"expected texture coordinates (vt) on the faces of material {name!r}, which has a map_d",
                             file=path, field="vt")
        coordinates = np.asarray(point_arrays[name], dtype=np.float64)
        if not np.all(np.isfinite(coordinates[np.unique(triangles[rows])])):
            raise InputError(f"expected finite texture coordinates (vt) on the faces of material {name!r}, found NaN "
                             f"or infinity", file=path, line=_line_of_first_non_finite(path), field="vt")
        slots = points.shape[0] + 3 * np.searchsorted(masked, rows)[:, None] + np.arange(3)
        corner = triangles[rows]
        uv[slots] = np.stack([coordinates[corner, 0], 1.0 - coordinates[corner, 1]], axis=-1)
        vertex_mask[slots] = k
        out[rows] = slots
    vertices = np.concatenate([points, points[triangles[masked]].reshape(-1, 3)])
    return vertices, out, dict(uv=uv, vertex_mask=vertex_mask, alpha=masks)


def _ground_under(scene: Scene) -> Scene:
    """A square plane at the scene's lowest ``y``, centred under it, :data:`GROUND_SIZE_FACTOR` times its size."""
    lo, hi = scene.bounds
    half = GROUND_SIZE_FACTOR * float(np.max(hi - lo)) / 2.0
    cx, cz = (lo[0] + hi[0]) / 2.0, (lo[2] + hi[2]) / 2.0
    plane = height_field([cx - half, cx + half], [cz - half, cz + half], np.full((2, 2), lo[1]), albedo=GROUND_ALBEDO)
    return scene_from_parts([plane], name="ground")


def load_mesh(file, *, scale: float = 1.0, up: str = "y", ground: bool = False, albedo=(0.6, 0.6, 0.6),
              blend_casters: str = "opaque") -> Scene:
    """Read a mesh file (OBJ, PLY, STL, VTK, glTF) into a Scene in csmlab's world: metres, Y up.

    Parameters
    ----------
    file : str or os.PathLike
        A file whose suffix is a key of :data:`MESH_FORMATS`.
    scale : float
        Metres per file unit (0.001 for a file in millimetres), > 0. Applied first.
    up : {"y", "z"}
        The file's up axis; a Z-up file is turned to Y-up by :data:`UP_AXES` (``(x, y, z) →
        (x, z, −y)``). The mesh is not moved: the file's origin stays the world origin.
    ground : bool
        Add a square ground plane (two triangles, facing +Y, albedo :data:`GROUND_ALBEDO`) at the
        mesh's lowest point, centred under it, :data:`GROUND_SIZE_FACTOR` times its largest
        bounding-box side, so a lone object casts a visible shadow. Its triangles come last.
    albedo : (float, float, float)
        Linear RGB in [0, 1] for every triangle of the mesh (file colours are not read).
    blend_casters : {"opaque", "masked"}
        glTF: ``alphaMode = "BLEND"`` materials read solid or alpha-tested; their masks are kept
        as ``vertex_blend`` either way (:func:`csmlab.scene.gltf_materials.blend_rule_masks`).

    Returns
    -------
    Scene
        Named after the file; vertices in metres; zero-area triangles dropped.

    Raises
    ------
    InputError
        Naming the file and the field: ``file`` (missing, not a file, unknown suffix, unreadable
        by VTK or as glTF, no vertices), a glTF key (a broken accessor, node or reference),
        ``triangles`` (no polygon, or only zero-area ones), ``vertices``
        (NaN or infinite coordinates).
    ValueError
        On a bad ``scale``, ``up`` or ``albedo``, naming the keyword.

    Examples
    --------
    >>> box = load_mesh("cornell_box.obj", scale=0.001)  # doctest: +SKIP
    """
    path = Path(file)
    scale_value = float(scale) if isinstance(scale, (int, float)) and not isinstance(scale, bool) else float("nan")
    if not np.isfinite(scale_value) or scale_value <= 0.0:
        raise ValueError(f"scale: expected a finite number > 0 (metres per file unit), got {scale!r}")
    check_name(up, UP_AXES, field="up")
    check_name(blend_casters, BLEND_CASTERS, field="blend_casters")
    colour = np.asarray(albedo, dtype=np.float64)
    if colour.shape != (3,) or not np.all((colour >= 0.0) & (colour <= 1.0)):
        raise ValueError(f"albedo: expected three linear RGB values in [0, 1], got {albedo!r}")
    if not path.is_file():
        raise InputError("expected an existing mesh file, found " + ("a directory" if path.is_dir() else "nothing"),
                         file=path, field="file")
    fmt = MESH_FORMATS.get(path.suffix.lower())
    if fmt is None:
        raise InputError(f"expected a mesh file ending in one of {', '.join(MESH_FORMATS)}, "
                         f"got {path.suffix or 'no suffix'!r}", file=path, field="file")
    if path.suffix.lower() in GLTF_SUFFIXES:
        gltf = read_gltf(path)
        blended = read_blended_masked(gltf.document)
        points, triangles, masks = gltf_scene_triangles(gltf)
        masks = blend_rule_masks(masks, masks.pop("mask_materials", []), blended, blend_casters)
    else:
        points, triangles, masks = _vtk_mesh(path, fmt)
    with np.errstate(over="ignore", invalid="ignore"):  # a coordinate scaled past float64: refused below
        points = (points * scale_value) @ UP_AXES[up].T
    far = ~np.all(np.abs(points) <= MAX_COORDINATE, axis=1)
    if np.any(far):
        at = int(np.argmax(far))
        raise InputError(f"expected vertices within {MAX_COORDINATE:g} m of the origin (docs/design.md, \"Inputs\"), "
                         f"vertex {at + 1} in reading order lies at {np.abs(points[at]).max():.3g} m", file=path,
                         field="vertices")
    base_colour = masks.pop("base_colour", None)
    textures = masks.pop("colour", None)
    if base_colour is not None:  # a material's base colour; `albedo` where a face has none
        colour = np.where(np.isnan(base_colour), colour, base_colour)
    try:
        scene = Scene.from_triangles(points, triangles, albedo=colour, name=path.name)
    except ValueError as exc:
        raise InputError(f"expected at least one triangle of non-zero area, all {triangles.shape[0]} are degenerate",
                         file=path, field="triangles") from exc
    if masks or textures is not None:
        scene = Scene(scene.vertices, scene.triangles, scene.normals, scene.albedo, name=scene.name, colour=textures,
                      **masks)
    return scene.merged(_ground_under(scene)) if ground else scene


def _vtk_mesh(path: Path, fmt: str) -> tuple[np.ndarray, np.ndarray, dict]:
    """Points, triangles and (an OBJ's ``map_d``) masks of a mesh file read through VTK."""
    if fmt == MESH_FORMATS[".obj"]:
        _check_obj_references(path)
    data = _read_dataset(path, fmt)
    points, triangles, cells, point_arrays = _surface_triangles(data, path)
    masks = {}
    if fmt == MESH_FORMATS[".obj"]:
        materials = _obj_materials(path)
        colour = _obj_colours(materials, data.n_cells, path, triangles, cells, point_arrays)
        found = _obj_masks(materials, data.n_cells, path, points, triangles, cells, point_arrays)
        if found is not None:
            points, triangles, masks = found
        if colour is not None:
            points, triangles, masks = _with_colour(points, triangles, masks, colour)
    return points, triangles, masks


@dataclass(frozen=True)
class _ObjColours:
    """An OBJ mesh's base colours: ``Kd`` per triangle and its ``map_Kd`` textures.

    Attributes
    ----------
    base_colour : ndarray, shape (T, 3), float64
        ``Kd`` of each triangle's material; NaN where it has none (the ``albedo`` given).
    rows : ndarray, shape (R,), int64
        The triangles with a ``map_Kd``.
    uv : ndarray, shape (R, 3, 2), float64
        Their corners' texture coordinates, v running down the image.
    texture : ndarray, shape (R,), int32
        Index of each one's texture in ``textures``.
    textures : tuple of ColourTexture
    """

    base_colour: np.ndarray
    rows: np.ndarray
    uv: np.ndarray
    texture: np.ndarray
    textures: tuple


def _obj_colours(materials: _ObjMaterials, cell_count: int, path: Path, triangles: np.ndarray, cells: np.ndarray,
                 point_arrays: dict) -> _ObjColours | None:
    """The ``Kd`` and ``map_Kd`` of an OBJ mesh's triangles; None when no face's material has either."""
    faces = materials.faces
    coloured = {name for name in faces if name in materials.diffuse or name in materials.colour_maps}
    if not coloured:
        return None
    if len(faces) != cell_count:
        raise InputError(f"expected one cell per face line to match materials to faces, VTK read {cell_count} "
                         f"cells for {len(faces)} faces", file=path, field="usemtl")
    names = sorted(set(faces))
    face_material = np.array([names.index(name) for name in faces], dtype=np.int64)[cells]
    table = np.array([materials.diffuse.get(name, np.full(3, np.nan)) for name in names])
    textured = sorted(name for name in coloured if name in materials.colour_maps)
    textures = tuple(read_colour_texture(materials.colour_maps[name], field="map_Kd") for name in textured)
    rows, uv, texture = [], [], []
    for k, name in enumerate(textured):
        picked = np.flatnonzero(face_material == names.index(name))
        if name not in point_arrays:
            raise InputError(f"expected texture coordinates (vt) on the faces of material {name!r}, which has a "
                             f"map_Kd", file=path, field="vt")
        coordinates = np.asarray(point_arrays[name], dtype=np.float64)[triangles[picked]]
        if not np.all(np.isfinite(coordinates)):
            raise InputError(f"expected finite texture coordinates (vt) on the faces of material {name!r}, found NaN "
                             f"or infinity", file=path, line=_line_of_first_non_finite(path), field="vt")
        rows.append(picked)
        uv.append(np.stack([coordinates[..., 0], 1.0 - coordinates[..., 1]], axis=-1))
        texture.append(np.full(picked.size, k, np.int32))
    return _ObjColours(table[face_material], np.concatenate(rows) if rows else np.zeros(0, np.int64),
                       np.concatenate(uv) if uv else np.zeros((0, 3, 2)),
                       np.concatenate(texture) if texture else np.zeros(0, np.int32), textures)


def _with_colour(points: np.ndarray, triangles: np.ndarray, masks: dict,
                 colour: _ObjColours) -> tuple[np.ndarray, np.ndarray, dict]:
    """``points``, ``triangles`` and ``masks`` with the colours of :func:`_obj_colours` as ``base_colour`` and
    ``colour`` (each textured triangle's corners become vertices of their own, their masks copied)."""
    out = triangles.copy()
    extra = {"base_colour": colour.base_colour}
    if not colour.textures:
        return points, out, {**masks, **extra}
    corners = triangles[colour.rows].reshape(-1)
    slots = (points.shape[0] + np.arange(corners.size)).reshape(-1, 3)
    out[colour.rows] = slots
    vertex_texture = np.full(points.shape[0] + corners.size, -1, np.int32)
    vertex_texture[slots] = colour.texture[:, None]
    uv = np.zeros((vertex_texture.size, 2))
    uv[slots] = colour.uv
    if masks:
        masks = dict(masks, uv=np.concatenate([masks["uv"], masks["uv"][corners]]),
                     vertex_mask=np.concatenate([masks["vertex_mask"], masks["vertex_mask"][corners]]))
    extra["colour"] = ColourTextures(uv, vertex_texture, colour.textures)
    return np.concatenate([points, points[corners]]), out, {**masks, **extra}
