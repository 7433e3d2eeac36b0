"""Every documented field fed its bad values: the loader answers with one located input error, never a crash.

The cases are generated from the schema (the records of :mod:`csmlab.config.records` and
:class:`~csmlab.settings.ShadowSettings`, their type hints and their own range checks: the edges of
each range found by bisection), loaded from small TOML files without running anything; a value the
loader takes must build the cascades of a frame.
"""

from __future__ import annotations

import dataclasses
import itertools
import json
import math
import re
import struct
import typing

import pytest
from typer.testing import CliRunner

from csmlab.cascades import build_cascades
from csmlab.cli import app
from csmlab.config import (CameraConfig, LightConfig, ReportConfig, SceneConfig, TuneConfig, field_docs,
                           load_experiment, shadow_method_registries)
from csmlab.errors import InputError
from csmlab.paths.generators import make_path
from csmlab.registry import parameters
from csmlab.settings import APPLIES, ShadowSettings

TINY = """
[scene]
kind = "plane_box"
[camera]
path = "walk"
frames = 2
width = 32
height = 18
[shadow]
cascades = 3
resolution = 64
"""


@pytest.mark.parametrize("splits, words", [
    ("[0.5, 0.2, 1.0]", "increasing"),
    ("[60.0, 20.0, 200.0]", "increasing"),
    ("[0.2, 0.5, 0.9]", "ending at 1.0"),
    ("[20.0, 60.0, 150.0]", "end at the shadow distance"),
    ("[0.0001, 0.5, 1.0]", "above near"),
])
def test_manual_splits_out_of_order_or_short_of_the_shadow_exit_2_naming_file_and_splits(tmp_path, splits, words):
    path = tmp_path / "exp.toml"
    path.write_text(TINY + f'split = "manual"\nsplits = {splits}\n')
    outcome = CliRunner().invoke(app, ["run", str(path), "--out", str(tmp_path / "out")])
    assert outcome.exit_code == 2, outcome.output
    message = outcome.stderr.strip()
    assert len(message.splitlines()) == 1 and "Traceback" not in outcome.output
    assert f"{path}:" in message and "shadow.splits" in message and words in message
    assert not (tmp_path / "out").exists()


@pytest.mark.parametrize("split", ['split = "manual"\nsplits = [0.001, 0.5, 1.0]',
                                   'split = "geometric"\nfirst_cascade_far = 0.2'])
def test_fixed_split_ends_over_the_visible_range_of_sdsm_exit_2_naming_bounds(tmp_path, split):
    path = tmp_path / "exp.toml"
    path.write_text(TINY + f'{split}\n[[methods]]\nname = "m"\nbounds = "sdsm"\n')
    outcome = CliRunner().invoke(app, ["run", str(path), "--out", str(tmp_path / "out")])
    assert outcome.exit_code == 2, outcome.output
    message = outcome.stderr.strip()
    assert len(message.splitlines()) == 1 and "Traceback" not in outcome.output
    assert f"{path}:" in message and "methods.m.bounds" in message and 'bounds = "frustum"' in message


# --- every documented field fed its bad values ---------------------------------------------------------

SECTIONS = {"scene": SceneConfig, "camera": CameraConfig, "light": LightConfig, "shadow": ShadowSettings,
            "report": ReportConfig, "tune": TuneConfig}
"""Each TOML table and the record its fields are documented on (``csmlab show``)."""
TOP = {"name": str, "description": str, "chunk_frames": int, "extends": tuple[str, ...]}
"""The top-level fields (``_DOCS_TOP`` documents them) and their types."""
TOP_REFUSED = {"name": ["two words"], "chunk_frames": [0, -1], "extends": [["no_such_preset"]]}
"""Values of the right type the loader refuses for a top-level field (no record holds their ranges)."""
PER_CASCADE = {"splits", "cascade_resolutions"}
"""List fields that hold one value per cascade: another length is wrong."""
ORDERED = {"splits"}
"""List fields whose values must rise: the reversed list is wrong."""
SIZES = {"memory_budget", "max_flicker"}
"""Fields that also take a string (``"64MiB"``, ``"best-preset"``): their wrong types are listed by hand."""
SCENE_CORNERS = [(x, y, z) for x in (-50.0, 50.0) for y in (0.0, 20.0) for z in (-50.0, 50.0)]
"""A scene's bounds for the cascades a taken value builds."""
MINIMAL = {"scene": {"kind": "plane_box"}, "camera": {"path": "walk", "frames": 2, "width": 32, "height": 18}}


def _toml(value) -> str:
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, float) and not math.isfinite(value):
        return "nan" if math.isnan(value) else ("inf" if value > 0 else "-inf")
    if isinstance(value, (list, tuple)):
        return "[" + ", ".join(_toml(v) for v in value) + "]"
    if isinstance(value, dict):
        return "{ " + ", ".join(f"{k} = {_toml(v)}" for k, v in value.items()) + " }"
    return json.dumps(value) if isinstance(value, str) else repr(value)


