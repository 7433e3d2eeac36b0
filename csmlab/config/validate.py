"""Reading the merged document into records: types, ranges, names, files — every check, before any work.

Everything a user can get wrong is checked here and reported as one
:class:`~csmlab.errors.InputError` naming the file the value came from (preset or experiment), the
line where it is written when it can be found, the field, and what was expected.
"""

from __future__ import annotations

import difflib
import functools
import itertools
import math
import os
import re
import typing
from dataclasses import fields
from pathlib import Path

from csmlab.config.locate import _Located
from csmlab.config.presets import _METHOD_NAME, CONFIGS_DIR, _merged, _read_toml
from csmlab.config.records import (_TOP_FIELDS, CameraConfig, Experiment, LightConfig, Method, ReportConfig, TaaConfig,
                                   SceneConfig, ScenePart, TuneConfig, _positive, _record_fields, sweep_points)
from csmlab.config.toml_writer import _toml_value
from csmlab.errors import InputError
from csmlab.registry import close_match_hint, parameters, unknown_name_message
from csmlab.settings import APPLIES, ShadowSettings


_SIZE_UNITS = {"": 1, "b": 1, "kb": 10**3, "mb": 10**6, "gb": 10**9, "kib": 2**10, "mib": 2**20, "gib": 2**30}


def parse_size(text) -> int:
    """Bytes from ``64MiB``, ``16MB``, ``1.5GiB`` or a plain number of bytes (int or digits).

    Raises
    ------
    ValueError
        Saying what was expected.
    """
    if isinstance(text, int) and not isinstance(text, bool) and text > 0:
        return text
    match = re.fullmatch(r"\s*([0-9]+(?:\.[0-9]*)?)\s*([A-Za-z]*)\s*", text) if isinstance(text, str) else None
    unit = match.group(2).lower() if match else None
    if unit not in _SIZE_UNITS or float(match.group(1)) <= 0:
        raise ValueError(f"expected a positive size such as 64MiB, 16MB or 16777216 (bytes), got {text!r}")
    return int(round(float(match.group(1)) * _SIZE_UNITS[unit]))


# --- typed fields ---------------------------------------------------------------------------------


def _type_name(kind) -> str:
    if kind is bool:
        return "true or false"
    if kind is int:
        return "an integer"
    if kind is float:
        return "a number"
    if kind is str:
        return "a string"
    if kind is dict:
        return "a table"
    origin = typing.get_origin(kind)
    args = typing.get_args(kind)
    if origin is tuple and len(args) == 2 and args[1] is Ellipsis:
        return f"a list of {_type_name(args[0]).removeprefix('a ').removeprefix('an ')}s"
    if origin is tuple and all(typing.get_origin(a) is tuple for a in args):
        return f"a list of {len(args)} {_type_name(args[0]).replace('a list', 'lists', 1)}"
    if origin is tuple:
        return f"a list of {len(args)} numbers"
    if type(None) in args:
        return _type_name(next(a for a in args if a is not type(None)))
    return str(kind)


def _coerce(value, kind):
    """``value`` as ``kind`` (int, float, str, bool, dict, tuples, ``X | None``); raise TypeError if it is not."""
    args = typing.get_args(kind)
    origin = typing.get_origin(kind)
    if type(None) in args:
        return _coerce(value, next(a for a in args if a is not type(None)))
    if kind is bool:
        ok = isinstance(value, bool)
    elif kind is int:
        ok = isinstance(value, int) and not isinstance(value, bool)
    elif kind is float:
        ok = isinstance(value, (int, float)) and not isinstance(value, bool)
        value = float(value) if ok else value
    elif kind in (str, dict):
        ok = isinstance(value, kind)
    elif origin is tuple:
        items = args[:1] * len(value) if len(args) == 2 and args[1] is Ellipsis and isinstance(value, list) else args
        ok = isinstance(value, list) and len(value) == len(items)
        if ok:
            return tuple(_coerce(v, k) for v, k in zip(value, items))
    else:
        raise TypeError(kind)
    if not ok:
        raise TypeError(kind)
    return value


def _typed_value(value, kind, check, *, where: str, located: _Located):
    try:
        out = _coerce(value, kind)
    except TypeError:
        raise located.error(where, f"expected {_type_name(kind)}, got {value!r}") from None
    if check is not None and out is not None:
        predicate, text = check
        values = out if isinstance(out, tuple) else (out,)
        if isinstance(out, float) and not math.isfinite(out) or not all(predicate(v) for v in values):
            raise located.error(where, f"expected {text}, got {value!r}")
    if isinstance(out, tuple) and any(isinstance(v, float) and not math.isfinite(v) for v in out):
        raise located.error(where, f"expected finite numbers, got {value!r}")
    if isinstance(out, float) and not math.isfinite(out):
        raise located.error(where, f"expected a finite number, got {value!r}")
    return out


