"""Bevy: a scene (``.scn.ron``) holding ``CascadeShadowConfig`` and the ``DirectionalLight``, read and written.

Components and resources are matched by the last segment of their type path (``bevy_light::cascade::
CascadeShadowConfig``, ``…::DirectionalLight``, the ``DirectionalLightShadowMap`` resource, the camera's
``ShadowFilteringMethod``; bevyengine/bevy @4805ca7 crates/bevy_light). ``bounds`` (metres: split =
"geometric" with first_cascade_far = bounds[0] when they are the builder's geometric series, else
"manual"), ``overlap_proportion`` (blend_band), ``shadow_depth_bias`` (bias_constant, metres),
``shadow_normal_bias`` (normal_offset, texels), ``size`` (resolution) and the filtering method
(``Hardware2x2``: pcf_bilinear; ``Gaussian``: the preset's Castaño 5×5) map to csmlab fields; what the
scene leaves out keeps ``configs/engines/bevy.toml``.

The snippet (export_bevy) names: ``CascadeShadowConfigBuilder { num_cascades, minimum_distance, maximum_distance,
first_cascade_far_bound, overlap_proportion }``, ``CascadeShadowConfig { bounds, … }``,
``DirectionalLightShadowMap { size }``, ``ShadowFilteringMethod``.
"""

from __future__ import annotations

import numpy as np

from csmlab.cascades.splits import split_boundaries
from csmlab.engines.common import (Engine, EngineFiles, Snippet, TuneSpace, common_lacking, fixed_preset,
                                   largest_resolution, shape_lacking)
from csmlab.engines.reading import Entry, Imported, Located, Reading, read_text
from csmlab.engines.ron import parse_ron
from csmlab.errors import InputError
from csmlab.settings import ShadowSettings

__all__ = ["BEVY_EXACT", "BEVY_FILTERING", "ENGINE", "FIELDS", "PRESET", "TUNE_SPACE", "export_bevy", "read_bevy",
           "settled_bevy", "write_bevy"]

PRESET = "bevy"
"""The engine preset holding Bevy's defaults."""

FIELDS = frozenset({"cascades", "split", "splits", "first_cascade_far", "shadow_distance", "blend_band",
                    "bias_constant", "normal_offset", "resolution", "filter", "filter_size"})
"""The csmlab fields a scene carries."""

BEVY_FILTERING: dict[str, str] = {"pcf_bilinear": "Hardware2x2", "pcf": "Gaussian", "pcf_gaussian": "Gaussian",
                                  "pcf_tent": "Gaussian", "pcf_castano": "Gaussian", "pcf_tent_bilinear": "Gaussian",
                                  "pcf_bilinear_box": "Gaussian"}
"""Bevy's nearest ``ShadowFilteringMethod`` by csmlab filter (a key of csmlab.lookup_choices.FILTER_METHODS).

Bevy's Gaussian is Castaño's 5×5 of 9 bilinear taps, ``sample_shadow_map_castano_thirteen``
(csmlab's ``pcf_castano`` 5, configs/engines/bevy.toml); a filter not here gets no method.
"""

BEVY_EXACT: dict[str, int | None] = {"pcf_bilinear": None, "pcf_castano": 5}
"""The filters Bevy runs as csmlab does, with the filter_size that matches (None: any); the others are lacking."""


def _by_type(table: Entry, name: str) -> Entry | None:
    """The value of ``table`` (components or resources, by type path) whose type's last segment is ``name``,
    keyed by that name."""
    found = next((value for key, value in table.fields() if isinstance(key, str) and key.rsplit("::", 1)[-1] == name),
                 None)
    return None if found is None else Entry(found.raw, file=table.file, key=name, line=found.line)


def _geometric(bounds: np.ndarray) -> bool:
    """Whether far bounds ``(n,)`` (positive, increasing) grow by one ratio: the builder's series after the first."""
    steps = np.diff(np.log(bounds))  # logs: a ratio of 1e308 to 1e-300 overflows, its log does not
    return len(bounds) > 1 and bool(np.all(np.abs(steps - steps[0]) <= 1e-6))


