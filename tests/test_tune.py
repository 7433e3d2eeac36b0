"""Tuning: the best trial is the best measured, a Pareto front is undominated, the search repeats."""

from __future__ import annotations

import json
import math

import pytest

from csmlab.config import load_experiment
from csmlab.errors import InputError
from csmlab.settings import ShadowSettings
from csmlab.tune import objective_direction, parse_space, tune

TINY = """
name = "tiny_tune"
extends = ["methods/none"]

[scene]
kind = "terrain"
resolution = 24
trees = 60
ring_trees = 60

[camera]
path = "walk"
frames = 3
width = 48
height = 27

[shadow]
cascades = 2
resolution = 128
shadow_distance = 40.0
"""


@pytest.fixture(scope="module")
def experiment(tmp_path_factory):
    path = tmp_path_factory.mktemp("tune") / "tiny.toml"
    path.write_text(TINY)
    return load_experiment(path)


def _space():
    return parse_space(["resolution=64,128,256", "lambda=0.3:0.9"], settings=ShadowSettings())


def test_single_objective_reports_the_best_measured_trial(experiment, tmp_path):
    result = tune(experiment, space=_space(), objectives=["flicker"], trials=4, out_dir=tmp_path)
    values = [t.values["flicker"] for t in result.trials]
    assert len(values) == 4 and len(result.best) == 1
    assert result.best[0].values["flicker"] == min(values)
    for t in result.trials:
        assert t.params["resolution"] in (64, 128, 256) and 0.3 <= t.params["lambda"] <= 0.9
    document = json.loads((tmp_path / "tune.json").read_text())
    assert [t["values"]["flicker"] for t in document["trials"]] == values


def _badness(value, better):
    """The oracle of "better", written out: lower, higher, or closer to 1 on a log scale."""
    return {"lower": value, "higher": -value, "one": abs(math.log(value))}[better]


def _dominates(a, b, goals) -> bool:
    worse = [_badness(a[m], d) - _badness(b[m], d) for m, d in goals]
    return all(w <= 0 for w in worse) and any(w < 0 for w in worse)


def test_several_objectives_give_an_undominated_front(experiment, tmp_path):
    result = tune(experiment, space=_space(), objectives=["flicker", "rho_median"], trials=5, out_dir=tmp_path)
    goals = result.objectives
    assert goals == (("flicker", "lower"), ("rho_median", "one"))
    front = {t.number for t in result.best}
    for t in result.trials:
        dominated = any(_dominates(o.values, t.values, goals) for o in result.trials)
        assert dominated == (t.number not in front)


def test_median_rho_is_tuned_toward_one_not_upward(experiment, tmp_path):
    # Resolutions from far too coarse to far too fine: the largest median ρ is not the best one.
    space = parse_space(["resolution=16,128,4096"], settings=ShadowSettings())
    result = tune(experiment, space=space, objectives=["rho_median"], trials=8, out_dir=tmp_path)
    medians = {t.params["resolution"]: t.values["rho_median"] for t in result.trials}
    assert len(medians) == 3 and max(medians.values()) > 1.0 > min(medians.values())
    closest = min(medians.values(), key=lambda rho: abs(math.log(rho)))
    assert result.best[0].values["rho_median"] == closest != max(medians.values())


def test_the_same_seed_repeats_the_search(experiment, tmp_path):
    first = tune(experiment, space=_space(), objectives=["flicker"], trials=2, out_dir=tmp_path / "a", seed=3)
    second = tune(experiment, space=_space(), objectives=["flicker"], trials=2, out_dir=tmp_path / "b", seed=3)
    assert first.trials == second.trials


@pytest.mark.parametrize("spec, match", [("resolution", "FIELD=LO:HI"), ("wobble=1:2", "shadow\\] field"),
                                         ("resolution=big,small", "int values"), ("lambda=0.9:0.3", "empty range")])
def test_bad_search_space_names_the_option(spec, match):
    with pytest.raises(InputError, match=match) as caught:
        parse_space([spec], settings=ShadowSettings())
    assert "--param" in str(caught.value)


def test_objective_needs_a_better_direction():
    assert objective_direction("flicker") == "lower" and objective_direction("ssim") == "higher"
    assert objective_direction("rho_median") == "one"
    with pytest.raises(InputError, match="--objective"):
        objective_direction("no_such_metric")


def test_cli_tune_refuses_a_bad_space_with_exit_code_2():
    from typer.testing import CliRunner

    from csmlab.cli import app

    outcome = CliRunner().invoke(app, ["tune", "gate", "--param", "wobble=1:2"])
    assert outcome.exit_code == 2
    assert "--param" in outcome.output and "Traceback" not in outcome.output