def _unknown(where: str, key: str, known, located: _Located) -> InputError:
    close = difflib.get_close_matches(key, list(known), n=1)
    hint = f"did you mean {close[0]!r}? " if close else ""
    return located.error(f"{where}.{key}" if where else key,
                         f"unknown field {key!r}: {hint}expected one of {sorted(known)}")


def _record(cls, table, *, where: str, located: _Located, extra=()):
    """An instance of the dataclass ``cls`` from a TOML table; keys in ``extra`` go to its ``params``."""
    if not isinstance(table, dict):
        raise located.error(where, f"expected a table [{where}], got {table!r}")
    hints = typing.get_type_hints(cls)
    own = {f.name: f for f in fields(cls) if f.name != "params"}
    values, params = {}, {}
    for key, value in table.items():
        if key in own:
            values[key] = _typed_value(value, hints[key], None, where=f"{where}.{key}", located=located)
        elif key in extra:
            params[key] = value
        else:
            raise _unknown(where, key, [*own, *extra], located)
    if params:
        values["params"] = params
    return _validated(cls(**values), where_of=lambda name: f"{where}.{name}", located=located)


def _validated(record, *, where_of, located: _Located):
    """``record.validated()``, its ``ValueError("<field>: …")`` raised as an :class:`InputError` at ``where_of(field)``.

    The one range check of every record: config records declare theirs in field metadata,
    :class:`~csmlab.settings.ShadowSettings` in its own ``validated``.
    """
    try:
        return record.validated()
    except ValueError as exc:
        name, _, message = str(exc).partition(": ")
        raise located.error(where_of(name), message) from None


def _registry_name(value: str, registry, *, where: str, located: _Located) -> None:
    if value not in registry:
        raise located.error(where, unknown_name_message(value, registry))


def _existing_file(value: str, *, where: str, located: _Located) -> str:
    base = located.file_of(where).parent
    path = (base / value).resolve()
    if not path.is_file():
        raise located.error(where, f"expected an existing file, got {value!r} (looked for {path})")
    if not os.access(path, os.R_OK):
        raise located.error(where, f"expected a readable file, got {value!r} (permission denied: {path})")
    return str(path)


# --- sections ----------------------------------------------------------------------------------------


def _scene(table, located: _Located) -> SceneConfig:
    from csmlab.scene import SCENE_KINDS

    kind = table.get("kind", SceneConfig.kind) if isinstance(table, dict) else None
    if isinstance(kind, str):
        _registry_name(kind, SCENE_KINDS, where="scene.kind", located=located)
    generator = SCENE_KINDS.get(kind) if isinstance(kind, str) and kind != "mesh" else None
    accepted = parameters(generator) if generator is not None else ()
    common = {"kind", "seed", "file", "scale", "up", "ground", "offset", "parts", "blend_casters"}
    extra = [p for p in accepted if p not in common]
    parts = table.get("parts", []) if isinstance(table, dict) else []
    scene = _record(SceneConfig, {k: v for k, v in table.items() if k != "parts"} if isinstance(table, dict) else table,
                    where="scene", located=located, extra=extra)
    if scene.kind != "mesh":
        for key in ("file", "scale", "up", "ground", "parts", "blend_casters"):
            if key in table:
                raise located.error(f"scene.{key}",
                                    f"expected {key} only with kind = \"mesh\", got kind = {scene.kind!r}")
        return scene
    placed = _scene_parts(parts, located)
    if not scene.file and not placed:
        raise located.error("scene.file", "expected a mesh file (or [[scene.parts]]) with kind = \"mesh\", got none")
    from csmlab.scene.mesh import UP_AXES

    _registry_name(scene.up, UP_AXES, where="scene.up", located=located)
    file = _existing_file(scene.file, where="scene.file", located=located) if scene.file else ""
    return SceneConfig(**{**_record_fields(scene), "file": file, "parts": placed})


