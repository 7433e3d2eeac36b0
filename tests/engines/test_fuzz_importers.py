"""Every engine importer, fuzzed: each variant of a shipped engine file imports or exits 2 naming the file.

The good files are the fixtures of tests/data/engines/ (and, when present, the real ones of
/work/shared/data/engines/: Godot's demo projects, a URP template's asset). Each is fuzzed two ways
with the harness of tests/fuzzing.py (seeded, a fixed number of variants per file):

- its parsed tree: every value replaced by each other type (list, map, string, number, null, NaN,
  huge), keys deleted, values nested one level deeper (:func:`tests.fuzzing.json_variants`), and the
  tree written back in the engine's own format — Unity YAML, Stride's tagged YAML, RON, Godot's
  ConfigFile, Unreal's ini and T3D (JSON for three.js and Filament);
- its text: tokens replaced, lines deleted or repeated, bytes inserted, truncated, re-encoded
  (:func:`tests.fuzzing.text_variants`).

The property, for every variant: ``import_settings`` returns and the preset it makes (``preset_toml``, what
``csmlab import`` writes) parses as TOML, or an InputError naming a file of the variant's folder is raised —
never another exception, never a NumPy warning. :data:`TRIED` counts the variants per importer
(printed with ``-s``).
"""

from __future__ import annotations

import json
import math
import os
import re
import tomllib
from pathlib import Path

import pytest
import yaml
from tests.engines.engine_cases import DATA

from csmlab.engines import import_settings, preset_toml
from csmlab.errors import InputError
from tests.fuzzing import fuzz_reader, json_variants, text_variants

pytestmark = pytest.mark.fuzz

EXAMPLES = int(os.environ.get("CSMLAB_FUZZ_EXAMPLES", "40"))
"""Variants per file and way (tree, text); ``CSMLAB_FUZZ_EXAMPLES=1000`` searches deeper."""
SHARED = Path("/work/shared/data/engines")
TRIED: dict[str, int] = {}
"""Variants tried per importer, filled as the tests run."""


# -- the engines' formats written from a tree --------------------------------------------------------------------

def _scalar_text(value) -> str:
    """A tree's leaf as a text format spells it (a string as itself, anything else as JSON)."""
    return value if isinstance(value, str) else json.dumps(value, allow_nan=True)


def _unity(tree) -> str:
    """A Unity asset of the documents ``tree`` ``[[marker, {type: fields}], …]``."""
    lines = ["%YAML 1.1", "%TAG !u! tag:unity3d.com,2011:"]
    for entry in tree if isinstance(tree, list) else [tree]:
        marker, document = entry if isinstance(entry, list) and len(entry) == 2 and isinstance(entry[0], str) \
            else ("--- !u!114 &11400000", entry)
        lines += [marker, yaml.safe_dump(document, default_flow_style=False, allow_unicode=True).rstrip("\n")]
    return "\n".join(lines) + "\n"


def _unity_tree(text: str) -> list:
    markers = re.findall(r"^--- .*$", text, re.M)
    documents = yaml.safe_load_all(re.sub(r"^--- .*$", "---", text, flags=re.M))
    return [[marker, document] for marker, document in zip(markers, [d for d in documents if d is not None])]


class _TaggedMapping(dict):
    tag = ""


def _stride_dumper():
    class Dumper(yaml.SafeDumper):
        pass

    Dumper.add_representer(_TaggedMapping, lambda dumper, data: dumper.represent_mapping("!" + data.tag, dict(data)))
    return Dumper


def _stride_tree(value):
    """Stride's asset YAML as a JSON tree: a tagged mapping's tag as its key ``"!"``."""
    from csmlab.engines.stride import _StrideLoader

    def plain(node):
        if isinstance(node, dict):
            out = {str(k): plain(v) for k, v in node.items()}
            if getattr(node, "tag", ""):
                out["!"] = node.tag
            return out
        if isinstance(node, list):
            return [plain(v) for v in node]
        return node

    return plain(yaml.load(value, Loader=_StrideLoader))


def _stride(tree) -> str:
    def tagged(node):
        if isinstance(node, dict):
            mapping = {k: tagged(v) for k, v in node.items() if not (k == "!" and isinstance(v, str))}
            if isinstance(node.get("!"), str):
                mapping = _TaggedMapping(mapping)
                mapping.tag = node["!"]
            return mapping
        if isinstance(node, list):
            return [tagged(v) for v in node]
        return node

    return yaml.dump(tagged(tree), Dumper=_stride_dumper(), default_flow_style=False, allow_unicode=True)


