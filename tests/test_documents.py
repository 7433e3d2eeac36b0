"""The typed accessor of parsed documents: each read states what it expects and names the file and key otherwise.

Oracles: documents written here with a known value at a known key (and line), and the messages the
accessor must give for each wrong type — the JSON types a broken file holds at a key.
"""

from __future__ import annotations

import json
import sys

import numpy as np
import pytest

from csmlab.documents import MAX_JSON_DEPTH, Value, described, found_at, is_file, json_document, json_value, \
    within_limit
from csmlab.errors import InputError

DOCUMENT = {"nodes": [{"rotation": [0, 0, 0, 1], "name": "sun", "mesh": 1}], "scale": 2.5, "flag": True}


def _value(document=DOCUMENT):
    return json_value(json.dumps(document, indent=1), file="level.gltf", lines=True)


def test_a_value_read_as_what_it_is_comes_back():
    root = _value()
    node = root.at("nodes").items()[0].mapping()
    np.testing.assert_array_equal(node.at("rotation").numbers(4), [0, 0, 0, 1])
    assert node.at("name").text() == "sun" and node.at("mesh").index(2, "meshes") == 1
    assert root.at("scale").number(above=0) == 2.5 and root.at("flag").boolean() is True
    assert root.get("missing") is None and root.list_at("missing") == []


@pytest.mark.parametrize("read, key, expected, got", [
    (lambda r: r.at("scale").mapping(), "scale", "an object", "2.5"),
    (lambda r: r.at("nodes").mapping(), "nodes", "an object", "a list of 1 item"),
    (lambda r: r.at("scale").items(), "scale", "a list", "2.5"),
    (lambda r: r.at("flag").number(), "flag", "a finite number", "true"),
    (lambda r: r.at("nodes").items()[0].at("name").number(), "nodes[0].name", "a finite number", "the string 'sun'"),
    (lambda r: r.at("nodes").items()[0].at("mesh").index(1, "meshes"), "nodes[0].mesh",
     "an index into meshes in \\[0, 1\\)", "1"),
    (lambda r: r.at("scale").integer(), "scale", "an integer", "2.5"),
    (lambda r: r.at("scale").text(), "scale", "a string", "2.5"),
    (lambda r: r.at("nodes").items()[0].at("rotation").numbers(3), "nodes[0].rotation", "a list of 3 finite numbers",
     "a list of 4 item"),
    (lambda r: r.at("nodes").items()[0].at("name").text(("moon",)), "nodes[0].name", "one of 'moon'",
     "the string 'sun'"),
    (lambda r: r.at("scale").number(maximum=1.0), "scale", "a finite number ≤ 1", "2.5"),
])
def test_a_value_of_another_type_names_file_key_expected_and_got(read, key, expected, got):
    with pytest.raises(InputError, match=f"expected {expected}, got {got}") as info:
        read(_value())
    assert info.value.file == "level.gltf" and info.value.field == key
    assert str(info.value).startswith("level.gltf:") and f": {key}: expected" in str(info.value)


def test_a_missing_key_says_it_is_missing_and_a_null_says_null():
    root = _value({"a": None})
    with pytest.raises(InputError, match="b: expected a number, got no key 'b'"):
        root.at("b", "a number")
    with pytest.raises(InputError, match="a: expected a number, got null"):
        root.at("a", "a number")
    assert root.get("a") is None and not root.has("a")


@pytest.mark.parametrize("raw", [float("nan"), float("inf"), 10 ** 400, True, None, "1.0", [1.0], {"v": 1}])
def test_a_number_refuses_every_non_finite_or_non_number(raw):
    with pytest.raises(InputError):
        Value(raw, file="f.json", key="k").number()
    with pytest.raises(InputError):
        Value([0.0, raw], file="f.json", key="k").numbers(2)


def test_a_key_inside_an_object_carries_the_objects_line():
    root = _value()
    with pytest.raises(InputError) as info:
        root.at("nodes").items()[0].at("name").number()
    text = json.dumps(DOCUMENT, indent=1).splitlines()
    assert text[info.value.line - 1].strip() == "{"  # the node's opening brace
    assert '"name": "sun"' in "\n".join(text[info.value.line - 1:info.value.line + 12])


def test_nesting_deeper_than_the_limit_is_refused_before_parsing(tmp_path):
    deep = "[" * (MAX_JSON_DEPTH + 1) + "]" * (MAX_JSON_DEPTH + 1)
    assert sys.getrecursionlimit() > MAX_JSON_DEPTH + 1  # the limit sits below Python's own
    with pytest.raises(InputError, match=f"nested at most {MAX_JSON_DEPTH} deep"):
        json_value(deep, file="deep.json")
    json_value("[" * MAX_JSON_DEPTH + "]" * MAX_JSON_DEPTH, file="ok.json")
    # Brackets inside strings are text, not nesting.
    assert json_value(json.dumps({"s": "[" * 10_000}), file="s.json").at("s").text() == "[" * 10_000
    file = tmp_path / "bomb.json"
    file.write_text("[" * 100_000 + "]" * 100_000)
    with pytest.raises(InputError) as info:
        json_document(file)
    assert info.value.file == str(file) and info.value.line == 1


@pytest.mark.parametrize("text, match", [("{", "expected JSON"), ("1" * 5000, "expected JSON"),
                                         ("{\"a\": 1,}", "expected JSON")])
def test_text_that_is_not_json_names_the_file(text, match):
    with pytest.raises(InputError, match=match) as info:
        json_value(text, file="bad.json", lines=True)
    assert info.value.file == "bad.json"


def test_bytes_that_are_not_utf8_name_the_file_and_line(tmp_path):
    file = tmp_path / "latin.json"
    file.write_bytes(b'{\n"a": "\xe9"}')
    with pytest.raises(InputError, match="expected UTF-8 text") as info:
        json_document(file)
    assert info.value.line == 2


def test_a_limit_exceeded_names_the_limit_and_the_count():
    assert within_limit(5, 5, what="frames", file="f") == 5
    with pytest.raises(InputError, match="expected at most 5 frames .*Inputs.*, got 6"):
        within_limit(6, 5, what="frames", file="f", field="frames")


def test_names_no_file_system_holds_are_not_files(tmp_path):
    assert not is_file(tmp_path / ("x" * 1000)) and not is_file(str(tmp_path) + "/a\0b")
    assert found_at(tmp_path) == "a directory" and found_at(tmp_path / ("x" * 1000)).startswith("nothing")


def test_described_values_are_short():
    assert described("x" * 1000).endswith("…'") or len(described("x" * 1000)) < 80
    assert described(list(range(10 ** 4))) == "a list of 10000 item(s)"
    assert described({}) == "an empty object" and described(None) == "null" and described(False) == "false"