def _scene_parts(parts, located: _Located) -> tuple[ScenePart, ...]:
    """``[[scene.parts]]``: each a :class:`ScenePart` with its file made absolute and checked."""
    if not isinstance(parts, list) or not all(isinstance(p, dict) for p in parts):
        raise located.error("scene.parts", f"expected [[scene.parts]] tables (file, translation, rotation_deg, "
                                           f"scale or matrix), got {parts!r}")
    out = []
    for i, table in enumerate(parts):
        where = f"scene.parts[{i}]"
        both = [key for key in ("translation", "rotation_deg", "scale") if key in table]
        if "matrix" in table and both:
            raise located.error(f"{where}.matrix", f"expected either matrix or translation, rotation_deg and scale, "
                                                   f"got matrix and {', '.join(both)}")
        part = _record(ScenePart, table, where=where, located=located)
        if not part.file:
            raise located.error(f"{where}.file", "expected the part's mesh file, got none")
        out.append(ScenePart(**{**_record_fields(part),
                                "file": _existing_file(part.file, where=f"{where}.file", located=located)}))
    return tuple(out)


def _camera(table, located: _Located) -> CameraConfig:
    from csmlab.paths import CONVENTIONS, PATH_FORMATS, PATH_GENERATORS
    from csmlab.paths.formats import ANCHORS
    from csmlab.paths.timing import DUPLICATE_RULES, GAP_RULES

    name = table.get("path") if isinstance(table, dict) else None
    if isinstance(name, str) and name:
        _registry_name(name, PATH_GENERATORS, where="camera.path", located=located)
    generator = PATH_GENERATORS.get(name) if isinstance(name, str) else None
    accepted = parameters(generator) if generator is not None else ()
    common = {f.name for f in fields(CameraConfig)} | {"aspect", "light_direction", "name"}
    extra = [p for p in accepted if p not in common]
    camera = _record(CameraConfig, table, where="camera", located=located, extra=extra)
    if camera.far <= camera.near:
        raise located.error("camera.far", f"expected a distance greater than near ({camera.near}), got {camera.far}")
    file_only = ("format", "convention", "scale", "offset", "time_offset", "start_s", "end_s", "times_file", "anchor",
                 "duplicate_times", "max_gap", "gaps", "camera")
    if camera.path and camera.file:
        raise located.error("camera.file", f"expected either path (a generator) or file, got both: path = "
                                           f"{camera.path!r} (from {located.file_of('camera.path')}) and file")
    if not camera.path and not camera.file:
        raise located.error("camera.path",
                            f"expected a path generator {sorted(PATH_GENERATORS)} or a file, got neither")
    if camera.path:
        for key in file_only:
            if key in table:
                raise located.error(f"camera.{key}", f"expected {key} only with a recorded file, got path = "
                                                     f"{camera.path!r}")
        for key, owner in (("orbit_height", "orbit"), ("flight_height", "flyover")):
            if key in table and camera.path != owner:
                raise located.error(f"camera.{key}", f"expected {key} only with path = {owner!r}, got path = "
                                                     f"{camera.path!r}")
        return camera
    for key in ("fit_level", "orbit_height", "flight_height"):
        if key in table:
            raise located.error(f"camera.{key}", f"expected {key} only with a path generator (path = ...), got "
                                                 f"file = {camera.file!r}")
    if camera.params:
        key = next(iter(camera.params))
        raise _unknown("camera", key, [f.name for f in fields(CameraConfig) if f.name != "params"], located)
    if camera.format:
        _registry_name(camera.format, PATH_FORMATS, where="camera.format", located=located)
    if camera.convention:
        _registry_name(camera.convention, CONVENTIONS, where="camera.convention", located=located)
    is_gltf = camera.format == "gltf" or (not camera.format and Path(camera.file).suffix.lower() in (".gltf", ".glb"))
    if camera.camera and not is_gltf:
        raise located.error("camera.camera", f"expected camera only with a glTF file (format gltf), got file = "
                                             f"{camera.file!r}, format = {camera.format!r}")
    for key, choices in (("anchor", ANCHORS), ("duplicate_times", DUPLICATE_RULES), ("gaps", GAP_RULES)):
        _registry_name(getattr(camera, key), choices, where=f"camera.{key}", located=located)
    if camera.start_s is not None and camera.end_s is not None and camera.end_s < camera.start_s:
        raise located.error("camera.end_s",
                            f"expected a time not before start_s ({camera.start_s}), got {camera.end_s}")
    files = {"file": _existing_file(camera.file, where="camera.file", located=located)}
    if camera.times_file:
        files["times_file"] = _existing_file(camera.times_file, where="camera.times_file", located=located)
    return CameraConfig(**{**_record_fields(camera), **files})


