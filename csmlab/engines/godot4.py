"""Godot 4: ``project.godot`` and a ``.tscn`` scene holding a ``DirectionalLight3D``, read and written.

Both are Godot ``ConfigFile`` text: ``[section]`` headers (in a scene, ``[node name="…" type="…"]``)
followed by ``key = value`` lines. The light's ``directional_shadow_*``, ``shadow_*`` and
``light_angular_distance`` properties and the project's ``rendering/lights_and_shadows/directional_shadow/``
settings map to csmlab fields; a property the file leaves out keeps Godot's default, which is
``configs/engines/godot4.toml``'s value (Godot writes only changed properties).

Sources: DirectionalLight3D and Light3D class references; ``light_storage.cpp``
``LightStorage::update_light_buffers`` (``shadow_bias / 100 · bias_scale``, ``bias_scale = depth range ·
soft_shadow_scale`` with soft_shadow_scale 2: ``bias_depth_range = shadow_bias · 0.02``; ``shadow_normal_bias``
texels); ``RendererSceneRenderRD::directional_soft_shadow_filter_set_quality`` (Hard … Ultra: 0 to 32 taps at a
quality radius, × ``shadow_blur``: csmlab.lookup_choices.GODOT_SOFT_SHADOW_QUALITIES); ``scene_forward_clustered.glsl``
``light_process`` (``directional_shadow_blend_splits``: csmlab.cascades.fit.GODOT_BLEND_SPLITS);
``RendererSceneCull::get_directional_light_shadow_size`` (2 or 4 splits: half the atlas).

The snippet (export_godot4) names: ``DirectionalLight3D.directional_shadow_mode`` (orthogonal, 2 or 4 splits),
``directional_shadow_max_distance``, ``directional_shadow_split_1..3``, ``directional_shadow_blend_splits``;
project setting ``rendering/lights_and_shadows/directional_shadow/size`` (the atlas).
"""

from __future__ import annotations

import re
from pathlib import Path

from csmlab.cascades.fit import GODOT_BLEND_SPLITS
from csmlab.cascades.splits import count_one_two_or_four, fractions_of_range, split_boundaries
from csmlab.engines.common import (Engine, EngineFiles, Snippet, common_lacking, fixed_preset,
                                   four_digits, hard_filter, largest_resolution, shape_lacking, vogel_is)
from csmlab.engines.reading import Imported, Reading, number, read_text
from csmlab.errors import InputError
from csmlab.lookup_choices import GODOT_SOFT_SHADOW_QUALITIES, godot_soft_shadow_fields
from csmlab.settings import ShadowSettings

__all__ = ["ENGINE", "FIELDS", "GODOT_SOFT_LOW", "PRESET", "config_sections", "export_godot4", "read_godot4",
           "write_godot4"]

PRESET = "godot4"
"""The engine preset holding Godot's defaults."""

FIELDS = frozenset({"cascades", "split", "splits", "shadow_distance", "fade_out", "pancake", "bias_depth_range",
                    "normal_offset", "vogel_taps", "vogel_radius", "vogel_angle", "vogel_scale", "cull", "resolution",
                    "filter", "depth_format", "blend_band", "transition", "blend_curve"})
"""The csmlab fields Godot's files carry."""

GODOT_SOFT_LOW = {"vogel_taps": 4, "vogel_radius": 2.0, "vogel_angle": 2.4, "vogel_scale": "first_split"}
"""Godot 4's Soft Low (soft_shadow_filter_quality = 2) as csmlab's ``pcf_vogel`` fields (configs/engines/godot4.toml)."""
GODOT_SOFT_LOW_LEVEL = 2
"""The project setting's default level, Soft Low (the preset's filter)."""

SHADOW_BIAS_SCALE = 0.02
"""bias_depth_range per unit of Light3D.shadow_bias: / 100 × soft_shadow_scale 2.0 (light_storage.cpp)."""

_MODES = {0: 1, 1: 2, 2: 4}
_PROJECT = "rendering/lights_and_shadows/directional_shadow/"
_HEADER = re.compile(r"^\[(?P<kind>[A-Za-z_]+)(?P<attrs>.*)\]\s*$")
_ATTR = re.compile(r'(\w+)=("(?:[^"\\]|\\.)*"|\S+)')