def read_bevy(paths) -> Imported:
    """Bevy settings from a ``.scn.ron`` scene.

    Raises
    ------
    InputError
        Not RON, not a scene, no CascadeShadowConfig or DirectionalLight, or a value out of range.
    """
    reading = Reading("bevy", PRESET)
    for path in paths:
        scene = Entry(parse_ron(read_text(path), file=path), file=path)
        entities = scene.get("entities") if scene.is_object() else None
        if entities is None or not entities.is_object():
            raise InputError("expected a Bevy scene: ( resources: {…}, entities: {…} )", file=path,
                             field="entities", line=scene.line)
        merged = Located()
        merged.line, merged.key_lines = entities.line, {}
        for _, entity in entities.fields():
            found = entity.mapping("an entity: ( components: {…} )").get("components")
            for key, value in [] if found is None else found.mapping("components by type path").fields():
                if key not in merged:
                    merged[key], merged.key_lines[key] = value.raw, value.line
        components = Entry(merged, file=path, key="components", line=entities.line)
        config = _by_type(components, "CascadeShadowConfig")
        light = _by_type(components, "DirectionalLight")
        if config is None and light is None:
            raise InputError("expected an entity with CascadeShadowConfig or DirectionalLight components", file=path,
                             field="CascadeShadowConfig")
        if config is not None:
            _read_cascades(config.mapping("CascadeShadowConfig's members (bounds, overlap_proportion, …)"), reading)
        if light is not None:
            light.mapping("DirectionalLight's members (shadow_depth_bias, …)")
            for field, attribute in (("shadow_depth_bias", "bias_constant"), ("shadow_normal_bias", "normal_offset")):
                if (entry := light.member(field)) is not None:
                    reading.set(attribute, entry.number(minimum=0.0), file=path, key=entry.key)
            enabled = light.member("shadows_enabled")
            if enabled is not None and not enabled.boolean():
                reading.lack(file=path, key=enabled.key, value=False,
                             why="the light casts no shadow in Bevy; csmlab measures its shadows anyway")
        resources = scene.get("resources")
        shadow_map = None if resources is None else _by_type(resources.mapping("resources by type path"),
                                                             "DirectionalLightShadowMap")
        if shadow_map is not None and (entry := shadow_map.mapping("( size: … )").member("size")) is not None:
            reading.set("resolution", entry.integer(minimum=1), file=path, key=entry.key)
        filtering = _by_type(components, "ShadowFilteringMethod")
        method = None if filtering is None else filtering.text(what="a ShadowFilteringMethod (Hardware2x2, "
                                                                     "Gaussian, Temporal)")
        if method == "Hardware2x2":
            reading.set("filter", "pcf_bilinear", file=path, key="ShadowFilteringMethod", raw=method)
        elif method not in (None, "Gaussian"):
            reading.lack(file=path, key="ShadowFilteringMethod", value=method,
                         why="csmlab models Hardware2x2 and Gaussian (Castaño 5×5); the preset's Gaussian is kept")
    return reading.result()


def _read_cascades(config: Entry, reading: Reading) -> None:
    """CascadeShadowConfig's bounds, overlap and minimum distance."""
    path, name = config.file, config.key
    if (found := config.member("bounds")) is not None:
        entries = found.items("a list of far bounds in metres")
        if not entries:
            raise found.error("a list of far bounds in metres")
        b = np.array([entry.number(above=0.0) for entry in entries])
        if np.any(np.diff(b) <= 0):
            raise found.error("increasing bounds")
        bounds = [float(v) for v in b]
        reading.set("cascades", len(b), file=path, key=found.key, raw=bounds)
        reading.set("shadow_distance", bounds[-1], file=path, key=f"{name}.bounds[-1]", raw=bounds[-1])
        if _geometric(b):
            reading.set("split", "geometric", file=path, key=found.key, raw="geometric after the first")
            reading.set("first_cascade_far", bounds[0], file=path, key=f"{name}.bounds[0]", raw=bounds[0])
        else:
            reading.set("split", "manual", file=path, key=found.key, raw=bounds)
            reading.set("splits", tuple(float(v) for v in b / b[-1]), file=path, key=found.key, raw=bounds)
    if (entry := config.member("overlap_proportion")) is not None:
        reading.set("blend_band", entry.number(minimum=0.0), file=path, key=entry.key)
    if (entry := config.member("minimum_distance")) is not None:
        reading.lack(file=path, key=entry.key, value=entry.number(minimum=0.0),
                     why="csmlab's first cascade starts at the camera's near plane")