def _document(section: str | None, key: str, value, context: dict) -> str:
    document = {name: dict(table) for name, table in MINIMAL.items()}
    document.setdefault("shadow", {}).update(context)
    if section is None:
        document[key] = value
    else:
        document.setdefault(section, {})[key] = value
    top = [f"{k} = {_toml(v)}" for k, v in document.items() if not isinstance(v, dict)]
    tables = [f"[{k}]\n" + "".join(f"{n} = {_toml(v)}\n" for n, v in t.items())
              for k, t in document.items() if isinstance(t, dict)]
    return "\n".join(top) + "\n" + "\n".join(tables)


def _plain(kind):
    args = typing.get_args(kind)
    return next(a for a in args if a is not type(None)) if type(None) in args else kind


def _accepts(record, name: str):
    """Whether ``record``'s own range checks (``validated``) take a value for ``name``, as a function of it."""
    def accepts(value) -> bool:
        try:
            dataclasses.replace(record, **{"lambda_" if name == "lambda" else name: value}).validated()
        except ValueError:
            return False
        return True
    return accepts


def _ordered(x: float) -> int:
    """An integer that orders floats as their values do (adjacent floats are adjacent integers)."""
    bits = struct.unpack("<q", struct.pack("<d", x))[0]
    return bits if bits >= 0 else -(bits & 0x7FFF_FFFF_FFFF_FFFF)


def _float(n: int) -> float:
    return struct.unpack("<d", struct.pack("<Q", n if n >= 0 else -n | 1 << 63))[0]


def _edges(accepts, start, kind) -> list:
    """``(inside, outside)``: the last value ``accepts`` takes and the first it refuses on each side of ``start``,
    by bisection (no pair on a side where it takes everything)."""
    to, back = (int, int) if kind is int else (_ordered, _float)
    out = []
    for far in ((-10**12, 10**12) if kind is int else (-1e300, 1e300)):
        if not accepts(start) or accepts(far):
            continue
        inside, outside = to(start), to(far)
        while abs(outside - inside) > 1:
            middle = (inside + outside) // 2
            inside, outside = (middle, outside) if accepts(back(middle)) else (inside, middle)
        out.append((back(inside), back(outside)))
    return out


def _context(key: str) -> dict:
    """``[shadow]`` fields under which ``key`` applies (:data:`APPLIES`), so that its own check is what answers."""
    rule = APPLIES.get(key)
    if rule is None:
        return {}
    registries = shadow_method_registries()
    defaults = ShadowSettings()
    quoted = re.findall(r'"([^"]+)"', rule.when)
    choices = {name: list(registries[name]) if name in registries else
               [True, False] if isinstance(getattr(defaults, name), bool) else
               [getattr(defaults, name), *quoted] if isinstance(getattr(defaults, name), str) else
               [getattr(defaults, name), 0.1] if isinstance(getattr(defaults, name), float) else
               [getattr(defaults, name)] for name in parameters(rule.test)}
    return next(point for point in (dict(zip(choices, values)) for values in itertools.product(*choices.values()))
                if rule.holds(defaults.replace(**point)))


def _sample(name: str, element) -> list:
    """A valid list of ``element``s for the list field ``name`` (one per default cascade in PER_CASCADE)."""
    count = ShadowSettings().cascades if name in PER_CASCADE else 2
    if element is float:
        return [(i + 1) / count for i in range(count)]
    return [64] * count if element is int else ["flicker"] * count


def _element_edges(accepts, value: tuple, kind) -> list:
    """``(value, refused)``: lists with one element of ``value`` at an edge of its range, the others kept."""
    out = []
    for i, start in enumerate(value):
        def swap(x, i=i):
            return [*value[:i], x, *value[i + 1:]]
        for inside, outside in _edges(lambda x, swap=swap: accepts(tuple(swap(x))), start, kind):
            out += [(swap(inside), False), (swap(outside), True)]
    return out