def _value(text: str):
    """A ConfigFile value: bool, number or string (anything else, e.g. ``Transform3D(…)``, as its text)."""
    text = text.strip()
    if text in ("true", "false"):
        return text == "true"
    if text.startswith('"') and text.endswith('"') and len(text) >= 2:
        return text[1:-1]
    try:
        return int(text)
    except ValueError:
        pass
    try:
        return float(text)
    except ValueError:
        return text


def _open(value: str) -> bool:
    """Whether ``value`` continues on the next line: a string or a bracket still open."""
    unquoted = re.sub(r'"(?:[^"\\]|\\.)*"', "", value)
    return '"' in unquoted or sum(unquoted.count(o) - unquoted.count(c) for o, c in ("()", "[]", "{}")) > 0


def config_sections(path) -> list[tuple[str, dict, dict, int]]:
    """The sections of a Godot ConfigFile: ``(kind, header attributes, {key: value}, header line)`` in file order.

    Lines before the first header form the section of kind ``""``; a value whose brackets are still
    open continues on the next lines.
    """
    sections = [("", {}, {}, 0)]
    lines = read_text(path).splitlines()
    i = 0
    while i < len(lines):
        line = lines[i].strip()
        i += 1
        if not line or line.startswith(";"):
            continue
        header = _HEADER.match(line)
        if header:
            attrs = {k: _value(v) for k, v in _ATTR.findall(header.group("attrs"))}
            sections.append((header.group("kind"), attrs, {}, i))
            continue
        if "=" not in line:
            raise InputError(f"expected key = value or a [section] header, got {line[:60]!r}", file=path, line=i)
        key, value = (part.strip() for part in line.split("=", 1))
        while _open(value) and i < len(lines):
            value += "\n" + lines[i]
            i += 1
        sections[-1][2][key] = _value(value)
    return sections


def _project(path, reading: Reading) -> None:
    sections = config_sections(path)
    if "config_version" not in sections[0][2]:
        raise InputError("expected a Godot project file (config_version at the top), found none", file=path,
                         field="config_version")
    rendering = next((keys for kind, _, keys, _ in sections[1:] if kind == "rendering"), {})
    settings = {f"rendering/{k}": v for k, v in rendering.items() if f"rendering/{k}".startswith(_PROJECT)}
    for key, value in settings.items():
        name = key[len(_PROJECT):]
        if name == "size":
            size = number(value, file=path, key=key, integer=True, minimum=1)
            reading.pending["atlas"] = (size, key)
        elif name == "soft_shadow_filter_quality":
            quality = number(value, file=path, key=key, integer=True, minimum=0)
            if quality not in GODOT_SOFT_SHADOW_QUALITIES:
                raise InputError(f"expected 0 (Hard) to 5 (Soft Ultra), got {quality}", file=path, field=key)
            reading.pending["quality"] = (quality, f"{Path(path).name}: {key} = {value}")
        elif name == "16_bits":
            if not isinstance(value, bool):
                raise InputError(f"expected true or false, got {value!r}", file=path, field=key)
            reading.set("depth_format", "unorm16" if value else "float32", file=path, key=key, raw=str(value).lower())
        else:
            reading.lack(file=path, key=key, value=value, why="no csmlab knob")