def _light(table, located: _Located) -> LightConfig:
    light = _record(LightConfig, table, where="light", located=located)
    angles = [k for k in ("elevation_deg", "azimuth_deg", "elevation_end_deg", "azimuth_end_deg") if k in table]
    if light.from_scene:
        given = [k for k in ("direction", *angles) if k in table]
        if given:
            raise located.error(f"light.{given[0]}", "expected either from_scene = true or a direction or angles, "
                                                     "got both")
        return light
    if light.direction is not None:
        if angles:
            raise located.error(f"light.{angles[0]}", "expected either direction or elevation/azimuth angles, got both")
        if math.hypot(*light.direction) < 1e-12:
            raise located.error("light.direction", f"expected a non-zero vector from the light toward the scene, "
                                                   f"got {list(light.direction)}")
        return light
    elevation = 40.0 if light.elevation_deg is None else light.elevation_deg
    azimuth = 30.0 if light.azimuth_deg is None else light.azimuth_deg
    return LightConfig(elevation_deg=elevation, azimuth_deg=azimuth, elevation_end_deg=light.elevation_end_deg,
                       azimuth_end_deg=light.azimuth_end_deg)


@functools.cache
def _shadow_types() -> dict:
    """Type of every ShadowSettings field by its TOML name."""
    return {("lambda" if k == "lambda_" else k): v for k, v in typing.get_type_hints(ShadowSettings).items()}


def _shadow_fields(table, *, where: str, located: _Located, allow=("name",)) -> dict:
    """``[shadow]``-field overrides of a table, typed; keys in ``allow`` are skipped."""
    if not isinstance(table, dict):
        raise located.error(where, f"expected a table, got {table!r}")
    types = _shadow_types()
    out = {}
    for key, value in table.items():
        if key in allow:
            continue
        if key not in types:
            raise _unknown(where, key, [*types, *allow], located)
        if key == "shadow_distance":
            out.update(_shadow_distance(value, given_from="shadow_distance_from" in table, where=f"{where}.{key}",
                                        located=located))
            continue
        out[key] = _typed_value(value, types[key], None, where=f"{where}.{key}", located=located)
    return out


def _shadow_distance(value, *, given_from: bool, where: str, located: _Located) -> dict:
    """The fields ``shadow_distance = value`` sets: a string names ``shadow_distance_from`` (``"camera_far"``,
    ``"farthest_visible"``); a number is metres, and ``fixed`` unless the same table writes
    ``shadow_distance_from`` itself (a resolved document writes both)."""
    from csmlab.cascades.bounds import SHADOW_DISTANCE_METHODS

    if isinstance(value, str):
        names = [name for name in SHADOW_DISTANCE_METHODS if name != "fixed"]
        if value not in names:
            raise located.error(where, f"expected a distance in metres or one of {names}, got {value!r}"
                                       f"{close_match_hint(value, names)}")
        return {"shadow_distance_from": value}
    metres = _typed_value(value, float, None, where=where, located=located)
    return {"shadow_distance": metres} if given_from else {"shadow_distance": metres, "shadow_distance_from": "fixed"}


def shadow_method_registries() -> dict:
    """The registry of every ``[shadow]`` field that names a method, by field (``csmlab list`` prints them)."""
    from csmlab.cascades import (BOUNDS_METHODS, DEPTH_RANGE_METHODS, EXTENT_METHODS, FIT_METHODS, SNAP_METHODS,
                                 SPLIT_METHODS, STABILIZATION_METHODS)
    from csmlab.lookup_choices import FILTER_METHODS, OUTSIDE_METHODS, SELECTION_METHODS
    from csmlab.cascades.bounds import HOLD_METHODS, SHADOW_DISTANCE_METHODS
    from csmlab.cascades.fit import BLEND_CURVES, TRANSITION_METHODS
    from csmlab.culling import CULL_METHODS
    from csmlab.fades import FADE_METHODS
    from csmlab.geometry import LIGHT_BASIS_METHODS
    from csmlab.storage import DEPTH_QUANTIZATION_METHODS
    from csmlab.texels import PRECISION_METHODS, VERTEX_SNAPS
    from csmlab.cascades.focus import FOCUS_METHODS
    from csmlab.cascades.warp import WARP_METHODS
    from csmlab.shadow_policies import SUN_POLICIES, ZOOM_POLICIES

    return {"split": SPLIT_METHODS, "fit": FIT_METHODS, "stabilization": STABILIZATION_METHODS,
            "selection": SELECTION_METHODS, "filter": FILTER_METHODS, "extent": EXTENT_METHODS, "snap": SNAP_METHODS,
            "depth_range": DEPTH_RANGE_METHODS, "bounds": BOUNDS_METHODS, "engine_precision": PRECISION_METHODS,
            "transition": TRANSITION_METHODS, "hold": HOLD_METHODS, "blend_curve": BLEND_CURVES, "fade": FADE_METHODS,
            "cull": CULL_METHODS, "focus": FOCUS_METHODS, "warp": WARP_METHODS, "vertex_snap": VERTEX_SNAPS,
            "light_basis": LIGHT_BASIS_METHODS, "depth_quantization": DEPTH_QUANTIZATION_METHODS,
            "outside": OUTSIDE_METHODS, "shadow_distance_from": SHADOW_DISTANCE_METHODS, "zoom_policy": ZOOM_POLICIES,
            "sun_policy": SUN_POLICIES}


