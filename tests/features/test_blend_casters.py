"""Blended (glTF ``alphaMode = BLEND``) casters cast by each method's own rule ([shadow] blend_casters).

Oracles: a ray cast of the level read under the matching ``[scene] blend_casters`` (the reference
alpha-tests or not on its own BVH), a level without the card (the ``none`` rule's map), the
quad's light-space area (the ``opaque`` rule's texels) and half of it (the mask's opaque half).
"""

from __future__ import annotations

import io

import numpy as np
import pytest
from PIL import Image

from csmlab.camera import CameraPose
from csmlab.cascades import build_cascades
from csmlab.geometry import rotation_looking_at
from csmlab.light import direction_from_angles
from csmlab.render import caster_scene, prepare_scene, render_frame, shadow_maps
from csmlab.scene import make_scene
from csmlab.scene.gltf_writer import GltfBuilder, ground
from csmlab.scene.mesh import load_mesh
from csmlab.settings import ShadowSettings

LIGHT = direction_from_angles(elevation_deg=60.0, azimuth_deg=30.0)
HEIGHT = 8.0
"""The card's height: its footprint lies HEIGHT·tan(30°) = 4.6 m from below it, clear of its 3 m side."""
HALF = 1.5
FOOTPRINT = HEIGHT * np.array([LIGHT[0], 0.0, LIGHT[2]]) / -LIGHT[1]
POSE = CameraPose(position=FOOTPRINT + [0.0, 14.0, 0.0], orientation=rotation_looking_at((0.0, -1.0, 0.0)),
                  aspect=4.0 / 3.0)
SETTINGS = dict(cascades=1, resolution=256, shadow_distance=20.0, filter="none", bias_constant=0.05, bias_slope=0.0,
                normal_offset=0.0, receiver_plane_bias=False)


def _half_mask_png() -> bytes:
    """A 2×1 RGBA image: the left texel (u < ½) opaque, the right one clear."""
    image = Image.fromarray(np.array([[[255, 255, 255, 255], [255, 255, 255, 0]]], dtype=np.uint8), "RGBA")
    out = io.BytesIO()
    image.save(out, format="PNG")
    return out.getvalue()


def _level(tmp_path, *, card: bool = True, mode: str = "BLEND"):
    """A 60 m ground and, HEIGHT above it, a 3 m card of material ``mode`` opaque where x < 0 (u < ½)."""
    b = GltfBuilder()
    roots = [b.add_node(mesh=b.add_mesh(*ground(half_size=30.0)))]
    if card:
        material = b.add_masked_material(_half_mask_png())
        b.document.materials[material].alphaMode = mode
        b.document.materials[material].name = "glass"
        points, triangles = ground(half_size=HALF)
        uv = np.c_[(points[:, 0] + HALF) / (2 * HALF), (points[:, 2] + HALF) / (2 * HALF)]
        roots.append(b.add_node(mesh=b.add_mesh(points, triangles, uv=uv, material=material),
                                translation=(0.0, HEIGHT, 0.0)))
    return b.save(tmp_path / f"level_{card}_{mode}.glb", roots=roots)


def _depth(dscene, rule: str, corners) -> tuple[np.ndarray, float]:
    settings = ShadowSettings(**SETTINGS, blend_casters=rule).validated()
    cascades = build_cascades(pose=POSE, light_direction=LIGHT, scene_corners=corners, settings=settings)
    return shadow_maps(dscene, cascades, settings).depth[0], float(np.max(cascades.cascades[0].texel_size))


def test_each_rule_casts_the_blend_card_none_solid_or_by_its_mask(tmp_path):
    dscene = prepare_scene(load_mesh(_level(tmp_path), blend_casters="opaque"))
    bare = prepare_scene(load_mesh(_level(tmp_path, card=False)))
    maps = {rule: _depth(dscene, rule, dscene.corners)[0] for rule in ("scene", "opaque", "masked", "none")}
    ground_only, texel = _depth(bare, "scene", dscene.corners)
    assert np.array_equal(maps["none"], ground_only), "none: the card casts nothing"
    assert np.array_equal(maps["scene"], maps["opaque"]), "the level reads BLEND solid"
    solid = maps["opaque"] < ground_only
    cut = maps["masked"] < ground_only
    # The 3 m square seen from a light 60° above the horizon covers 9 sin 60° m² of the light's plane.
    area = (2 * HALF) ** 2 * -LIGHT[1] / texel ** 2
    assert abs(solid.sum() / area - 1.0) < 0.05, (solid.sum(), area)
    assert abs(cut.sum() / (area / 2) - 1.0) < 0.06, (cut.sum(), area / 2)
    assert np.all(solid[cut]) and np.array_equal(maps["masked"][cut], maps["opaque"][cut])


def _ground_shadow(scene, rule: str):
    """``(on_ground, lit, reference)`` ``(H, W)`` of a camera looking down on the card's footprint: the ground
    pixels (the card, partly in view, left out), the shadow map's and the ray cast's lit fractions."""
    frame = render_frame(scene, POSE, LIGHT, ShadowSettings(**{**SETTINGS, "resolution": 512}, blend_casters=rule),
                         width=160, height=120)
    hits = frame.view.gbuffer.hits.triangle
    on_ground = (hits >= 0) & (hits < 2) & (frame.shadow.cascade >= 0)
    assert on_ground.sum() > 15000
    return on_ground, frame.shadow.lit, frame.view.reference