def _ron(value) -> str:
    """A tree as RON: an object of identifier keys as a struct, of other keys as a map."""
    if isinstance(value, dict):
        if value and all(isinstance(k, str) and k.isidentifier() for k in value):
            return "(" + ", ".join(f"{k}: {_ron(v)}" for k, v in value.items()) + ")"
        return "{" + ", ".join(f"{_ron(_map_key(k))}: {_ron(v)}" for k, v in value.items()) + "}"
    if isinstance(value, list):
        return "[" + ", ".join(_ron(v) for v in value) + "]"
    if isinstance(value, bool):
        return "true" if value else "false"
    if value is None:
        return "None"
    if isinstance(value, float) and not math.isfinite(value):
        return "NaN" if math.isnan(value) else ("inf" if value > 0 else "-inf")
    if isinstance(value, str):
        return value if value.isidentifier() else json.dumps(value, ensure_ascii=False)
    return repr(value)


def _map_key(key: str):
    """A RON map key: an entity id (JSON made it text) as its number, a type path as a string."""
    return int(key) if key.isdigit() else key


def _config_tree(text: str, *, separator: str) -> dict:
    """A ConfigFile or ini text as ``{header line: {key: value text}}`` (lines before the first header: ``""``)."""
    tree, section, key = {"": {}}, "", None
    for line in text.splitlines():
        stripped = line.strip()
        if key is not None:  # a string still open: the value goes on
            tree[section][key] += "\n" + line
            key = key if line.count('"') % 2 == 0 else None
        elif stripped.startswith("[") and stripped.endswith("]"):
            section = stripped
            tree[section] = {}
        elif separator in stripped and not stripped.startswith((";", "#")):
            key, value = stripped.split(separator, 1)
            key = key.strip()
            tree[section][key] = value.strip()
            key = key if value.count('"') % 2 else None
    return tree


def _config(tree, *, separator: str) -> str:
    lines = []
    for header, body in (tree.items() if isinstance(tree, dict) else [("", tree)]):
        if header:
            lines.append(header)
        pairs = body.items() if isinstance(body, dict) else [("value", body)]
        lines += [f"{key}{separator}{_scalar_text(value)}" for key, value in pairs]
    return "\n".join(lines) + "\n"


_T3D_PROPERTY = re.compile(r"^(\s*)(\w+)=(.*)$")


def _t3d_tree(text: str) -> dict:
    return {m.group(2): m.group(3) for m in map(_T3D_PROPERTY.match, text.splitlines()) if m}


def _t3d(template: str):
    """T3D text: ``template``'s lines with its ``Key=Value`` properties replaced by a tree's."""
    def write(tree) -> str:
        skeleton = [line for line in template.splitlines() if not _T3D_PROPERTY.match(line)]
        at = next(i for i, line in enumerate(skeleton) if line.strip().startswith("Begin Object Name="))
        pairs = tree.items() if isinstance(tree, dict) else [("Value", tree)]
        properties = [f"            {key}={_scalar_text(value)}" for key, value in pairs]
        return "\n".join(skeleton[:at + 1] + properties + skeleton[at + 1:]) + "\n"

    return write


def _written(write):
    """``json_variants``' encoder: the variant's JSON text written by ``write`` (a truncated text as it is)."""
    def encode(text: str) -> bytes:
        try:
            tree = json.loads(text)
        except ValueError:
            return text.encode("utf-8")
        return write(tree).encode("utf-8")

    return encode


# -- the importers and their files ------------------------------------------------------------------------------

def _fixture(engine: str, name: str) -> str:
    return (DATA / engine / name).read_text(encoding="utf-8")


def _engine_files(engine: str, names) -> dict[str, bytes]:
    return {name: (DATA / engine / name).read_bytes() for name in names}


def _importer(engine: str, names):
    """``read(path)``: ``engine``'s importer given the files ``names`` of the variant's folder, and the preset."""
    def read(path: Path) -> None:
        files = [path.parent / name for name in names]
        imported = import_settings(files, engine=engine)
        # What csmlab import writes must be TOML: a line break in a file's string must not end a comment.
        tomllib.loads(preset_toml(imported, name="fuzzed", files=files))

    return read