def _checked_settings(settings: ShadowSettings, *, where_of, located: _Located,
                      camera: CameraConfig) -> ShadowSettings:
    """``settings`` after range, method-name and split checks; ``where_of(field)`` says where a field was set."""
    _validated(settings, where_of=where_of, located=located)
    for name, registry in shadow_method_registries().items():
        _registry_name(getattr(settings, name), registry, where=where_of(name), located=located)
    if settings.shadow_distance_from != "fixed" and 0.0 < settings.max_shadow_distance <= camera.near:
        raise located.error(where_of("max_shadow_distance"), f"expected 0 (no cap) or a distance beyond the camera's "
                                                             f"near plane ({camera.near} m), got "
                                                             f"{settings.max_shadow_distance}")
    end = _shadow_end_of(settings, camera)
    if settings.split == "geometric" and settings.cascades > 1 and settings.first_cascade_far >= end:
        raise located.error(where_of("first_cascade_far"), f"expected a distance below shadow_distance "
                                                           f"({end} m), got {settings.first_cascade_far}")
    _split_distances(settings, camera, where_of=where_of, located=located)
    _room_inside_margins(settings, where_of=where_of, located=located)
    return settings


def _shadow_end_of(settings: ShadowSettings, camera: CameraConfig) -> float:
    """Where the last cascade ends under the experiment's camera (its far plane for ``camera_far`` and, before
    any frame is seen, for ``farthest_visible``)."""
    from csmlab.cascades.bounds import shadow_end

    return shadow_end(method=settings.shadow_distance_from, shadow_distance=settings.shadow_distance,
                      max_shadow_distance=settings.max_shadow_distance, camera_far=camera.far)


def _room_inside_margins(settings: ShadowSettings, *, where_of, located: _Located) -> None:
    """Every cascade's resolution leaves texels inside the margins its filter keeps free."""
    from csmlab.cascades.stabilize import check_resolution

    for resolution in settings.cascade_resolutions or (settings.resolution,):
        try:
            check_resolution(resolution, margin=settings.margin_texels, method=settings.stabilization,
                             snap=settings.snap)
        except ValueError as exc:
            raise located.error(where_of("cascade_resolutions" if settings.cascade_resolutions else "resolution"),
                                f"{str(exc).partition(': ')[2]} (the filter's taps and a texel kept inside each "
                                f"box edge)") from None


def _split_distances(settings: ShadowSettings, camera: CameraConfig, *, where_of, located: _Located) -> None:
    """The splits over the camera's near plane to where the shadow ends, as a frame computes them: manual far
    ends one per cascade and rising, a geometric first far end inside that range, a shadow beyond the near plane;
    neither scheme's fixed ends over the visible range of ``bounds = "sdsm"``."""
    from csmlab.cascades import split_distances

    if settings.split == "manual" and len(settings.splits) != settings.cascades:
        raise located.error(where_of("splits"), f"expected {settings.cascades} split distances (one per cascade) "
                                                f"with split = \"manual\", got {len(settings.splits)}")
    if settings.bounds == "sdsm" and settings.split in ("manual", "geometric"):
        raise located.error(where_of("bounds"), f"expected bounds = \"frustum\" with split = \"{settings.split}\" "
                                                f"(its far ends are fixed, and the visible depth range may begin "
                                                f"beyond them), got \"sdsm\"")
    try:
        split_distances(near=camera.near, far=_shadow_end_of(settings, camera), count=settings.cascades,
                        method=settings.split, lambda_=settings.lambda_, splits=settings.splits,
                        distribution_exponent=settings.distribution_exponent,
                        first_cascade_far=settings.first_cascade_far)
    except ValueError as exc:
        name, _, message = str(exc).partition(": ")
        raise located.error(where_of(name), message) from None


def _by_toml_name(settings: ShadowSettings) -> dict:
    """Every field of ``settings`` by its TOML name."""
    return dict(zip(ShadowSettings.field_names(), (getattr(settings, f.name) for f in fields(settings))))


_DEFAULTS = _by_toml_name(ShadowSettings())


