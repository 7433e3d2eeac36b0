"""The registry protocol: one name check with a close-match hint, dispatch by declared keywords."""

import subprocess
import sys
from pathlib import Path

import pytest

from csmlab.registry import check_name, dispatch, parameters

ROOT = Path(__file__).resolve().parents[1]


def _registries():
    from csmlab.cascades import EXTENT_METHODS, FIT_METHODS, SNAP_METHODS, SPLIT_METHODS, STABILIZATION_METHODS
    from csmlab.engines import EXPORT_METHODS
    from csmlab.executor import EXECUTORS
    from csmlab.paths import PATH_GENERATORS
    from csmlab.scene import SCENE_KINDS

    return {"split": SPLIT_METHODS, "fit": FIT_METHODS, "stabilization": STABILIZATION_METHODS,
            "snap": SNAP_METHODS, "extent": EXTENT_METHODS, "engine": EXPORT_METHODS, "executor": EXECUTORS,
            "path": PATH_GENERATORS, "scene": SCENE_KINDS}


def test_an_unknown_name_names_the_field_lists_the_valid_names_and_the_closest():
    with pytest.raises(ValueError) as caught:
        check_name("practcal", {"uniform": 0, "log": 1, "practical": 2}, field="split")
    assert str(caught.value) == ("split: expected one of ['log', 'practical', 'uniform'], got 'practcal' "
                                 "(did you mean 'practical'?)")
    with pytest.raises(ValueError, match=r"got 'zzz'$"):
        check_name("zzz", {"uniform": 0}, field="split")


def test_dispatch_passes_a_method_only_the_keywords_it_declares():
    seen = {}

    def one(x, *, a):
        seen["one"] = (x, a)
        return "one"

    def two(x, *, a, b):
        seen["two"] = (x, a, b)
        return "two"

    registry = {"one": one, "two": two}
    assert dispatch(registry, "one", 5, field="f", a=1, offered={"b": 2}) == "one"
    assert dispatch(registry, "two", 6, field="f", a=1, offered={"b": 2}) == "two"
    assert seen == {"one": (5, 1), "two": (6, 1, 2)}
    with pytest.raises(ValueError, match=r"one: unknown parameter\(s\) \['b'\]; expected some of \['a', 'x'\]"):
        dispatch(registry, "one", 5, field="f", a=1, b=2)
    with pytest.raises(TypeError, match=r"f: no method of the registry takes \['c'\]"):
        dispatch(registry, "one", 5, field="f", a=1, offered={"c": 3})
    with pytest.raises(ValueError, match="did you mean 'two'"):
        dispatch(registry, "tow", 5, field="f", a=1)


def test_a_method_taking_kwargs_is_refused():
    def swallow(*, a, **_unused):
        return a

    with pytest.raises(TypeError, match="declares its keywords"):
        parameters(swallow)


@pytest.mark.parametrize("field", sorted(_registries()))
def test_every_registered_method_declares_its_keywords(field):
    for function in _registries()[field].values():
        assert all(isinstance(name, str) for name in parameters(function))  # raises on **kwargs


def test_a_split_scheme_gets_only_its_own_parameter():
    from csmlab.cascades import split_distances

    # practical ignores splits; manual reads them: a wrong-length list breaks only manual.
    z = split_distances(near=1.0, far=100.0, count=2, method="practical", lambda_=0.0, splits=(5.0,))
    assert z.tolist() == [1.0, 50.5, 100.0]
    with pytest.raises(ValueError, match="splits: expected 2 far ends"):
        split_distances(near=1.0, far=100.0, count=2, method="manual", splits=(5.0,))


def test_loading_an_experiment_does_not_import_warp():
    code = ("import sys\n"
            "from csmlab.config import load_experiment\n"
            f"e = load_experiment({str(ROOT / 'experiments' / 'default.toml')!r})\n"
            "assert e.methods\n"
            "print('warp' in sys.modules)\n")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True, cwd=ROOT)
    assert out.stdout.strip() == "False", out.stderr