TREES = {
    "threejs_csm": (json.loads, lambda tree: json.dumps(tree, indent=2, allow_nan=True)),
    "filament": (json.loads, lambda tree: json.dumps(tree, indent=4, allow_nan=True)),
    "unity_urp": (_unity_tree, _unity),
    "unity_builtin": (_unity_tree, _unity),
    "stride": (_stride_tree, _stride),
    "bevy": (None, _ron),
    "godot4": (lambda text: _config_tree(text, separator="="), lambda tree: _config(tree, separator=" = ")),
    "ue5": (lambda text: _config_tree(text, separator="="), lambda tree: _config(tree, separator="=")),
}
"""Per engine: its text as a JSON tree, and a tree as its text."""

CASES = [
    ("threejs_csm", ["csm.json"], "csm.json"),
    ("filament", ["settings.json"], "settings.json"),
    ("unity_urp", ["UniversalRP-HighQuality.asset"], "UniversalRP-HighQuality.asset"),
    ("unity_builtin", ["QualitySettings.asset"], "QualitySettings.asset"),
    ("stride", ["MainScene.sdscene"], "MainScene.sdscene"),
    ("bevy", ["sun.scn.ron"], "sun.scn.ron"),
    ("godot4", ["project.godot", "level.tscn"], "project.godot"),
    ("godot4", ["project.godot", "level.tscn"], "level.tscn"),
    ("ue5", ["DefaultEngine.ini", "DefaultScalability.ini", "DirectionalLight.t3d"], "DefaultEngine.ini"),
    ("ue5", ["DefaultEngine.ini", "DefaultScalability.ini", "DirectionalLight.t3d"], "DefaultScalability.ini"),
    ("ue5", ["DefaultEngine.ini", "DefaultScalability.ini", "DirectionalLight.t3d"], "DirectionalLight.t3d"),
]
"""``(engine, the files it is given, the file fuzzed)``."""


def _tree_and_writer(engine: str, target: str, text: str):
    if engine == "bevy":
        from csmlab.engines.ron import parse_ron

        return json.loads(json.dumps(parse_ron(text))), _ron
    if target.endswith(".t3d"):
        return _t3d_tree(text), _t3d(text)
    parse, write = TREES[engine]
    return json.loads(json.dumps(parse(text), default=str)), write


def _fuzzed(name: str, engine: str, files: dict[str, bytes], target: str) -> dict:
    text = files[target].decode("utf-8")
    tree, write = _tree_and_writer(engine, target, text)
    counts = {}
    for way, variants in (("tree", json_variants(tree, encode=_written(write))), ("text", text_variants(text))):
        outcome = fuzz_reader(_importer(engine, list(files)), files, target, variants, examples=EXAMPLES)
        counts[way] = outcome
        assert sum(outcome.values()) >= EXAMPLES // 2
    TRIED[name] = sum(sum(c.values()) for c in counts.values())
    loaded = sum(c["loaded"] for c in counts.values())
    refused = sum(c["refused"] for c in counts.values())
    print(f"fuzz {name}: {TRIED[name]} variants, {loaded} imported, {refused} refused (exit 2)")
    # A fuzzer whose variants all import, or all fail, tests nothing.
    assert loaded and refused, counts
    return counts


@pytest.mark.parametrize("engine, names, target", CASES, ids=[f"{e}-{t}" for e, _, t in CASES])
def test_every_variant_of_an_engine_file_imports_or_exits_2_naming_the_file(engine, names, target):
    _fuzzed(f"{engine} {target}", engine, _engine_files(engine, names), target)


@pytest.mark.parametrize("engine, folder, names, target", [
    ("godot4", "godot_lights_and_shadows", ["project.godot", "test.tscn"], "test.tscn"),
    ("godot4", "godot_global_illumination", ["project.godot", "test.tscn"], "project.godot"),
    ("unity_urp", "unity_urp_highfidelity", ["URP-HighFidelity.asset"], "URP-HighFidelity.asset"),
])
def test_every_variant_of_a_file_an_engine_wrote_imports_or_exits_2(engine, folder, names, target):
    if not (SHARED / folder).is_dir():
        pytest.skip(f"{SHARED / folder} absent (/work/shared/data/README)")
    files = {name: (SHARED / folder / name).read_bytes() for name in names}
    _fuzzed(f"{engine} {folder}/{target}", engine, files, target)