def _light(path, reading: Reading) -> None:
    if not read_text(path).lstrip().startswith(("[gd_scene", "[gd_resource")):
        raise InputError("expected a Godot scene ([gd_scene …] on the first line)", file=path, field="gd_scene")
    sections = config_sections(path)
    if len(sections) < 2 or sections[1][0] not in ("gd_scene", "gd_resource"):
        raise InputError("expected a Godot scene ([gd_scene …] on the first line)", file=path, field="gd_scene")
    lights = [(attrs, keys) for kind, attrs, keys, _ in sections if kind == "node"
              and attrs.get("type") == "DirectionalLight3D"]
    if not lights:
        raise InputError("expected a node of type DirectionalLight3D, found none", file=path,
                         field="DirectionalLight3D")
    attrs, keys = next(((a, k) for a, k in lights if k.get("shadow_enabled") is True), lights[0])
    prefix = f"{attrs.get('name', 'DirectionalLight3D')}."
    base = reading.base
    if keys.get("shadow_enabled") is not True:
        reading.lack(file=path, key=prefix + "shadow_enabled", value=keys.get("shadow_enabled", False),
                     why="the light casts no shadow in Godot; csmlab measures its shadows anyway")
    mode_key = "directional_shadow_mode"
    cascades = base.cascades
    if mode_key in keys:
        mode = number(keys[mode_key], file=path, key=prefix + mode_key, integer=True, minimum=0)
        if mode not in _MODES:
            raise InputError(f"expected 0, 1 or 2, got {mode}", file=path, field=prefix + mode_key)
        cascades = _MODES[mode]
        reading.set("cascades", cascades, file=path, key=prefix + mode_key, raw=mode)
    split_keys = [f"directional_shadow_split_{i}" for i in range(1, cascades)]
    if mode_key in keys or any(k in keys for k in split_keys):
        fractions = [number(keys[k], file=path, key=prefix + k, above=0.0) if k in keys else base.splits[i]
                     for i, k in enumerate(split_keys)] + [1.0]
        if any(b <= a for a, b in zip(fractions, fractions[1:])):
            raise InputError(f"expected increasing splits below 1, got {fractions[:-1]}", file=path,
                             field=prefix + "directional_shadow_split_1")
        found = [prefix + k for k in split_keys if k in keys] or [prefix + mode_key]
        raw = fractions[:-1] if any(k in keys for k in split_keys) else keys.get(mode_key)
        reading.set("split", "manual_range", file=path, key=", ".join(found), raw=raw)
        reading.set("splits", tuple(fractions), file=path, key=", ".join(found), raw=raw)
    plain = {"directional_shadow_max_distance": ("shadow_distance", 1.0, 0.0),
             "directional_shadow_pancake_size": ("pancake", 1.0, None),
             "shadow_normal_bias": ("normal_offset", 1.0, None),
             "shadow_bias": ("bias_depth_range", SHADOW_BIAS_SCALE, None)}
    if "shadow_blur" in keys:
        blur = number(keys["shadow_blur"], file=path, key=prefix + "shadow_blur", above=0.0)
        reading.pending["blur"] = (blur, f"{Path(path).name}: {prefix}shadow_blur = {keys['shadow_blur']}")
    for key, (attribute, scale, above) in plain.items():
        if key in keys:
            value = number(keys[key], file=path, key=prefix + key, above=above, minimum=None if above is not None
                           else 0.0)
            reading.set(attribute, value * scale, file=path, key=prefix + key, raw=keys[key])
    if "directional_shadow_fade_start" in keys:
        start = number(keys["directional_shadow_fade_start"], file=path, key=prefix + "directional_shadow_fade_start",
                       minimum=0.0)
        if start > 1.0:
            raise InputError(f"expected a fraction in [0, 1], got {start}", file=path,
                             field=prefix + "directional_shadow_fade_start")
        # Rounded to 12 digits: 1 - 0.8 is 0.19999999999999996 in binary, Godot's fade_start is a float32.
        reading.set("fade_out", round(1.0 - start, 12), file=path, key=prefix + "directional_shadow_fade_start", raw=start)
    if "shadow_reverse_cull_face" in keys:
        reading.set("cull", "front" if keys["shadow_reverse_cull_face"] is True else "back", file=path,
                    key=prefix + "shadow_reverse_cull_face", raw=keys["shadow_reverse_cull_face"])
    if "directional_shadow_blend_splits" in keys:
        blend = keys["directional_shadow_blend_splits"]
        if not isinstance(blend, bool):
            raise InputError(f"expected true or false, got {blend!r}", file=path,
                             field=prefix + "directional_shadow_blend_splits")
        reading.pending["blend"] = (blend, f"{Path(path).name}: {prefix}directional_shadow_blend_splits = "
                                           f"{str(blend).lower()}")
    angular = keys.get("light_angular_distance", 0)
    if angular not in (0, 0.0):
        reading.lack(file=path, key=prefix + "light_angular_distance", value=angular,
                     why="a nonzero angle turns on Godot's PCSS penumbra, not modelled; the Soft Low disk is kept")
    for key in ("shadow_opacity", "shadow_transmittance_bias", "directional_shadow_fade_start.mobile",
                "shadow_caster_mask"):
        if key in keys:
            reading.lack(file=path, key=prefix + key, value=keys[key], why="no csmlab knob")