@pytest.mark.parametrize("rule", ["opaque", "masked"])
def test_a_methods_rule_casts_as_the_ray_cast_of_the_level_read_under_it(tmp_path, rule):
    # The level is read under the other [scene] rule: the method's rule alone makes its casters.
    level = load_mesh(_level(tmp_path), blend_casters="opaque" if rule == "masked" else "masked")
    seen, lit, _ = _ground_shadow(level, rule)
    seen_too, _, reference = _ground_shadow(load_mesh(_level(tmp_path), blend_casters=rule), "scene")
    both = seen & seen_too
    lit, reference = lit[both], reference[both]
    shadowed = reference == 0.0
    assert shadowed.sum() > (300 if rule == "opaque" else 150)
    # Agreement but at the footprint's edge (texels of ~4 cm, pixels of ~13 cm).
    assert np.mean(lit == reference) > 0.99, np.mean(lit == reference)
    assert np.mean(lit[shadowed] == 0.0) > 0.9
    assert abs(int((lit == 0.0).sum()) - int(shadowed.sum())) < 0.1 * shadowed.sum()


def test_the_none_rule_leaves_the_ground_lit_while_the_reference_keeps_the_levels_card(tmp_path):
    seen, lit, reference = _ground_shadow(load_mesh(_level(tmp_path), blend_casters="opaque"), "none")
    assert (reference[seen] == 0.0).sum() > 300
    assert np.all(lit[seen] == 1.0)


@pytest.mark.parametrize("kind", ["foliage", "plane_box"])
def test_a_level_without_blend_triangles_casts_the_same_maps_under_every_rule(kind):
    dscene = prepare_scene(make_scene(kind))
    maps = {rule: _depth(dscene, rule, dscene.corners)[0] for rule in ("scene", "opaque", "masked", "none")}
    assert all(caster_scene(dscene, rule) is dscene for rule in maps)
    assert all(np.array_equal(maps["scene"], m) for m in maps.values())
    assert np.isfinite(maps["scene"]).any()


def test_a_mask_material_is_not_touched_by_any_rule(tmp_path):
    # MASK cards are alpha-tested whatever a method's blend rule: only BLEND triangles follow it.
    dscene = prepare_scene(load_mesh(_level(tmp_path, mode="MASK")))
    assert not dscene.scene.blended and dscene.scene.masked
    maps = [_depth(dscene, rule, dscene.corners)[0] for rule in ("scene", "opaque", "none")]
    assert all(np.array_equal(maps[0], m) for m in maps)


def test_methods_of_one_run_cast_by_their_own_rules_against_the_levels_reference(tmp_path):
    import csv

    from csmlab.config import load_experiment
    from csmlab.experiment import run_experiment
    from csmlab.scene.gltf_materials import blend_line

    _level(tmp_path)
    path = tmp_path / "x.toml"
    path.write_text('[scene]\nkind = "mesh"\nfile = "level_True_BLEND.glb"\nblend_casters = "masked"\n[camera]\n'
                    'path = "pan"\nframes = 2\nwidth = 64\nheight = 36\nview_check = "off"\n[[methods]]\n'
                    'name = "level"\n[[methods]]\nname = "own"\nblend_casters = "masked"\n[[methods]]\n'
                    'name = "solid"\nblend_casters = "opaque"\n[[methods]]\nname = "none"\nblend_casters = "none"\n')
    result = run_experiment(load_experiment(path), out_dir=tmp_path / "out")
    with open(tmp_path / "out" / "metrics.csv", newline="") as f:
        rows = {}
        for row in csv.DictReader(f):
            rows.setdefault(row.pop("method"), []).append(row)
    # The method whose rule is the level's casts the level's casters: its rows are the level's.
    assert rows["own"] == rows["level"]
    assert all(float(r["ref_false_shadow"]) == 0.0 and float(r["ref_false_light"]) == 0.0 for r in rows["level"])
    # The card solid shadows the mask's clear half; no card leaves its shadow lit.
    assert all(float(r["ref_false_shadow"]) > 0.0 for r in rows["solid"])
    assert all(float(r["ref_false_light"]) > 0.0 for r in rows["none"])
    note = result.summary["blend_materials"]
    assert note == {"rule": "masked", "materials": ["level_True_BLEND.glb: glass"],
                    "methods": {"own": "masked", "solid": "opaque", "none": "none"}}
    assert "solid's shadow opaque; none's shadow none" in blend_line(note)


def test_none_on_a_level_that_is_all_blended_is_refused_before_any_frame_naming_the_method(tmp_path):
    from csmlab.config import load_experiment
    from csmlab.errors import InputError
    from csmlab.experiment import build_workload

    b = GltfBuilder()
    material = b.add_masked_material(_half_mask_png())
    b.document.materials[material].alphaMode = "BLEND"
    points, triangles = ground(half_size=HALF)
    uv = np.c_[(points[:, 0] + HALF) / (2 * HALF), (points[:, 2] + HALF) / (2 * HALF)]
    b.save(tmp_path / "glass.glb", roots=[b.add_node(mesh=b.add_mesh(points, triangles, uv=uv, material=material))])
    path = tmp_path / "x.toml"
    path.write_text('[scene]\nkind = "mesh"\nfile = "glass.glb"\n[camera]\npath = "pan"\nframes = 2\nwidth = 64\n'
                    'height = 36\nview_check = "off"\n[[methods]]\nname = "urp"\nblend_casters = "none"\n')
    with pytest.raises(InputError, match=r"urp\.shadow\.blend_casters.*every triangle of .* is blended"):
        build_workload(load_experiment(path))