def _refuse_where_it_never_applies(key: str, candidates: list[ShadowSettings], *, where: str, located: _Located,
                                   everywhere: str) -> None:
    """Raise at ``where`` when the field ``key`` takes effect under none of ``candidates`` (:data:`APPLIES`)."""
    rule = APPLIES.get(key)
    if rule is None or any(rule.holds(s) for s in candidates):
        return
    inputs = [rule.inputs(s) for s in candidates]
    got = ", ".join(f"{name} = {' or '.join(dict.fromkeys(_toml_value(i[name]) for i in inputs))}"
                    for name in inputs[0])
    raise located.error(where, f"expected {key} only with {rule.when}, got {got}{everywhere}")


def _written_where_they_apply(base: ShadowSettings, shadow: dict, methods: tuple[Method, ...], sweep,
                              located: _Located) -> None:
    """Refuse a written field that changes nothing (:data:`~csmlab.settings.APPLIES`; presets count as written).

    A method's own field must apply to that method at some sweep point; a ``[shadow]`` or ``[sweep]``
    field to some method at some point. A field written at its default value says nothing and passes
    (the resolved document, which writes every field, loads back).
    """
    points = [point for _, point in sweep_points(sweep)]
    variants = {m.name: [m.settings.replace(**point) for point in points] for m in methods}
    every = [s for candidates in variants.values() for s in candidates]
    scope = " in every method" + (" and sweep point" if sweep else "")
    for m in methods:
        for key, value in m.overrides.items():
            if value != _DEFAULTS[key]:
                _refuse_where_it_never_applies(key, variants[m.name], where=f"methods.{m.name}.{key}",
                                               located=located, everywhere=" at every sweep point" if sweep else "")
    written = _by_toml_name(base)
    for key in shadow:
        if written[key] != _DEFAULTS[key]:
            _refuse_where_it_never_applies(key, every, where=f"shadow.{key}", located=located, everywhere=scope)
    for key, _ in sweep:
        _refuse_where_it_never_applies(key, every, where=f"sweep.{key}", located=located, everywhere=scope)


def _methods(entries: list, base: ShadowSettings, located: _Located, camera: CameraConfig) -> tuple[Method, ...]:
    if not entries:
        return (Method(name="base", overrides={}, settings=base),)
    out = []
    for entry in entries:
        name = entry["name"]
        overrides = _shadow_fields(entry, where=f"methods.{name}", located=located)
        settings = _checked_settings(
            base.replace(**overrides), located=located, camera=camera,
            where_of=lambda f, o=overrides, n=name: f"methods.{n}.{f}" if f in o else f"shadow.{f}")
        out.append(Method(name=name, overrides=overrides, settings=settings))
    return tuple(out)


def _sweep(table, methods: tuple[Method, ...], located: _Located,
           camera: CameraConfig) -> tuple[tuple[str, tuple], ...]:
    if not isinstance(table, dict):
        raise located.error("sweep", f"expected a table of shadow fields and their values, got {table!r}")
    out = []
    for key, values in table.items():
        if not isinstance(values, list) or not values:
            raise located.error(f"sweep.{key}", f"expected a non-empty list of values, got {values!r}")
        if key == "shadow_distance" and any(isinstance(v, str) for v in values):
            raise located.error("sweep.shadow_distance", f"expected distances in metres (sweep shadow_distance_from "
                                                         f"for \"camera_far\" or \"farthest_visible\"), got {values!r}")
        typed = [_shadow_fields({key: v}, where="sweep", located=located, allow=())[key] for v in values]
        if len(set(map(repr, typed))) != len(typed):
            raise located.error(f"sweep.{key}", f"expected distinct values, got {values!r}")
        out.append((key, tuple(typed)))
    for m in methods:
        for values in itertools.product(*(v for _, v in out)):
            point = dict(zip((k for k, _ in out), values))
            _checked_settings(m.settings.replace(**point), located=located, camera=camera,
                              where_of=lambda f, p=point, n=m.name: f"sweep.{f}" if f in p else f"methods.{n}.{f}")
    return tuple(out)


def _regress(table, located: _Located) -> dict:
    from csmlab.metric_registry import METRICS, is_metric_column

    if not isinstance(table, dict):
        raise located.error("regress", f"expected a table of metric tolerances, got {table!r}")
    out = {}
    for metric, tolerance in table.items():
        if not is_metric_column(metric):
            raise _unknown("regress", metric, METRICS, located)
        if not isinstance(tolerance, dict):
            raise located.error(f"regress.{metric}", f"expected {{ abs = …, rel = … }}, got {tolerance!r}")
        entry = {}
        for key, value in tolerance.items():
            if key not in ("abs", "rel"):
                raise _unknown(f"regress.{metric}", key, ("abs", "rel"), located)
            entry[key] = _typed_value(value, float, (lambda x: x >= 0, "a non-negative tolerance"),
                                      where=f"regress.{metric}.{key}", located=located)
        out[metric] = entry
    return out


