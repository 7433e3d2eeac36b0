"""docs/engines.md holds every engine and seed preset field by field, and engines_equal_budget holds one budget.

Each preset file of configs/engines/ and configs/seeds/ has a section ``### `kind/name` `` in
docs/engines.md whose rows name exactly the fields the preset's [[methods]] entry sets, each with the
same value (read from the file as TOML, not from csmlab) and csmlab's default for it, and say where the
engine's value comes from and how sure that is; so a preset changed without its row fails here.
"""

from __future__ import annotations

import re
import tomllib

import pytest

from csmlab.config import find_experiment, load_experiment
from csmlab.metrics.cost import shadow_memory_bytes
from csmlab.settings import ShadowSettings
from tests.locations import ROOT

DOC = ROOT / "docs" / "engines.md"
PRESETS = sorted(f"{kind}/{p.stem}" for kind in ("engines", "seeds") for p in (ROOT / "configs" / kind).glob("*.toml"))
STATUSES = ("source", "docs", "third-party", "seed text", "unverified", "approximation")
BUDGET = 4 * 1024 * 1024 * 4


def _toml(text: str):
    return tomllib.loads(f"v = {text}")["v"]


def _plain(value):
    return [_plain(v) for v in value] if isinstance(value, (list, tuple)) else value


def _section(name: str) -> str:
    text = DOC.read_text(encoding="utf-8")
    start = text.find(f"### `{name}`\n")
    assert start >= 0, f"docs/engines.md has no section ### `{name}`"
    end = re.search(r"^#{2,3} ", text[start + 4:], flags=re.M)
    return text[start:start + 4 + end.start()] if end else text[start:]


def _rows(name: str) -> dict[str, list[str]]:
    rows = {}
    for line in _section(name).splitlines():
        match = re.match(r"\| `([a-z_]+)` \|", line)
        if match:
            cells = [c.strip() for c in line.strip().strip("|").split(" | ")]
            assert match[1] not in rows, f"{name}: {match[1]} has two rows"
            rows[match[1]] = cells
    return rows


def _written(name: str) -> dict:
    (entry,) = tomllib.loads((ROOT / "configs" / f"{name}.toml").read_text(encoding="utf-8"))["methods"]
    return {k: v for k, v in entry.items() if k not in ("name", "description")}


@pytest.mark.parametrize("name", PRESETS)
def test_every_field_a_preset_sets_has_its_row_with_the_same_value(name):
    written, rows = _written(name), _rows(name)
    assert sorted(rows) == sorted(written), f"docs/engines.md, {name}: rows for {sorted(rows)}, the preset sets " \
                                            f"{sorted(written)}"
    for key, value in written.items():
        cell = re.match(r"`(.*)`$", rows[key][1])
        assert cell and _toml(cell[1]) == value, f"docs/engines.md, {name}.{key}: {rows[key][1]} but the preset " \
                                                 f"sets {value!r}"


@pytest.mark.parametrize("name", PRESETS)
def test_every_row_gives_csmlabs_default_the_engines_value_its_source_and_status(name):
    defaults = ShadowSettings()
    for key, cells in _rows(name).items():
        assert len(cells) == 6, f"{name}.{key}: expected 6 cells, got {cells}"
        default = re.match(r"`(.*?)`", cells[2])
        expected = _plain(getattr(defaults, "lambda_" if key == "lambda" else key))
        assert default and _toml(default[1]) == expected, f"{name}.{key}: csmlab's default is {expected!r}"
        assert cells[3] not in ("", "TODO") and cells[4] not in ("", "TODO"), f"{name}.{key}: no engine value or source"
        assert cells[5] in STATUSES, f"{name}.{key}: status {cells[5]!r}, expected one of {STATUSES}"


def test_unreal_is_read_from_documentation_only():
    """Unreal's source is not public: no row of its preset claims to have read it."""
    assert {cells[5] for cells in _rows("engines/ue5").values()} <= {"docs", "third-party", "unverified",
                                                                      "approximation"}


def test_the_equal_budget_experiment_runs_every_engine_of_engines_toml_at_one_budget():
    """Each engine keeps its cascade count and depth format and takes the largest R within 4 × 1024² × 4 bytes (a
    virtual clipmap the most pages): every method's shadow maps within 0.1 % of the budget, none over it."""
    shipped = load_experiment(find_experiment("engines"))
    equal = load_experiment(find_experiment("engines_equal_budget"))
    assert [m.name for m in equal.methods] == [m.name for m in shipped.methods]
    for ours, theirs in zip(equal.methods, shipped.methods):
        # A virtual clipmap's memory is its page pool: it takes the most pages within the budget.
        size = "physical_pages" if ours.settings.shadow_map == "virtual_clipmap" else "resolution"
        assert ours.settings.replace(**{size: getattr(theirs.settings, size)}) == theirs.settings, ours.name
        memory = shadow_memory_bytes(ours.settings)
        assert 0.999 * BUDGET <= memory <= BUDGET, (ours.name, memory)
        assert shadow_memory_bytes(ours.settings.replace(**{size: getattr(ours.settings, size) + 1})) > BUDGET, \
            ours.name
