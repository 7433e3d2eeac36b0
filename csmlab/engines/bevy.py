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
from csmlab.engines.common import (Engine, EngineFiles, Snippet, common_lacking, fixed_preset, largest_resolution,
                                   shape_lacking)
from csmlab.engines.reading import Imported, Reading, number, read_text
from csmlab.engines.ron import parse_ron
from csmlab.errors import InputError
from csmlab.settings import ShadowSettings

__all__ = ["BEVY_EXACT", "BEVY_FILTERING", "ENGINE", "FIELDS", "PRESET", "export_bevy", "read_bevy", "write_bevy"]

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


def _by_type(table: dict, name: str):
    return next(((k, v) for k, v in table.items() if isinstance(k, str) and k.rsplit("::", 1)[-1] == name),
                (None, None))


def read_bevy(paths) -> Imported:
    """Bevy settings from a ``.scn.ron`` scene.

    Raises
    ------
    InputError
        Not RON, not a scene, no CascadeShadowConfig or DirectionalLight, or a value out of range.
    """
    reading = Reading("bevy", PRESET)
    for path in paths:
        scene = parse_ron(read_text(path), file=path)
        if not isinstance(scene, dict) or not isinstance(scene.get("entities"), dict):
            raise InputError("expected a Bevy scene: ( resources: {…}, entities: {…} )", file=path, field="entities")
        components = {}
        for entity in scene["entities"].values():
            for key, value in (entity.get("components", {}) if isinstance(entity, dict) else {}).items():
                components.setdefault(key, value)
        key, config = _by_type(components, "CascadeShadowConfig")
        light_key, light = _by_type(components, "DirectionalLight")
        if config is None and light is None:
            raise InputError("expected an entity with CascadeShadowConfig or DirectionalLight components", file=path,
                             field="CascadeShadowConfig")
        name = "CascadeShadowConfig"
        if isinstance(config, dict) and "bounds" in config:
            bounds = config["bounds"]
            if not isinstance(bounds, list) or not bounds:
                raise InputError(f"expected a list of far bounds in metres, got {bounds!r}", file=path,
                                 field=f"{name}.bounds")
            b = np.array([number(v, file=path, key=f"{name}.bounds", above=0.0) for v in bounds])
            if np.any(np.diff(b) <= 0):
                raise InputError(f"expected increasing bounds, got {bounds}", file=path, field=f"{name}.bounds")
            reading.set("cascades", len(b), file=path, key=f"{name}.bounds", raw=bounds)
            reading.set("shadow_distance", float(b[-1]), file=path, key=f"{name}.bounds[-1]", raw=bounds[-1])
            ratios = b[1:] / b[:-1]
            if len(b) > 1 and np.allclose(ratios, ratios[0], rtol=1e-6):
                reading.set("split", "geometric", file=path, key=f"{name}.bounds", raw="geometric after the first")
                reading.set("first_cascade_far", float(b[0]), file=path, key=f"{name}.bounds[0]", raw=bounds[0])
            else:
                reading.set("split", "manual", file=path, key=f"{name}.bounds", raw=bounds)
                reading.set("splits", tuple(float(v) for v in b / b[-1]), file=path, key=f"{name}.bounds", raw=bounds)
        if isinstance(config, dict) and "overlap_proportion" in config:
            reading.set("blend_band", number(config["overlap_proportion"], file=path,
                                             key=f"{name}.overlap_proportion", minimum=0.0), file=path,
                        key=f"{name}.overlap_proportion")
        if isinstance(config, dict) and "minimum_distance" in config:
            reading.lack(file=path, key=f"{name}.minimum_distance", value=config["minimum_distance"],
                         why="csmlab's first cascade starts at the camera's near plane")
        if isinstance(light, dict):
            for field, attribute in (("shadow_depth_bias", "bias_constant"), ("shadow_normal_bias", "normal_offset")):
                if field in light:
                    reading.set(attribute, number(light[field], file=path, key=f"DirectionalLight.{field}",
                                                  minimum=0.0), file=path, key=f"DirectionalLight.{field}")
            if light.get("shadows_enabled") is False:
                reading.lack(file=path, key="DirectionalLight.shadows_enabled", value=False,
                             why="the light casts no shadow in Bevy; csmlab measures its shadows anyway")
        resources = scene.get("resources", {}) if isinstance(scene.get("resources"), dict) else {}
        _, shadow_map = _by_type(resources, "DirectionalLightShadowMap")
        if isinstance(shadow_map, dict) and "size" in shadow_map:
            reading.set("resolution", number(shadow_map["size"], file=path, key="DirectionalLightShadowMap.size",
                                             integer=True, minimum=1), file=path, key="DirectionalLightShadowMap.size")
        _, filtering = _by_type(components, "ShadowFilteringMethod")
        if filtering == "Hardware2x2":
            reading.set("filter", "pcf_bilinear", file=path, key="ShadowFilteringMethod", raw=filtering)
        elif filtering not in (None, "Gaussian"):
            reading.lack(file=path, key="ShadowFilteringMethod", value=filtering,
                         why="csmlab models Hardware2x2 and Gaussian (Castaño 5×5); the preset's Gaussian is kept")
    return reading.result()


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
    lacking = common_lacking(settings, stable="exact") + shape_lacking(settings, transition="far_bound")
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
             f"app.insert_resource(DirectionalLightShadowMap {{ size: {largest_resolution(settings)} }});"]
    if filtering:
        lines.append(f"// on the camera: ShadowFilteringMethod::{filtering}")
    return Snippet("bevy", "Bevy: CascadeShadowConfig and DirectionalLightShadowMap", "rust", "\n".join(lines) + "\n",
                   tuple(lacking))


ENGINE = Engine("bevy", export_bevy, EngineFiles(
    read=read_bevy, write=write_bevy, fields=FIELDS, preset=fixed_preset(PRESET), presets=(PRESET,),
    files="a .scn.ron scene with CascadeShadowConfig and the DirectionalLight"))
"""What the registries of csmlab.engines take from this module."""