def _tune(table, methods: tuple[Method, ...], located: _Located, camera: CameraConfig) -> TuneConfig:
    """``[tune]``: its options, and every other key a ``[shadow]`` field with choices or a range."""
    from csmlab.metric_registry import metric_columns

    if not isinstance(table, dict):
        raise located.error("tune", f"expected a table of search ranges and options, got {table!r}")
    options = {f.name: f for f in fields(TuneConfig) if f.name != "space"}
    hints = typing.get_type_hints(TuneConfig)
    types = _shadow_types()
    space, values = [], {}
    for key, value in table.items():
        where = f"tune.{key}"
        if key == "memory_budget":
            try:
                values[key] = parse_size(value)
            except ValueError as exc:
                raise located.error(where, str(exc)) from None
        elif key == "max_flicker":
            if isinstance(value, str) and value != "best-preset":
                raise located.error(where, f'expected a non-negative number or "best-preset", got {value!r}')
            values[key] = value if value == "best-preset" else _typed_value(
                value, float, (lambda x: x >= 0, 'a non-negative number or "best-preset"'), where=where,
                located=located)
        elif key in options:
            values[key] = _typed_value(value, hints[key], None, where=where, located=located)
        elif key in types:
            space.append((key, _tune_spec(value, types[key], where=where, located=located)))
        else:
            raise _unknown("tune", key, [*options, *types], located)
    known = metric_columns(8)
    for key in ("objectives", "flicker_metric"):
        for metric in (values.get(key) or ()) if key == "objectives" else [values.get(key, "flicker")]:
            if metric not in known:
                raise located.error(f"tune.{key}", f"expected metrics.csv columns {sorted(known)}, got {metric!r}")
    names = [m.name for m in methods]
    if values.get("method") and values["method"] not in names:
        raise located.error("tune.method", f"expected one of the experiment's methods {names}, got "
                                           f"{values['method']!r}")
    tuned = next(m for m in methods if m.name == (values.get("method") or names[0]))
    # An engine preset's method is checked by csmlab tune, which first sets the fields the engine derives from a
    # candidate (Godot's splits for its cascade count: csmlab.engines' tune spaces, which config does not import).
    engine_preset = (CONFIGS_DIR / "engines" / f"{tuned.name}.toml").is_file()
    for key, spec in [] if engine_preset else space:
        for value in (spec[1] if spec[0] == "choice" else spec[1:3]):
            _checked_settings(tuned.settings.replace(**{key: value}), located=located, camera=camera,
                              where_of=lambda f, k=key: f"tune.{k}" if f == k else f"methods.{tuned.name}.{f}")
    deciding = {name for rule in APPLIES.values() for name in parameters(rule.test)}
    grid = [[(key, value) for value in (spec[1] if spec[0] == "choice" else spec[1:3])]
            for key, spec in space if key in deciding]
    candidates = [tuned.settings.replace(**dict(point)) for point in itertools.product(*grid)]
    for key, _ in space:
        _refuse_where_it_never_applies(key, candidates, where=f"tune.{key}", located=located,
                                       everywhere=f" in every candidate of {tuned.name}")
    return _validated(TuneConfig(space=tuple(space), **values), where_of=lambda name: f"tune.{name}", located=located)


def _tune_spec(value, kind, *, where: str, located: _Located) -> tuple:
    """``("choice", values)`` from a list, ``("range", lo, hi, log, step)`` from ``{ min, max, log, step }``."""
    if isinstance(value, list):
        if not value:
            raise located.error(where, "expected a non-empty list of choices")
        choices = tuple(_typed_value(v, kind, None, where=where, located=located) for v in value)
        if len(set(map(repr, choices))) != len(choices):
            raise located.error(where, f"expected distinct choices, got {value!r}")
        return ("choice", choices)
    if not isinstance(value, dict) or kind not in (int, float):
        what = "a list of choices or { min = …, max = … }" if kind in (int, float) else "a list of choices"
        raise located.error(where, f"expected {what}, got {value!r}")
    for key in value:
        if key not in ("min", "max", "log", "step"):
            raise _unknown(where, key, ("min", "max", "log", "step"), located)
    if "min" not in value or "max" not in value:
        raise located.error(where, f"expected both min and max, got {value!r}")
    lo, hi = (_typed_value(value[k], kind, None, where=f"{where}.{k}", located=located) for k in ("min", "max"))
    log = _typed_value(value.get("log", False), bool, None, where=f"{where}.log", located=located)
    step = (_typed_value(value["step"], kind, (_positive, "a positive step"), where=f"{where}.step", located=located)
            if "step" in value else None)
    if not lo < hi or (log and lo <= 0):
        raise located.error(where, f"expected min < max{' and min > 0 on a log scale' if log else ''}, got "
                                   f"{lo}..{hi}")
    return ("range", lo, hi, log, step)


