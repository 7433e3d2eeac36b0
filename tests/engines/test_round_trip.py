"""Settings that go back whole: what a tune of an engine preset can recommend, the engine's files hold.

Every engine declares its tune space (csmlab.engines.common.TuneSpace: the values the engine can express);
a setting drawn from it, or the engine's preset itself, is exported with no "lacks" line and read back
through the engine's own files as the same setting.
"""

from __future__ import annotations

import numpy as np
import pytest

from csmlab.engines import ENGINES, export, import_settings
from csmlab.engines.reading import engine_settings, toml_name
from csmlab.errors import InputError
from csmlab.settings import APPLIES, ShadowSettings

NEAR, FAR = 0.1, 10000.0
"""A far plane beyond every engine's largest shadow distance: the distance exported is the setting's."""
DRAWS = 6

PRESETS = [(name, preset) for name, engine in ENGINES.items() for preset in engine.files.presets]


def drawn(space: dict, base: ShadowSettings, seed: int) -> ShadowSettings:
    """A setting of ``base`` with every field of ``space`` drawn at random (seeded): a choice uniformly, a range
    uniformly (log-uniformly for a log range, integers for an int range, on its step's grid); then settled as the
    engine settles it."""
    rng = np.random.default_rng(seed)
    fields = {}
    for name, spec in space.fields.items():
        if spec[0] == "choice":
            value = spec[1][rng.integers(len(spec[1]))]
        else:
            _, lo, hi, log, step = spec
            if isinstance(lo, int):
                value = int(rng.integers(lo, hi + 1))
            elif log:
                value = float(np.exp(rng.uniform(np.log(lo), np.log(hi))))
            else:
                value = float(rng.uniform(lo, hi))
            if step is not None and not isinstance(lo, int):
                value = min(lo + round((value - lo) / step) * step, hi)
        fields["lambda_" if name == "lambda" else name] = value
    return space.settle(base.replace(**fields)).validated()


def back_through_files(settings: ShadowSettings, engine: str, folder) -> tuple[ShadowSettings, tuple]:
    """``import(export(settings))`` through ``engine``'s own files, and the export's lacking lines."""
    snippet = export(settings, near=NEAR, far=FAR, engine=engine)
    paths = []
    for name, text in snippet.files:
        paths.append(folder / name)
        paths[-1].write_text(text, encoding="utf-8")
    return import_settings(paths, engine=engine).settings, snippet.lacking


def changed_fields(settings: ShadowSettings, back: ShadowSettings) -> list[str]:
    """Fields that apply to ``settings`` and came back different (floats to 1e-9 relative: the files' decimals)."""
    wrong = []
    for attribute in ShadowSettings.__dataclass_fields__:
        name = toml_name(attribute)
        if name in APPLIES and not APPLIES[name].holds(settings):
            continue
        mine, theirs = getattr(settings, attribute), getattr(back, attribute)
        if isinstance(mine, (float, tuple)) and np.shape(mine) == np.shape(theirs):
            same = bool(np.allclose(mine, theirs, rtol=1e-9, atol=1e-12))
        else:
            same = mine == theirs
        if not same:
            wrong.append(f"{name}: {mine!r} → {theirs!r}")
    return wrong


def test_every_engine_declares_a_tune_space_its_files_carry():
    for name, engine in ENGINES.items():
        assert engine.tune is not None and engine.tune.fields, name
        carried = {toml_name(attribute) for attribute in engine.files.fields}
        assert set(engine.tune.fields) <= carried, (name, set(engine.tune.fields) - carried)


@pytest.mark.parametrize("engine,preset", PRESETS)
def test_an_engine_preset_exports_without_a_lacking_line_and_comes_back(engine, preset, tmp_path):
    settings = engine_settings(preset)
    back, lacking = back_through_files(settings, engine, tmp_path)
    assert lacking == ()
    assert changed_fields(settings, back) == []