def test_the_fuzzers_trees_write_back_the_files_they_came_from(tmp_path):
    # The tree way fuzzes the engine's format only if an untouched tree imports as the file does.
    for engine, names, target in CASES:
        files = _engine_files(engine, names)
        tree, write = _tree_and_writer(engine, target, files[target].decode("utf-8"))
        folder = tmp_path / f"{engine}-{target}"
        folder.mkdir()
        for name, data in files.items():
            (folder / name).write_bytes(data)
        original = import_settings([folder / n for n in names], engine=engine).settings
        (folder / target).write_text(write(tree), encoding="utf-8")
        assert import_settings([folder / n for n in names], engine=engine).settings == original, (engine, target)


# -- through the CLI ---------------------------------------------------------------------------------------------

def _csmlab_import(engine: str, files, out: Path):
    from typer.testing import CliRunner

    from csmlab.cli import app

    return CliRunner().invoke(app, ["import", engine, *map(str, files), "--out", str(out)])


def _replaced_in(engine: str, name: str, old: str, new: str) -> str:
    text = _fixture(engine, name)
    assert old in text, (engine, name, old)
    return text.replace(old, new)


BAD = [
    # The classes of issue 42: a list where the format has a member set or a word, a bad RON escape, deep JSON.
    ("unity_urp", "urp.asset", lambda: _replaced_in("unity_urp", "UniversalRP-HighQuality.asset",
                                                     "m_Cascade3Split: {x: 0.1, y: 0.3}",
                                                     "m_Cascade3Split: [0.1, 0.3]"),
     "urp.asset:40: m_Cascade3Split: expected {x: …, y: …}, got a list of 2 item(s)"),
    ("threejs_csm", "csm.json", lambda: '{"cascades": 3, "mode": ["practical"]}',
     "csm.json:1: mode: expected one of 'uniform', 'logarithmic', 'practical', 'custom', got a list of 1 item(s)"),
    ("bevy", "sun.scn.ron", lambda: _replaced_in("bevy", "sun.scn.ron", '"Sun"', '"Sun\\q"'),
     "sun.scn.ron:10: expected a string escape"),
    ("bevy", "sun.scn.ron", lambda: _replaced_in("bevy", "sun.scn.ron", '"bevy_ecs::name::Name": "Camera",\n'
                                                 '        "bevy_light::ShadowFilteringMethod": Hardware2x2,\n      }',
                                                 '"Camera", Hardware2x2]').replace("components: {\n        \"Camera\"",
                                                                                   "components: [\n        \"Camera\""),
     "sun.scn.ron:37: entities[4294967297].components: expected components by type path, got a list of 2 item(s)"),
    ("stride", "scene.sdscene", lambda: _replaced_in(
        "stride", "MainScene.sdscene", "BiasParameters:\n" + " " * 36 + "DepthBias: 0.001\n" + " " * 36
        + "NormalOffsetScale: 4.0", "BiasParameters: [0.001, 4.0]"),
     "scene.sdscene:74: Sun.Shadow.BiasParameters: expected the BiasParameters members, got a list of 2 item(s)"),
    ("filament", "settings.json", lambda: "[" * 100_000, "settings.json:1: expected JSON nested at most 64 deep"),
    ("ue5", "DefaultEngine.ini", lambda: "[SystemSettings]\nr.Shadow.MaxCSMResolution\n",
     "DefaultEngine.ini: [SystemSettings] r.Shadow.MaxCSMResolution: expected an integer ≥ 1, got null"),
]
"""``(engine, file name, its text, what the one line of exit 2 says after the folder)``."""


@pytest.mark.parametrize("engine, name, text, message", BAD, ids=[f"{e}-{m.split(':')[0]}" for e, _, _, m in BAD])
def test_cli_import_of_a_wrongly_shaped_file_exits_2_naming_file_line_and_key(engine, name, text, message, tmp_path):
    path = tmp_path / name
    path.write_text(text(), encoding="utf-8")
    outcome = _csmlab_import(engine, [path], tmp_path / "out.toml")
    assert outcome.exit_code == 2, outcome.output
    assert outcome.output.startswith(f"csmlab: error: {tmp_path / message}") and outcome.output.count("\n") == 1, \
        outcome.output
    assert not (tmp_path / "out.toml").exists()