def read_godot4(paths) -> Imported:
    """Godot 4 settings from ``project.godot`` and/or a ``.tscn`` with a DirectionalLight3D.

    Raises
    ------
    InputError
        A file that is neither, a foreign or malformed one, or a value out of range (file and key named).
    """
    reading = Reading("godot4", PRESET)
    for path in paths:
        suffix = Path(path).suffix
        if suffix == ".godot":
            _project(path, reading)
        elif suffix in (".tscn", ".escn"):
            _light(path, reading)
        else:
            raise InputError("expected project.godot or a .tscn scene", file=path, field="file")
    _soft_shadows(reading)
    if "atlas" in reading.pending:
        size, key = reading.pending["atlas"]
        cascades = reading.values.get("cascades", reading.base.cascades)
        # get_directional_light_shadow_size: 2 or 4 splits share the atlas, each split half its side.
        reading.set("resolution", size if cascades == 1 else size // 2, file="project.godot", key=key, raw=size)
    elif reading.values.get("cascades", reading.base.cascades) == 1:
        # One split takes the whole default atlas, twice the side of the preset's 4-split tile.
        reading.set("resolution", 2 * reading.base.resolution, file=reading.origins["cascades"].split(":")[0],
                    key="directional_shadow_mode",
                    raw="0 (one split takes the whole default atlas)")
    if reading.values.get("cascades", reading.base.cascades) == 1:
        # One split fills the atlas: one texture of one map, csmlab's array of one slice (memory_bytes).
        reading.set("storage", "array", file=reading.origins["cascades"].split(":")[0],
                    key="directional_shadow_mode", raw="0 (one split fills the atlas)")
    return reading.result()


def _soft_shadows(reading: Reading) -> None:
    """The filter of the project's soft-shadow level and the light's blur, and the light's blend splits, once every
    file is read: the level's Vogel disk has its quality radius × shadow_blur texels
    (csmlab.lookup_choices.godot_soft_shadow_fields), and blending splits drops the first-split blur scaling
    (csmlab.cascades.fit.GODOT_BLEND_SPLITS)."""
    origins = {}
    if "quality" in reading.pending or "blur" in reading.pending:
        quality, said_quality = reading.pending.get("quality", (GODOT_SOFT_LOW_LEVEL, None))
        blur, said_blur = reading.pending.get("blur", (1.0, None))
        origin = "; ".join(o for o in (said_quality, said_blur) if o)
        origins.update({name: (value, origin) for name, value in godot_soft_shadow_fields(quality, blur=blur).items()})
    if "blend" in reading.pending:
        blend, origin = reading.pending["blend"]
        fields = {**GODOT_BLEND_SPLITS, "vogel_scale": "none"} if blend else {
            "blend_band": 0.0, "vogel_scale": GODOT_SOFT_LOW["vogel_scale"]}
        origins.update({name: (value, origin) for name, value in fields.items()})
    for name, (value, origin) in origins.items():
        reading.values[name] = value
        reading.origins[name] = origin


def _soft_level(settings: ShadowSettings) -> tuple[int, float, list]:
    """The soft_shadow_filter_quality and shadow_blur that give ``settings``' filter, and what the files cannot hold
    of its filter and blend (Godot's blend splits are GODOT_BLEND_SPLITS, its disk unscaled under them)."""
    lacking = []
    differing = [k for k, v in GODOT_BLEND_SPLITS.items() if getattr(settings, k) != v]
    if settings.blend_band > 0 and differing:
        lacking.append(", ".join(f"{k} = {getattr(settings, k)!r}" for k in differing) +
                       f" (Godot blends splits over the last tenth of each: {GODOT_BLEND_SPLITS})")
    if hard_filter(settings):
        return 0, 1.0, lacking
    scale = "none" if settings.blend_band > 0 else GODOT_SOFT_LOW["vogel_scale"]
    if settings.filter == "pcf_vogel" and settings.vogel_scale != scale:
        lacking.append(f"vogel_scale = {settings.vogel_scale!r} (Godot scales its disk by the first split unless it "
                       f"blends splits: {scale!r} here)")
    for quality, level in GODOT_SOFT_SHADOW_QUALITIES.items():
        if level.samples and vogel_is(settings, vogel_taps=level.samples, vogel_angle=2.4):
            return quality, settings.vogel_radius / level.radius, lacking
    return GODOT_SOFT_LOW_LEVEL, 1.0, lacking + [
        f"filter = {settings.filter!r}, filter_size = {settings.filter_size} (Godot filters with its own soft-shadow "
        f"kernel: pcf_vogel at golden angle 2.4 with 1, 4, 8, 16 or 32 taps; Soft Low written)"]


def write_godot4(settings: ShadowSettings, *, near: float, far: float) -> tuple[dict, list]:
    """``settings`` as ``project.godot`` and ``light.tscn`` texts, and the knobs they cannot hold."""
    quality, blur, lacking = _soft_level(settings)
    cascades = count_one_two_or_four(settings.cascades)
    z = split_boundaries(settings.replace(cascades=cascades), near=near, far=far)
    fractions = fractions_of_range(z)
    size = largest_resolution(settings)
    if settings.cull == "none":
        lacking.append("cull = 'none' (Godot culls the material's back faces, or its front ones reversed)")
    if settings.depth_format not in ("unorm16", "float32"):
        lacking.append(f"depth_format = {settings.depth_format!r} (Godot's shadow atlas is 16-bit or 32-bit float)")
    mode = {v: k for k, v in _MODES.items()}[cascades]
    project = ["; Engine configuration file.", "config_version=5", "", "[rendering]", "",
               f"lights_and_shadows/directional_shadow/size={size * (1 if cascades == 1 else 2)}",
               f"lights_and_shadows/directional_shadow/soft_shadow_filter_quality={quality}",
               f"lights_and_shadows/directional_shadow/16_bits={'true' if settings.depth_format == 'unorm16' else 'false'}"]
    light = ['[gd_scene format=3]', '', '[node name="DirectionalLight3D" type="DirectionalLight3D"]',
             "shadow_enabled = true",
             f"shadow_bias = {settings.bias_depth_range / SHADOW_BIAS_SCALE!r}",
             f"shadow_normal_bias = {settings.normal_offset!r}",
             f"shadow_blur = {blur!r}",
             f"shadow_reverse_cull_face = {'true' if settings.cull == 'front' else 'false'}",
             f"directional_shadow_mode = {mode}",
             *(f"directional_shadow_split_{i + 1} = {f!r}" for i, f in enumerate(fractions)),
             f"directional_shadow_max_distance = {float(z[-1])!r}",
             f"directional_shadow_fade_start = {1.0 - settings.fade_out!r}",
             f"directional_shadow_pancake_size = {settings.pancake!r}",
             f"directional_shadow_blend_splits = {'true' if settings.blend_band > 0 else 'false'}"]
    return {"project.godot": "\n".join(project) + "\n", "light.tscn": "\n".join(light) + "\n"}, lacking


def export_godot4(settings: ShadowSettings, *, near: float, far: float) -> Snippet:
    """Godot 4: DirectionalLight3D properties and the directional shadow atlas size."""
    quality, blur, soft_lacking = _soft_level(settings)
    lacking = common_lacking(settings, stable="exact") + shape_lacking(settings, fade="smoothstep") + soft_lacking
    modes = {1: 0, 2: 1, 4: 2}
    cascades = count_one_two_or_four(settings.cascades)
    if cascades != settings.cascades:
        lacking.append(f"cascades = {settings.cascades} (Godot has 1, 2 or 4 splits; {cascades} written)")
    # Godot places each split at min_distance + split · (max_distance - min_distance) from the camera's near
    # plane (RendererSceneCull::_light_instance_setup_directional_shadow): fractions of the range, not of far.
    z = split_boundaries(settings.replace(cascades=cascades), near=near, far=far)
    fractions = fractions_of_range(z)
    atlas = largest_resolution(settings) * (1 if cascades == 1 else 2)
    lines = ["# DirectionalLight3D",
             f"directional_shadow_mode = {modes[cascades]}",
             f"directional_shadow_max_distance = {four_digits(min(settings.shadow_distance, far))}"]
    lines += [f"directional_shadow_split_{i + 1} = {four_digits(f)}" for i, f in enumerate(fractions)]
    lines += [f"directional_shadow_blend_splits = {'true' if settings.blend_band > 0 else 'false'}",
              "# Project Settings",
              f"rendering/lights_and_shadows/directional_shadow/size = {atlas}  "
              f"# {largest_resolution(settings)}² per split (2 splits: half the atlas each)",
              "rendering/lights_and_shadows/directional_shadow/soft_shadow_filter_quality = "
              f"{quality}  # {GODOT_SOFT_SHADOW_QUALITIES[quality].name}"]
    if quality:
        lines.insert(1, f"shadow_blur = {four_digits(blur)}")
    return Snippet("godot4", "Godot 4: DirectionalLight3D and project settings", "gdscript", "\n".join(lines) + "\n",
                   tuple(lacking))


ENGINE = Engine("godot4", export_godot4, EngineFiles(
    read=read_godot4, write=write_godot4, fields=FIELDS, preset=fixed_preset(PRESET), presets=(PRESET,),
    files="project.godot and/or a .tscn with a DirectionalLight3D"))
"""What the registries of csmlab.engines take from this module."""