@pytest.mark.parametrize("engine,preset", PRESETS)
def test_a_setting_from_the_engines_tune_space_exports_whole_and_comes_back(engine, preset, tmp_path):
    space = ENGINES[engine].tune
    for seed in range(DRAWS):
        settings = drawn(space, engine_settings(preset), seed)
        back, lacking = back_through_files(settings, engine, tmp_path)
        assert lacking == (), (seed, settings)
        assert changed_fields(settings, back) == [], seed


@pytest.mark.parametrize("engine,preset", PRESETS)
def test_each_choice_of_the_tune_space_comes_back(engine, preset, tmp_path):
    # Six draws may miss a value of a choice (Godot's one split, Unity's three cascades): each is tried alone.
    space = ENGINES[engine].tune
    base = engine_settings(preset)
    for name, spec in space.fields.items():
        for value in (spec[1] if spec[0] == "choice" else spec[1:3]):
            settings = space.settle(base.replace(**{"lambda_" if name == "lambda" else name: value})).validated()
            back, lacking = back_through_files(settings, engine, tmp_path)
            assert lacking == (), (name, value)
            assert changed_fields(settings, back) == [], (name, value)


def test_a_knob_at_the_engines_own_value_is_not_lacking_and_one_away_from_it_is():
    urp = engine_settings("unity_urp")  # URP selects cascades by sphere, as its preset says
    assert not any(item.startswith("selection") for item in export(urp, near=NEAR, far=FAR, engine="unity_urp").lacking)
    interval = export(urp.replace(selection="interval"), near=NEAR, far=FAR, engine="unity_urp").lacking
    assert any(item.startswith("selection = 'interval'") for item in interval)
    # levels equals the preset's default, but the preset does not quantize: it is named with the stabilization.
    quantized = export(engine_settings("godot4").replace(stabilization="quantized"), near=NEAR, far=FAR,
                       engine="godot4").lacking
    assert any(item.startswith("stabilization = 'quantized'") for item in quantized)
    assert any(item.startswith("levels =") for item in quantized)


@pytest.mark.parametrize("engine", sorted(ENGINES))
def test_the_snippet_to_paste_writes_every_field_of_the_tune_space(engine):
    # Not only the engine's files: the snippet a person pastes changes with each field a tune may change.
    space = ENGINES[engine].tune
    base = engine_settings(ENGINES[engine].files.presets[0])
    before = export(base, near=NEAR, far=FAR, engine=engine).text
    for name, spec in space.fields.items():
        attribute = "lambda_" if name == "lambda" else name
        other = next(v for v in (spec[1] if spec[0] == "choice" else spec[1:3]) if v != getattr(base, attribute))
        after = export(space.settle(base.replace(**{attribute: other})), near=NEAR, far=FAR, engine=engine).text
        assert after != before, (name, other)


def test_a_tune_space_cuts_a_users_space_to_the_values_the_engine_can_take():
    godot = ENGINES["godot4"].tune
    cut = godot.restricted({"cascades": ("choice", (1, 2, 3, 4)), "resolution": ("range", 600, 5000, False, None),
                            "shadow_distance": ("range", 0.5, 50.0, True, None)}, engine="godot4", method="godot4")
    assert cut == {"cascades": ("choice", (1, 2, 4)), "resolution": ("choice", (1024, 2048, 4096)),
                   "shadow_distance": ("range", 1.0, 50.0, True, None)}
    assert godot.restricted({}, engine="godot4", method="godot4") == godot.fields
    with pytest.raises(InputError, match=r"expected cascades values godot4 can take \(1, 2, 4\), got 3"):
        godot.restricted({"cascades": ("choice", (3,))}, engine="godot4", method="godot4")
    with pytest.raises(InputError, match="godot4 has no setting for 'warp'"):
        godot.restricted({"warp": ("choice", ("lispsm",))}, engine="godot4", method="godot4")