def test_cli_import_of_fuzzed_engine_files_exits_0_or_2_with_one_line_naming_the_file():
    # What the importers let through, csmlab's own checks then refuse (a resolution above 16384, …): the CLI names
    # the engine's file for those too, and writes a preset only for a file it takes.
    def read_with_the_cli(engine: str, names):
        def read(path: Path) -> None:
            out = path.parent / "fuzzed.toml"
            out.unlink(missing_ok=True)
            outcome = _csmlab_import(engine, [path.parent / name for name in names], out)
            if outcome.exit_code == 2 and outcome.output.count("\n") == 1 and str(path.parent) in outcome.output:
                assert not out.exists()
                raise InputError(outcome.output, file=path)
            assert outcome.exit_code == 0 and out.is_file(), (outcome.exit_code, outcome.output, outcome.exception)

        return read

    examples = max(EXAMPLES // 4, 4)
    for engine, names, target in CASES[:8]:
        files = _engine_files(engine, names)
        tree, write = _tree_and_writer(engine, target, files[target].decode("utf-8"))
        counts = fuzz_reader(read_with_the_cli(engine, names), files, target,
                             json_variants(tree, encode=_written(write)), examples=examples)
        TRIED[f"csmlab import {engine} {target}"] = sum(counts.values())
        print(f"fuzz csmlab import {engine} {target}: {sum(counts.values())} variants, {counts['loaded']} imported, "
              f"{counts['refused']} refused (exit 2)")
        assert sum(counts.values()) >= examples // 2


def _laughs(indent: str, last: str) -> str:
    """YAML anchors of 9⁹ strings by reference (``billion laughs``), the last one's alias at key ``last``."""
    lines = [f"{indent}m_Laugh0: &l0 [{', '.join(['lol'] * 9)}]"]
    lines += [f"{indent}m_Laugh{k}: &l{k} [{', '.join([f'*l{k - 1}'] * 9)}]" for k in range(1, 9)]
    return "\n".join(lines + [f"{indent}{last}: *l8"]) + "\n"


YAML_CASES = [
    ("unity_urp", "UniversalRP-HighQuality.asset", "  m_CascadeBorder: 0.1\n",
     "  m_CascadeBorder: 0.1\n" + _laughs("  ", "m_ShadowType"),
     "m_ShadowType: expected a finite number, got a list of 9 item(s)"),
    ("unity_urp", "UniversalRP-HighQuality.asset", "  m_ShadowDistance: 100\n", "  m_ShadowDistance: 2001-13-01\n",
     "expected valid YAML, got ValueError: month must be in 1..12"),
    ("stride", "MainScene.sdscene", "Tags: []\n", "Tags: " + "[" * 5000 + "]" * 5000 + "\n",
     "expected Stride asset YAML, got RecursionError"),
    ("stride", "MainScene.sdscene", " " * 36 + "DepthBias: 0.001\n",
     _laughs(" " * 36, "DepthBias"), "Sun.Shadow.BiasParameters.DepthBias: expected a finite number ≥ 0, got a list"),
]
"""What PyYAML builds that JSON cannot hold: aliases to 9⁹ strings, a date that is none, nesting past Python's stack."""


@pytest.mark.parametrize("engine, name, old, new, message", YAML_CASES, ids=[m.split(":")[0] for *_, m in YAML_CASES])
def test_yaml_that_pyyaml_builds_oddly_exits_2_naming_the_file(engine, name, old, new, message, tmp_path):
    path = tmp_path / name
    path.write_text(_replaced_in(engine, name, old, new), encoding="utf-8")
    with pytest.raises(InputError) as caught:
        import_settings([path], engine=engine)
    assert caught.value.file == str(path) and message in str(caught.value), str(caught.value)


def test_an_entry_reads_numbers_as_text_formats_spell_them_and_names_the_line_of_its_key():
    from csmlab.engines.reading import Entry, yaml_document

    document = Entry(yaml_document("a:\n  size: '2048'\n  scale: 0.5f\n  count: 4.0\n  word: big\n  list: [1]\n",
                                   file="f.asset"), file="f.asset")
    members = document.at("a")
    assert members.at("size").integer(minimum=1) == 2048 and members.at("scale").number() == 0.5
    assert members.at("count").integer() == 4
    with pytest.raises(InputError, match=r"^f\.asset:5: a\.word: expected a finite number, got the string 'big'$"):
        members.at("word").number()
    with pytest.raises(InputError, match=r"^f\.asset:6: a\.list: expected one of 'x', got a list of 1 item\(s\)$"):
        members.at("list").choice({"x": 1})
    with pytest.raises(InputError, match=r"^f\.asset:4: a\.count: expected an integer ≥ 5, got 4"):
        members.at("count").integer(minimum=5)