def _field_cases(name: str, kind, record, default):
    """``(value, refused)`` pairs for one field: ``refused`` where the loader must refuse the value."""
    origin, args = typing.get_origin(kind), typing.get_args(kind)
    accepts = _accepts(record, name) if record is not None else None
    wrong = [True, [1], {"a": 1}]
    if name in SIZES:
        yield from [(v, True) for v in (True, math.nan, math.inf, -math.inf, [1])]
        yield from [(v, False) for v in ("64MiB", "x", 0, -1, 1.5)]
        return
    if kind is int:
        yield from [(v, True) for v in ("1", 1.5, math.nan, math.inf, -math.inf, *wrong)]
        yield from [(v, False) for v in (-10**12, -1, 0, 1, 10**12)]
    elif kind is float:
        yield from [(v, True) for v in ("1.0", math.nan, math.inf, -math.inf, *wrong)]
        yield from [(v, False) for v in (-1e300, -1.0, -5e-324, 0.0, 5e-324, 1.0, 1e300)]
    elif kind is bool:
        yield from [(v, True) for v in (1, "true", 1.5, [True])]
    elif kind is str:
        yield from [(v, True) for v in (1, 1.0, *wrong)]
        yield from [(v, False) for v in ("", "no_such_name")]
    elif origin is tuple and args[-1] is not Ellipsis:
        n = len(args)
        yield from [(v, True) for v in (1.0, ["a"] * n, [1.0] * (n - 1), [1.0] * (n + 1), [math.nan] * n,
                                        [math.inf] * n, [-math.inf] * n)]
        yield from [(v, False) for v in ([0.0] * n, [1.0] * n, [-1.0] * n)]
        if default is not None and accepts is not None:
            yield from _element_edges(accepts, default, float)
            yield (list(default[::-1]), not accepts(default[::-1]))
    elif origin is tuple:
        element = args[0]
        sample = _sample(name, element)
        yield from [(v, True) for v in (1.0, [True], [[1]], *([[math.nan], [math.inf]] if element is float else []))]
        yield (sample, False)
        yield (sample[::-1], name in ORDERED or accepts is not None and not accepts(tuple(sample[::-1])))
        if name in PER_CASCADE:
            yield from [(sample[:-1], True), (sample + sample[-1:], True)]
        if element in (int, float) and accepts is not None:
            yield from _element_edges(accepts, tuple(sample), element)
    else:
        raise AssertionError(f"{name}: no bad values for {kind}")
    if kind in (int, float) and accepts is not None:
        for inside, outside in _edges(accepts, default if default is not None else kind(1), kind):
            yield from [(inside, False), (outside, True)]


def _cases():
    """``(section, field, value, refused, context)`` for every documented field of every table, and the top."""
    for section, cls in SECTIONS.items():
        record, hints = cls(), typing.get_type_hints(cls)
        for name in field_docs(cls):
            if name in ("space", "params"):
                continue
            attribute = "lambda_" if name == "lambda" else name
            for value, refused in _field_cases(name, _plain(hints[attribute]), record, getattr(record, attribute)):
                yield section, name, value, refused, _context(name) if section == "shadow" else {}
    for name, kind in TOP.items():
        for value, refused in [*_field_cases(name, kind, None, None), *((v, True) for v in TOP_REFUSED.get(name, ()))]:
            yield None, name, value, refused, {}
    for value in ("x", {"abs": "x"}, {"abs": math.nan}, {"rel": math.inf}, {"abs": -5e-324}, {"rel": -1.0},
                  {"abx": 1.0}):
        yield "regress", "flicker", value, True, {}


CASES = list(_cases())


def _id(case) -> str:
    section, name, value, refused, _ = case
    return f"{section + '.' if section else ''}{name}={_toml(value)}{'' if refused else '?'}"


@pytest.mark.parametrize("section, name, value, refused, context", CASES, ids=[_id(c) for c in CASES])
def test_every_field_refuses_its_bad_values_naming_file_and_field_never_crashing(tmp_path, section, name, value,
                                                                                 refused, context):
    path = tmp_path / "exp.toml"
    path.write_text(_document(section, name, value, context))
    try:
        experiment = load_experiment(path)
    except InputError as exc:
        assert exc.file == str(path) and name in (exc.field or "") + exc.detail, str(exc)
        return
    assert not refused, f"{_id((section, name, value, refused, context))} was taken"
    # What the loader takes, a frame takes too: the cascades of the first pose build.
    camera = experiment.camera
    pose = make_path(camera.path, frames=1, fov_y_deg=camera.fov_y_deg, aspect=camera.aspect, near=camera.near,
                     far=camera.far).pose(0)
    for method in experiment.methods:
        build_cascades(pose=pose, light_direction=(0.3, -0.8, 0.5), scene_corners=SCENE_CORNERS,
                       settings=method.settings)


def test_the_cases_cover_every_documented_field_and_each_has_one_that_must_be_refused():
    covered = {(section, name) for section, name, _, refused, _ in CASES if refused}
    documented = {(section, name) for section, cls in SECTIONS.items() for name in field_docs(cls)
                  if name not in ("space", "params")}
    assert documented | {(None, name) for name in TOP} <= covered
    assert len(CASES) > 300


@pytest.mark.parametrize("section, name, value", [
    ("shadow", "lambda", math.nan), ("camera", "width", 8.5), ("light", "direction", [1.0, 0.0]),
    ("report", "snapshot_frames", [-1]), ("tune", "trials", 0), ("scene", "offset", [math.inf, 0.0, 0.0])])
def test_the_command_line_exits_2_with_one_line_for_a_generated_case(tmp_path, section, name, value):
    path = tmp_path / "exp.toml"
    path.write_text(_document(section, name, value, {}))
    outcome = CliRunner().invoke(app, ["show", str(path)])
    assert outcome.exit_code == 2 and "Traceback" not in outcome.output
    message = outcome.stderr.strip()
    assert len(message.splitlines()) == 1 and f"{path}:" in message and f"{section}.{name}" in message