def write_bevy(settings: ShadowSettings, *, near: float, far: float) -> tuple[dict, list]:
    """``settings`` as a ``.scn.ron`` scene, and the knobs it cannot hold."""
    z = split_boundaries(settings, near=near, far=far)
    method = "Hardware2x2" if settings.filter == "pcf_bilinear" else BEVY_FILTERING.get(settings.filter, "Gaussian")
    bounds = ", ".join(repr(float(v)) for v in z[1:])
    text = f"""(
  resources: {{
    "bevy_light::directional_light::DirectionalLightShadowMap": (
      size: {largest_resolution(settings)},
    ),
  }},
  entities: {{
    4294967296: (
      components: {{
        "bevy_light::directional_light::DirectionalLight": (
          illuminance: 10000.0,
          shadows_enabled: true,
          shadow_depth_bias: {settings.bias_constant!r},
          shadow_normal_bias: {settings.normal_offset!r},
        ),
        "bevy_light::cascade::CascadeShadowConfig": (
          bounds: [{bounds}],
          overlap_proportion: {settings.blend_band!r},
          minimum_distance: {float(z[0])!r},
        ),
      }},
    ),
    4294967297: (
      components: {{
        "bevy_light::ShadowFilteringMethod": {method},
      }},
    ),
  }},
)
"""
    return {"scene.scn.ron": text}, []


def export_bevy(settings: ShadowSettings, *, near: float, far: float) -> Snippet:
    """Bevy: the CascadeShadowConfigBuilder, and the exact bounds as a CascadeShadowConfig."""
    z = split_boundaries(settings, near=near, far=far)
    lacking = common_lacking(settings, stable="exact", carried=FIELDS) + shape_lacking(settings, transition="far_bound")
    filtering = BEVY_FILTERING.get(settings.filter)
    if settings.filter not in BEVY_EXACT or BEVY_EXACT[settings.filter] not in (None, settings.filter_size):
        lacking.append(f"filter = {settings.filter!r}, filter_size = {settings.filter_size} (Bevy filters with "
                       f"Hardware2x2, Gaussian or Temporal)")
    bounds = ", ".join(f"{v:.3f}" for v in z[1:])
    lines = ["// The builder spaces the cascades after the first geometrically:",
             "let config: CascadeShadowConfig = CascadeShadowConfigBuilder {",
             f"    num_cascades: {settings.cascades},",
             f"    minimum_distance: {z[0]:.3f},",
             f"    maximum_distance: {z[-1]:.3f},",
             f"    first_cascade_far_bound: {z[1]:.3f},",
             f"    overlap_proportion: {settings.blend_band:.3f},",
             "}.build();",
             "// csmlab's bounds exactly:",
             f"let config = CascadeShadowConfig {{ bounds: vec![{bounds}], overlap_proportion: "
             f"{settings.blend_band:.3f}, minimum_distance: {z[0]:.3f} }};",
             f"app.insert_resource(DirectionalLightShadowMap {{ size: {largest_resolution(settings)} }});",
             f"// on the sun: DirectionalLight {{ shadow_depth_bias: {settings.bias_constant:.6g}, "
             f"shadow_normal_bias: {settings.normal_offset:.6g}, .. }}"]
    if filtering:
        lines.append(f"// on the camera: ShadowFilteringMethod::{filtering}")
    return Snippet("bevy", "Bevy: CascadeShadowConfig and DirectionalLightShadowMap", "rust", "\n".join(lines) + "\n",
                   tuple(lacking))


def settled_bevy(settings: ShadowSettings) -> ShadowSettings:
    """``settings`` with the bounds one cascade gives: a single far bound, the shadow distance (split ``manual``,
    as :func:`read_bevy` reads one bound)."""
    return settings.replace(split="manual", splits=(1.0,)) if settings.cascades == 1 else settings


TUNE_SPACE = TuneSpace({
    # CascadeShadowConfigBuilder: num_cascades (at most 4 per light), first_cascade_far_bound, maximum_distance
    # (beyond the first bound's largest), overlap_proportion; DirectionalLight's shadow_depth_bias and
    # shadow_normal_bias; DirectionalLightShadowMap.size; ShadowFilteringMethod Gaussian or Hardware2x2.
    "cascades": ("choice", (1, 2, 3, 4)),
    "first_cascade_far": ("range", 1.0, 20.0, False, None),
    "shadow_distance": ("range", 30.0, 1000.0, True, None),
    "blend_band": ("range", 0.0, 0.5, False, None),
    "bias_constant": ("range", 0.0, 0.2, False, None),
    "normal_offset": ("range", 0.0, 5.0, False, None),
    "resolution": ("choice", (512, 1024, 2048, 4096)),
    "filter": ("choice", ("pcf_castano", "pcf_bilinear")),
}, settle=settled_bevy)
"""What a tune of the Bevy preset may try: CascadeShadowConfig's, the light's and the shadow map's own settings."""

ENGINE = Engine("bevy", export_bevy, EngineFiles(
    read=read_bevy, write=write_bevy, fields=FIELDS, preset=fixed_preset(PRESET), presets=(PRESET,),
    files="a .scn.ron scene with CascadeShadowConfig and the DirectionalLight"), tune=TUNE_SPACE)
"""What the registries of csmlab.engines take from this module."""