def load_tolerances(path) -> dict:
    """Regression tolerances from a TOML file: ``metric = { abs = …, rel = … }`` at the top level or
    under ``[regress]``.

    Raises
    ------
    InputError
        Naming the file, the field and what was expected.
    """
    path = Path(path).resolve()
    document = _read_toml(path)
    table = document.get("regress", document) if set(document) <= {"regress"} else document
    origins = {f"regress.{key}": path for key in table}
    return _regress(table, _Located(origins, path))


def load_experiment(path, *, frames: int | None = None, then_extends=()) -> Experiment:
    """Read, merge and validate an experiment file.

    Parameters
    ----------
    path : str or Path
        The experiment TOML file.
    frames : int, optional
        Overrides ``camera.frames`` (the ``--frames`` option).
    then_extends : sequence of path, optional
        Preset files merged after the experiment, in memory, as a file with ``extends = [path, *then_extends]``
        would merge them (:func:`csmlab.tune` reads an engine preset's method on an experiment so).

    Returns
    -------
    Experiment

    Raises
    ------
    InputError
        Malformed TOML, an unknown field (with the closest known name), a wrong type or range, an
        unknown scene, path, format or method name, a missing or unreadable file, a zero-length light
        direction, manual splits that do not rise from the camera's near plane to the shadow distance, a
        ``[shadow]`` field written where it does not apply (:data:`~csmlab.settings.APPLIES`): the
        message names the file, the line where found, the field and what was expected.
    """
    path = Path(path).resolve()
    merged, origins = _merged(path, then_extends=tuple(Path(p).resolve() for p in then_extends))
    located = _Located(origins, path)
    for key in merged:
        if key not in _TOP_FIELDS:
            raise _unknown("", key, _TOP_FIELDS, located)
    name = merged.get("name", path.stem)
    if not isinstance(name, str) or not _METHOD_NAME.match(name):
        raise located.error("name", f"expected a name of letters, digits and _.+-, got {name!r}")
    description = merged.get("description", "")
    if not isinstance(description, str):
        raise located.error("description", f"expected a string, got {description!r}")
    chunk_frames = _typed_value(merged.get("chunk_frames", 10), int, (lambda x: x >= 1, "at least 1 frame"),
                                where="chunk_frames", located=located)
    scene = _scene(merged.get("scene", {}), located)
    camera = _camera(merged.get("camera", {}), located)
    light = _light(merged.get("light", {}), located)
    if light.from_scene and not (scene.kind == "mesh" and Path(scene.file).suffix.lower() in (".gltf", ".glb")):
        raise located.error("light.from_scene", f"expected a glTF scene (kind = \"mesh\", file *.gltf or *.glb) "
                                                f"to take the light from, got kind = {scene.kind!r}"
                                                + (f", file = {scene.file!r}" if scene.file else ""))
    base = ShadowSettings().replace(**_shadow_fields(merged.get("shadow", {}), where="shadow", located=located,
                                                     allow=()))
    base = _checked_settings(base, where_of=lambda f: f"shadow.{f}", located=located, camera=camera)
    methods = _methods(merged["methods"], base, located, camera)
    sweep = _sweep(merged.get("sweep", {}), methods, located, camera)
    _written_where_they_apply(base, merged.get("shadow", {}), methods, sweep, located)
    experiment = Experiment(
        name=name,
        description=description,
        source=str(path),
        extends=tuple(merged.get("extends", ())),
        scene=scene,
        camera=camera,
        light=light,
        shadow=base,
        methods=methods,
        sweep=sweep,
        regress=_regress(merged.get("regress", {}), located),
        report=_record(ReportConfig, merged.get("report", {}), where="report", located=located),
        chunk_frames=chunk_frames,
        tune=_tune(merged.get("tune", {}), methods, located, camera),
        taa=_record(TaaConfig, merged.get("taa", {}), where="taa", located=located),
    )
    return experiment if frames is None else experiment.with_frames(frames)
