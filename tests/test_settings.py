"""The ``[shadow]`` fields in named groups: one table (csmlab.settings.SETTING_GROUPS) that the class order,
docs/design.md, the validation, the applicability rules and ``csmlab list`` all follow."""

from __future__ import annotations

import re
from dataclasses import fields
from pathlib import Path

import pytest
from typer.testing import CliRunner

from csmlab.cli import app
from csmlab.config import TaaConfig
from csmlab.settings import APPLIES, SETTING_GROUPS, ShadowSettings

DESIGN = Path(__file__).resolve().parents[1] / "docs" / "design.md"

# One value out of range per group, in a field of that group (the defaults elsewhere).
BAD_VALUE_PER_GROUP = {
    "maps": {"cascades": 0},
    "clipmap": {"page_size": 100},
    "split": {"lambda_": 1.5},
    "policies": {"sun_step_deg": 0.0},
    "bounds": {"hysteresis": 1.0},
    "fit": {"levels": 0},
    "warp": {"warp": "perspective"},
    "depth_range": {"pancake": -1.0},
    "precision": {"subtexel_bits": 17},
    "depth_pass": {"cull": "sideways"},
    "filter": {"filter_size": 4},
    "moments": {"moment_blur": 2},
    "bias": {"bias_slope": -1.0},
    "blend": {"blend_band": 0.6},
    "storage": {"depth_format": "unorm8"},
}


def _toml(name: str) -> str:
    return "lambda" if name == "lambda_" else name


def _documented_sections() -> list[tuple[str, str, str]]:
    """``(name, title, text)`` of each ``# group NAME: TITLE`` section of design.md's ``[shadow]`` block."""
    text = DESIGN.read_text(encoding="utf-8")
    block = text[text.index("\n[shadow]"):text.index("\n[[methods]]")]
    parts = re.split(r"^# group (\w+): (.*)$", block, flags=re.M)
    assert not re.search(r"^\w+ =", parts[0], flags=re.M), "a [shadow] field before the first group line"
    return [(parts[i], parts[i + 1], parts[i + 2]) for i in range(1, len(parts), 3)]


def test_the_groups_hold_every_field_once_in_the_class_order():
    assert [name for group in SETTING_GROUPS for name in group.fields] == ShadowSettings.field_names()
    assert len({group.name for group in SETTING_GROUPS}) == len(SETTING_GROUPS)


def test_design_md_lists_the_shadow_fields_under_the_groups_of_the_table():
    sections = _documented_sections()
    assert [(name, title) for name, title, _ in sections] == [
        (g.name, g.title + (f" (only with {g.applies.when})" if g.applies else "")) for g in SETTING_GROUPS]
    for (name, _, text), group in zip(sections, SETTING_GROUPS):
        written = re.findall(r"^(\w+) =", text, flags=re.M)
        assert set(written) <= set(group.fields), (name, set(written) - set(group.fields))
        mentioned = set(re.findall(r"\w+", text))
        assert set(group.fields) <= mentioned, (name, set(group.fields) - mentioned)


def test_every_field_of_a_conditional_group_says_why_and_takes_effect_only_where_the_group_does():
    conditional = [g for g in SETTING_GROUPS if g.applies is not None]
    assert {g.name for g in conditional} == {"clipmap", "moments"}
    outside = {"clipmap": ShadowSettings(), "moments": ShadowSettings(filter="pcf", moment_mips=True)}
    for group in conditional:
        for key in group.fields:
            rule = APPLIES[key]
            assert rule.when.startswith(group.applies.when) or rule.when.startswith("filter =") or \
                rule.when.startswith("a moment filter"), key
            assert not group.applies.holds(outside[group.name]) and not rule.holds(outside[group.name]), key


@pytest.mark.parametrize("group", list(BAD_VALUE_PER_GROUP))
def test_each_groups_check_refuses_a_bad_value_naming_its_field(group):
    (attribute, value), = BAD_VALUE_PER_GROUP[group].items()
    settings = ShadowSettings().replace(**{attribute: value})
    with pytest.raises(ValueError, match=rf"^{_toml(attribute)}: expected "):
        settings.validated()
    with pytest.raises(ValueError, match=rf"^{_toml(attribute)}: expected "):
        next(g for g in SETTING_GROUPS if g.name == group).check(settings)


def test_validation_runs_the_groups_in_order_and_answers_with_the_first_bad_field():
    settings = ShadowSettings(cascades=0, bias_slope=-1.0, depth_format="unorm8")
    with pytest.raises(ValueError, match="^cascades: "):
        settings.validated()
    with pytest.raises(ValueError, match="^bias_slope: "):
        settings.replace(cascades=4).validated()


def test_every_group_has_a_bad_value_case_or_checks_names_only():
    assert set(BAD_VALUE_PER_GROUP) | {"selection"} == {g.name for g in SETTING_GROUPS}


def test_list_shows_every_group_with_its_fields_the_taa_table_and_the_policies():
    outcome = CliRunner().invoke(app, ["list"], env={"COLUMNS": "400"})
    assert outcome.exit_code == 0
    rows, name = {}, None
    for line in outcome.stdout.splitlines():
        if line.count("│") == 3:
            _, key, about, _ = line.split("│")
            name = key.strip() or name
            rows[name] = f"{rows.get(name, '')} {about.strip()}"
    for group in SETTING_GROUPS:
        assert group.name in rows and all(name in rows[group.name] for name in group.fields), group.name
    assert all(f.name in rows["[taa]"] for f in fields(TaaConfig))
    assert "every_n" in rows["sun_policy"] and "min_fov" in rows["zoom_policy"]
    assert "variance" in rows["[taa] clamp"]
