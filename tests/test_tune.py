"""Tuning: seeded and repeatable, budgets never broken by a recommendation, the exhaustive front is the
true Pareto set, an impossible budget exits 2, a resumed tune runs no candidate twice."""

from __future__ import annotations

import dataclasses
import json
import math

import pytest

import csmlab.tune as tune_module
from csmlab.config import TuneConfig, load_experiment, parse_size
from csmlab.errors import InputError
from csmlab.experiment import run_experiment
from csmlab.metrics.cost import shadow_memory_bytes
from csmlab.settings import ShadowSettings
from csmlab.tune import (ENGINES_DIR as ENGINES, Budgets, InfeasibleBudget, TuneRequest, flicker_limit,
                         objective_direction, parse_space, reference_settings, resolved_options, sampler_name, search,
                         tune, tune_result, write_tune)

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

METHODS = "/".join(["configs", "methods"])


@pytest.fixture(scope="module")
def experiment_file(tmp_path_factory):
    path = tmp_path_factory.mktemp("tune") / "tiny.toml"
    path.write_text(TINY + '\n[tune]\nresolution = [64, 128, 256]\nlambda = { min = 0.3, max = 0.9 }\n')
    return path


@pytest.fixture(scope="module")
def experiment(experiment_file):
    return load_experiment(experiment_file)


@pytest.fixture(scope="module")
def plain(experiment):
    """The experiment without its [tune] table: a test's own space is then the whole space."""
    return dataclasses.replace(experiment, tune=TuneConfig())


@pytest.fixture
def counted_runs(monkeypatch):
    """Every setting run_experiment is asked to run, as cache keys of its settings."""
    runs = []
    real = tune_module.run_experiment

    def spy(variant, **kwargs):
        runs.extend(m.settings for m in variant.methods)
        return real(variant, **kwargs)

    monkeypatch.setattr(tune_module, "run_experiment", spy)
    return runs


@pytest.mark.slow
def test_tune_table_gives_the_space_and_the_same_seed_repeats_the_search(experiment, tmp_path):
    first = tune(experiment, out_dir=tmp_path / "a", trials=5, seed=3, presets=[])
    second = tune(experiment, out_dir=tmp_path / "b", trials=5, seed=3, presets=[])
    assert [(t.params, t.values) for t in first.trials] == [(t.params, t.values) for t in second.trials]
    for t in first.trials:
        assert t.params["resolution"] in (64, 128, 256) and 0.3 <= t.params["lambda"] <= 0.9
    assert first.recommended.label == second.recommended.label
    document = json.loads((tmp_path / "a" / "tune.json").read_text())
    assert [t["values"]["rho_p05"] for t in document["trials"]] == [t.values["rho_p05"] for t in first.trials]


@pytest.mark.slow
def test_no_recommended_candidate_is_over_the_memory_budget(plain, tmp_path):
    budget = shadow_memory_bytes(ShadowSettings(cascades=2, resolution=128))
    result = tune(plain, out_dir=tmp_path, trials=8, seed=1, memory_budget=budget, presets=[],
                  space={"resolution": ("choice", (64, 128, 256, 512))})
    over = [t for t in result.trials if t.memory_bytes > budget]
    assert over, "the search must have proposed a setting over the budget for this test to mean anything"
    assert all(t.values is None and not t.feasible for t in over)  # known over from its settings: never run
    assert result.recommended.memory_bytes <= budget
    # Without the budget the sharpest trial is one of those over it: the budget changed the answer.
    free = tune(plain, out_dir=tmp_path / "free", trials=8, seed=1, presets=[],
                space={"resolution": ("choice", (64, 128, 256, 512))})
    assert free.recommended.memory_bytes > budget


def _dominates(a, b) -> bool:
    no_worse = a[0] <= b[0] and a[1] >= b[1] and a[2] <= b[2]
    return no_worse and (a[0] < b[0] or a[1] > b[1] or a[2] < b[2])


@pytest.mark.slow
def test_exhaustive_search_of_a_tiny_space_returns_the_true_pareto_set(plain, tmp_path):
    space = {"resolution": ("choice", (64, 128)), "lambda": ("choice", (0.3, 0.9)),
             "stabilization": ("choice", ("none", "exact"))}
    result = tune(plain, out_dir=tmp_path / "tune", trials=50, space=space, presets=[])
    assert result.sampler == "grid" and len(result.trials) == 8
    # Brute force, by another road: the same grid as a [sweep] of one plain run, front by pairwise comparison.
    oracle = dataclasses.replace(plain, sweep=tuple((f, spec[1]) for f, spec in space.items()))
    points = run_experiment(oracle, out_dir=tmp_path / "sweep").summary["points"]
    measured = {label: (by["none"]["memory_bytes"], by["none"]["rho_p05"], by["none"]["flicker"])
                for label, by in points.items()}
    true_front = {label for label, v in measured.items()
                  if not any(_dominates(w, v) for other, w in measured.items() if other != label)}
    found = {"/".join(f"{f}={t.params[f]}" for f in space) for t in result.trials if t.label in result.front}
    assert found == true_front and 0 < len(true_front) < 8


@pytest.mark.slow
def test_an_impossible_budget_exits_2_naming_the_budget_and_the_cheapest(experiment_file, tmp_path):
    from typer.testing import CliRunner

    from csmlab.cli import app

    outcome = CliRunner().invoke(app, ["tune", str(experiment_file), "--memory-budget", "1KiB", "--trials", "3",
                                       "--jobs", "1", "--out", str(tmp_path)])
    assert outcome.exit_code == 2
    assert "--memory-budget" in outcome.output and "cheapest seen is trial" in outcome.output
    assert "Traceback" not in outcome.output
    assert (tmp_path / "index.html").is_file() and not (tmp_path / "recommended.toml").exists()


@pytest.mark.slow
def test_a_resumed_tune_evaluates_no_candidate_twice(experiment, tmp_path, counted_runs):
    first = tune(experiment, out_dir=tmp_path, trials=4, seed=5, batch=2, presets=[])
    runs_first = len(counted_runs)
    resumed = tune(experiment, out_dir=tmp_path, trials=8, seed=5, batch=2, presets=[])
    assert [(t.params, t.values) for t in resumed.trials[:4]] == [(t.params, t.values) for t in first.trials]
    assert len(counted_runs) > runs_first  # the longer tune did run new candidates …
    assert len(set(counted_runs)) == len(counted_runs)  # … but never one it had run before
    assert all(not t.computed for t in resumed.trials[:4])
    repeated = tune(experiment, out_dir=tmp_path, trials=8, seed=5, batch=2, presets=[])
    assert repeated.runs_computed == 0 and len(set(counted_runs)) == len(counted_runs)


def test_a_null_metric_of_a_one_frame_run_does_not_crash_a_trial(experiment, tmp_path):
    one = experiment.with_frames(1)
    result = tune(one, out_dir=tmp_path, trials=2, presets=[])
    assert all(t.values["flicker"] is None and t.values["rho_p05"] is not None for t in result.trials)
    with pytest.raises(InputError, match="--objective.*1-frame"):
        tune(one, out_dir=tmp_path / "flicker", trials=2, objectives=["flicker"], presets=[])
    with pytest.raises(InputError, match="at least 2 frames"):
        tune(one, out_dir=tmp_path / "limit", trials=2, max_flicker=0.1, presets=[])


def test_engine_presets_are_measured_on_the_same_frames_and_fitted_to_the_budget(plain, tmp_path):
    presets = [f"{METHODS}/exact.toml", f"{METHODS}/quantized.toml"]
    budget = shadow_memory_bytes(ShadowSettings(cascades=2, resolution=64))
    result = tune(plain, out_dir=tmp_path, trials=3, presets=presets, memory_budget=budget,
                  max_flicker="best-preset", space={"stabilization": ("choice", ("none", "exact", "quantized")),
                                                    "resolution": ("choice", (64,))})
    labels = [c.label for c in result.references]
    assert labels == ["start", "exact @ 64²", "quantized @ 64²"]
    exact = result.references[1]
    assert exact.settings.stabilization == "exact" and exact.memory_bytes <= budget
    # best-preset: the limit is the lowest flicker of the presets within the budget.
    assert result.budgets.max_flicker == min(c.values["flicker"] for c in result.references[1:])
    assert result.recommended.values["flicker"] <= result.budgets.max_flicker
    assert (tmp_path / "recommended.toml").is_file() and (tmp_path / "exports" / "ue5.ini").is_file()
    recommended = load_experiment_with(tmp_path / "recommended.toml", tmp_path)
    assert recommended.settings == result.recommended.settings
    # Each engine's own files come back through csmlab import (tests/engines/ checks field by field),
    # the map size too unless the snippet says the engine cannot hold it.
    from csmlab.engines import IMPORT_METHODS, import_settings

    for engine in IMPORT_METHODS:
        back = import_settings(sorted((tmp_path / "exports" / engine).iterdir()), engine=engine).settings
        (snippet,) = (tmp_path / "exports").glob(f"{engine}.*")
        assert (back.resolution == result.recommended.settings.resolution
                or "lacks: resolution =" in snippet.read_text(encoding="utf-8")), engine


def load_experiment_with(preset, folder):
    """The method of a preset file, loaded as a user would: an experiment that extends it."""
    path = folder / "uses_preset.toml"
    path.write_text(f'extends = ["{preset.name}", "paths/walk"]\n')
    return load_experiment(path).methods[0]


def test_a_preset_must_name_its_method_after_its_file(experiment, tmp_path):
    preset = tmp_path / "myengine.toml"
    preset.write_text('[[methods]]\nname = "other"\nresolution = 64\n')
    with pytest.raises(InputError, match="named 'myengine'"):
        tune(experiment, out_dir=tmp_path / "out", trials=1, presets=[preset])


@pytest.mark.parametrize("text, expected", [("64MiB", 64 * 2 ** 20), ("16MB", 16_000_000), ("1024", 1024),
                                            ("1.5 KiB", 1536), (4096, 4096)])
def test_parse_size_reads_binary_and_decimal_units(text, expected):
    assert parse_size(text) == expected


@pytest.mark.parametrize("text", ["64 parsecs", "-5MiB", "0", "", 2.5, True])
def test_parse_size_refuses_what_is_not_a_size(text):
    with pytest.raises(ValueError, match="64MiB"):
        parse_size(text)


@pytest.mark.parametrize("table, match", [
    ('stabilization = ["exakt"]', r"tune.stabilization: expected one of \['exact', 'none', 'quantized', "
                                  r"'tight_snapped'\], got 'exakt' \(did you mean 'exact'\?\)"),
    ("lambda = { min = 0.9, max = 0.3 }", "tune.lambda: expected min < max"),
    ('split = { min = 1, max = 2 }', "tune.split: expected a list of choices"),
    ('memory_budget = "lots"', "tune.memory_budget: expected a positive size"),
    ('max_flicker = "little"', 'tune.max_flicker: expected a non-negative number or "best-preset"'),
    ("trials = 0", "tune.trials: expected at least 1 trial"),
    ('objectives = ["wobble"]', "tune.objectives: expected metrics.csv columns"),
    ("resolutions = [64]", "tune.resolutions: unknown field 'resolutions': did you mean 'resolution'"),
])
def test_a_bad_tune_table_names_file_line_and_field(tmp_path, table, match):
    path = tmp_path / "bad.toml"
    path.write_text(TINY + "\n[tune]\n" + table + "\n")
    with pytest.raises(InputError, match=match) as caught:
        load_experiment(path)
    assert str(path) in str(caught.value)


@pytest.mark.parametrize("spec, match", [("resolution", "FIELD=LO:HI"), ("wobble=1:2", "shadow\\] field"),
                                         ("resolution=big,small", "int values"), ("lambda=0.9:0.3", "empty range")])
def test_bad_search_space_names_the_option(spec, match):
    with pytest.raises(InputError, match=match) as caught:
        parse_space([spec], settings=ShadowSettings())
    assert "--param" in str(caught.value)


def test_objective_needs_a_better_direction():
    assert objective_direction("flicker") == "lower" and objective_direction("rho_p05") == "higher"
    assert objective_direction("rho_median") == "one"
    with pytest.raises(InputError, match="--objective"):
        objective_direction("no_such_metric")


def test_median_rho_is_tuned_toward_one_not_upward(plain, tmp_path):
    # Resolutions from far too coarse to far too fine: the largest median ρ is not the best one.
    result = tune(plain, out_dir=tmp_path, trials=3, objectives=["rho_median"], presets=[],
                  space={"resolution": ("choice", (16, 128, 4096))})
    medians = {t.params["resolution"]: t.values["rho_median"] for t in result.trials}
    assert len(medians) == 3 and max(medians.values()) > 1.0 > min(medians.values())
    closest = min(medians.values(), key=lambda rho: abs(math.log(rho)))
    assert result.recommended.values["rho_median"] == closest != max(medians.values())


@pytest.mark.parametrize("args, option", [(["--param", "wobble=1:2"], "--param"),
                                          (["--param", "resolution=64,128", "--memory-budget", "lots"],
                                           "--memory-budget"),
                                          (["--param", "resolution=64,128", "--max-flicker", "some"], "--max-flicker")])
def test_cli_tune_refuses_bad_options_with_exit_code_2(args, option):
    from typer.testing import CliRunner

    from csmlab.cli import app

    outcome = CliRunner().invoke(app, ["tune", "gate", *args])
    assert outcome.exit_code == 2
    assert option in outcome.output and "Traceback" not in outcome.output


def test_infeasible_budget_is_an_input_error():
    assert issubclass(InfeasibleBudget, InputError)


def test_real_engine_presets_are_measured_on_the_same_frames_fitted_and_labelled(plain, tmp_path):
    """Two presets of configs/engines (ue5: 3 float32 cascades, bevy: 4) under a budget of 3 float32 cascades
    at ue5's own resolution: ue5 fits as it is, bevy is halved; both ran in one run on the same frames."""
    import csv
    import tomllib

    presets = [tune_module.ENGINES_DIR / "ue5.toml", tune_module.ENGINES_DIR / "bevy.toml"]
    own = {p.stem: tomllib.loads(p.read_text())["methods"][0].get("resolution", plain.shadow.resolution)
           for p in presets}
    budget = shadow_memory_bytes(ShadowSettings(cascades=3, resolution=own["ue5"]))
    result = tune(plain, out_dir=tmp_path, trials=2, presets=presets, memory_budget=budget, max_flicker="best-preset",
                  flicker_metric="flicker_same", space={"stabilization": ("choice", ("exact",)),
                                                        "cascades": ("choice", (2, 3))})
    half = own["bevy"] // 2
    assert [c.label for c in result.references] == ["start", "ue5", f"bevy @ {half}²"]
    _, ue5, bevy = result.references
    assert ue5.settings.resolution == own["ue5"] and bevy.settings.resolution == half
    assert all(c.memory_bytes <= budget and c.values is not None for c in result.references)
    # Every field the preset file sets reaches the measured settings (read from the file, not from csmlab).
    for preset, measured in ((presets[0], ue5), (presets[1], bevy)):
        entry = tomllib.loads(preset.read_text())["methods"][0]
        for key, value in entry.items():
            if key != "name" and not (measured is bevy and key == "resolution"):
                got = getattr(measured.settings, "lambda_" if key == "lambda" else key)
                assert (list(got) if isinstance(got, tuple) else got) == value, (preset.stem, key)
    # One run measured the start and both presets: the same frames for each.
    runs = [p for p in (tmp_path / "runs").glob("*/metrics.csv")]
    frames = {}
    for path in runs:
        with path.open(newline="") as handle:
            for row in csv.DictReader(handle):
                frames.setdefault(row["method"], set()).add(int(row["frame"]))
    keys = {f"k{c.key}" for c in result.references}
    assert keys <= set(frames) and len({frozenset(frames[k]) for k in keys}) == 1
    assert frames[f"k{ue5.key}"] == set(range(plain.camera.frames))
    assert result.budgets.max_flicker == min(ue5.values["flicker_same"], bevy.values["flicker_same"])
    assert result.recommended.values["flicker_same"] <= result.budgets.max_flicker


def test_a_virtual_clipmap_preset_is_fitted_to_a_budget_by_its_page_pool():
    """ue5_vsm's memory is its pool of 2048 pages of 128² float32 (128 MiB): under 16 MiB it is measured with 256
    pages, its resolution untouched (a clipmap's memory does not depend on it)."""
    vsm = ShadowSettings(shadow_map="virtual_clipmap", filter="none")
    fitted = tune_module._fitted(vsm, 16 * 2**20)
    assert fitted == vsm.replace(physical_pages=256)
    assert shadow_memory_bytes(fitted) == 16 * 2**20
    assert tune_module._fitted_label("ue5_vsm", fitted) == "ue5_vsm @ 256 pages"
    assert tune_module._fitted(vsm, 1) == vsm.replace(physical_pages=1)


def test_a_candidate_that_is_no_valid_setting_is_refused_naming_the_trial_the_method_and_the_field(plain, tmp_path):
    # Each value alone is valid (2 or 3 cascades with practical splits; manual splits of 2); 3 manual is not.
    method = plain.methods[0]
    split = dataclasses.replace(plain, methods=(dataclasses.replace(
        method, settings=method.settings.replace(splits=(0.3, 1.0))),))
    space = {"cascades": ("choice", (2, 3)), "split": ("choice", ("practical", "manual"))}
    with pytest.raises(InputError) as caught:
        tune(split, out_dir=tmp_path, trials=4, space=space, presets=[])
    assert (f"trial 3, method {method.name}: splits: expected 3 far ends (one per cascade), got 2 (the candidate: "
            f"cascades=3, split='manual')") in str(caught.value)


GODOT = TINY.replace('extends = ["methods/none"]', 'extends = ["methods/none", "engines/godot4"]') + """
[tune]
method = "godot4"
cascades = [1, 2, 3, 4]
resolution = [256, 512, 1024]
"""


def test_a_tune_of_an_engine_preset_searches_the_engines_own_space_and_exports_whole(tmp_path):
    from csmlab.engines import export

    path = tmp_path / "godot.toml"
    path.write_text(GODOT)
    result = tune(load_experiment(path), out_dir=tmp_path / "out", trials=3, seed=2, presets=[])
    # Godot has 1, 2 or 4 splits and an atlas of 512² tiles or larger: 3 cascades and 256² are not offered.
    assert result.space == {"cascades": ("choice", (1, 2, 4)), "resolution": ("choice", (512, 1024))}
    assert {t.params["cascades"] for t in result.trials} - {1, 2, 4} == set()
    for trial in result.trials:
        # The split fractions follow the cascade count as Godot's split mode takes them.
        assert len(trial.settings.splits) == trial.settings.cascades
        assert export(trial.settings, near=0.1, far=1000.0, engine="godot4").lacking == ()
    assert "lacks:" not in (tmp_path / "out" / "exports" / "godot4.txt").read_text()


def test_a_field_an_engine_has_no_setting_for_is_refused_in_a_tune_of_its_preset(tmp_path):
    path = tmp_path / "godot.toml"
    path.write_text(GODOT)
    with pytest.raises(InputError, match="method godot4 extends the godot4 preset.*no setting for 'depth_range'"):
        tune(load_experiment(path), out_dir=tmp_path / "out", space={"depth_range": ("choice", ("scene",))},
             presets=[])


# --- the phases one by one: resolve options, references, search, result, outputs ---------------------------


def test_resolved_options_take_the_request_over_the_tune_table_over_the_defaults(experiment):
    options = resolved_options(experiment, TuneRequest(space={"lambda": ("choice", (0.5,))}, presets=[]))
    assert options.space == {"resolution": ("choice", (64, 128, 256)), "lambda": ("choice", (0.5,))}
    assert (options.method, options.trials, options.seed, options.batch) == ("none", 20, 0, 4)
    assert options.goals == (("rho_p05", "higher"),) and options.flicker_metric == "flicker"
    assert options.start == experiment.methods[0].settings and options.presets == {}
    assert options.memory_budget is None and options.max_flicker is None and options.device == "cpu"
    asked = resolved_options(experiment, TuneRequest(trials=7, seed=2, memory_budget=1024, max_flicker=0.5,
                                                     presets=[], device="cuda:0", jobs=3))
    assert (asked.trials, asked.seed, asked.memory_budget, asked.max_flicker) == (7, 2, 1024, 0.5)
    assert asked.run_options == {"jobs": 3, "executor": "inprocess", "address": None, "device": "cuda:0"}
    with pytest.raises(InputError) as caught:
        resolved_options(experiment, TuneRequest(method="nope", presets=[]))
    assert caught.value.field == "--method"
    with pytest.raises(InputError) as caught:
        resolved_options(experiment, TuneRequest(space={"resolution": ("choice", (8,))}, presets=[]))
    assert caught.value.field == "--param resolution"


def test_an_engine_preset_is_read_on_the_experiment_as_a_file_extending_both_would_read_it(experiment_file,
                                                                                            experiment, tmp_path):
    presets = [ENGINES / "ue5.toml", ENGINES / "godot4.toml"]
    options = resolved_options(experiment, TuneRequest(presets=presets))
    for preset in presets:
        # The oracle: the user's way, a file on disk extending the experiment and then the preset.
        probe = tmp_path / f"probe_{preset.stem}.toml"
        probe.write_text(f"extends = [{json.dumps(str(experiment_file))}, {json.dumps(str(preset))}]\n")
        expected = next(m for m in load_experiment(probe).methods if m.name == preset.stem).settings
        assert options.presets[preset.stem] == expected
        assert expected.shadow_distance != ShadowSettings().shadow_distance or preset.stem == "ue5"


def test_reference_settings_are_the_start_then_each_preset_fitted_to_the_budget(experiment):
    options = dataclasses.replace(resolved_options(experiment, TuneRequest(presets=[])),
                                  presets={"big": ShadowSettings(resolution=2048), "small": ShadowSettings()},
                                  memory_budget=shadow_memory_bytes(ShadowSettings(resolution=1024)))
    references = reference_settings(options)
    assert list(references) == ["start", "big @ 1024²", "small"]
    assert references["start"] == options.start and references["big @ 1024²"].resolution == 1024
    unlimited = reference_settings(dataclasses.replace(options, memory_budget=None))
    assert list(unlimited) == ["start", "big", "small"]


def test_flicker_limit_best_preset_is_the_lowest_measured_flicker_within_the_memory_budget(experiment):
    options = dataclasses.replace(resolved_options(experiment, TuneRequest(presets=[])), max_flicker="best-preset",
                                  memory_budget=shadow_memory_bytes(ShadowSettings(resolution=1024)))
    references = {"start": ShadowSettings(), "a": ShadowSettings(), "b": ShadowSettings(resolution=2048),
                  "c": ShadowSettings(), "d": ShadowSettings()}
    measured = {"start": ({"flicker": 0.0}, True), "a": ({"flicker": 0.3}, True), "b": ({"flicker": 0.1}, True),
                "c": ({"flicker": 0.2}, True), "d": ({"flicker": None}, True)}
    # The start and the preset over the budget do not set it; an unmeasured flicker neither.
    assert flicker_limit(options, references, measured) == 0.2
    assert flicker_limit(dataclasses.replace(options, max_flicker=0.05), references, measured) == 0.05
    with pytest.raises(InputError, match="expected an engine preset within the memory budget"):
        flicker_limit(options, {"start": ShadowSettings(), "b": references["b"]}, measured)


def test_sampler_is_a_grid_when_the_choices_fit_in_the_trials_else_tpe_or_nsga2(experiment):
    options = resolved_options(experiment, TuneRequest(presets=[]))  # [tune]: lambda is a range
    grid = dataclasses.replace(options, space={"resolution": ("choice", (64, 128)), "lambda": ("choice", (0.3, 0.9))},
                               trials=4)
    assert sampler_name(grid) == "grid"
    assert sampler_name(dataclasses.replace(grid, trials=3)) == "tpe"
    assert sampler_name(options) == "tpe"  # a range in the space
    assert sampler_name(dataclasses.replace(grid, trials=3, goals=(("rho_p05", "higher"), ("flicker", "lower")))) \
        == "nsga2"


def _fake_search(options, tmp_path):
    """:func:`search` with an evaluator that measures nothing: ρ p05 is the resolution, flicker 1 / resolution."""
    asked, ticks = [], []

    def evaluate(named):
        asked.append(dict(named))
        return {label: ({"rho_p05": float(s.resolution), "flicker": 1.0 / s.resolution}, True)
                for label, s in named.items()}

    budgets = Budgets(memory_bytes=options.memory_budget, flicker_metric="flicker")
    judge = tune_module._Judge(budgets, tune_module._Cache(tmp_path, workload="w", device="cpu"))
    return search(options, evaluate, judge, ticks.append), asked, ticks


def test_search_walks_a_grid_in_order_in_batches_and_runs_nothing_over_the_memory_budget(experiment, tmp_path):
    options = dataclasses.replace(resolved_options(experiment, TuneRequest(presets=[])),
                                  space={"resolution": ("choice", (64, 128, 256)), "lambda": ("choice", (0.3, 0.9))},
                                  trials=6, batch=4,
                                  memory_budget=shadow_memory_bytes(ShadowSettings(cascades=2, resolution=128)))
    trials, asked, ticks = _fake_search(options, tmp_path)
    assert [t.params for t in trials] == [{"resolution": r, "lambda": lam}
                                          for r in (64, 128, 256) for lam in (0.3, 0.9)]
    assert ticks == [t.label for t in trials] == [f"trial {i}" for i in range(6)]
    assert [list(batch) for batch in asked] == [["trial 0", "trial 1", "trial 2", "trial 3"], []]
    assert [t.values is None for t in trials] == [False] * 4 + [True] * 2
    assert all(t.settings.resolution == t.params["resolution"] and t.settings.lambda_ == t.params["lambda"]
               for t in trials)


def test_search_with_a_sampler_starts_at_the_start_and_repeats_with_its_seed(experiment, tmp_path):
    options = dataclasses.replace(resolved_options(experiment, TuneRequest(presets=[])),
                                  space={"resolution": ("choice", (64, 128, 256)),
                                         "lambda": ("range", 0.3, 0.9, False, None)}, trials=5, batch=2, seed=4)
    first, _, _ = _fake_search(options, tmp_path / "a")
    second, _, _ = _fake_search(options, tmp_path / "b")
    assert [t.params for t in first] == [t.params for t in second] and len(first) == 5
    assert first[0].params == {"resolution": 128, "lambda": options.start.lambda_}


def test_tune_result_recommends_the_best_feasible_trial_and_keeps_the_front(experiment, tmp_path):
    options = dataclasses.replace(resolved_options(experiment, TuneRequest(presets=[])),
                                  space={"resolution": ("choice", (64, 128, 256))}, trials=3, batch=3,
                                  memory_budget=shadow_memory_bytes(ShadowSettings(cascades=2, resolution=128)))
    trials, _, _ = _fake_search(options, tmp_path)
    budgets = Budgets(memory_bytes=options.memory_budget)
    result = tune_result(experiment, options, budgets=budgets, references=(), trials=trials, runs_computed=2)
    assert result.recommended.label == "trial 1"  # 128: the sharpest within the budget (256 is over it)
    assert result.sampler == "grid" and result.runs_computed == 2 and result.frames == experiment.camera.frames
    assert set(result.front) == {"trial 0", "trial 1"}  # 64 is cheaper, 128 sharper; 256 was not measured


def test_write_tune_writes_everything_then_raises_when_no_trial_is_recommended(experiment, tmp_path):
    options = dataclasses.replace(resolved_options(experiment, TuneRequest(presets=[])),
                                  space={"resolution": ("choice", (128, 256))}, trials=2,
                                  memory_budget=shadow_memory_bytes(ShadowSettings(cascades=2, resolution=64)))
    trials, _, _ = _fake_search(options, tmp_path / "cache")
    result = tune_result(experiment, options, budgets=Budgets(memory_bytes=options.memory_budget), references=(),
                         trials=trials, runs_computed=0)
    with pytest.raises(InfeasibleBudget) as caught:
        write_tune(result, tmp_path, near=0.1, far=400.0)
    assert caught.value.field == "--memory-budget" and "cheapest seen is trial 0" in caught.value.detail
    document = json.loads((tmp_path / "tune.json").read_text())
    assert document["recommended"] is None and [t["label"] for t in document["trials"]] == ["trial 0", "trial 1"]
    assert (tmp_path / "index.html").is_file() and not (tmp_path / "recommended.toml").exists()


@pytest.mark.parametrize("frames, chunk, jobs, want", [(12, 10, 2, 6), (12, 10, 1, 10), (120, 10, 2, 10), (3, 10, 4, 1),
                                                       (7, 10, 2, 4), (12, 4, 2, 4)])
def test_a_candidates_run_is_cut_so_that_every_process_has_a_unit(experiment, frames, chunk, jobs, want):
    from csmlab.experiment import chunk_ranges

    cut = tune_module.balanced_chunk_frames(dataclasses.replace(experiment.with_frames(frames), chunk_frames=chunk),
                                            jobs=jobs)
    assert cut == want and cut <= chunk and len(chunk_ranges(frames, cut)) >= min(jobs, frames)


def test_the_candidates_runs_take_the_balanced_cut(experiment, tmp_path, monkeypatch):
    cuts = []
    real = tune_module.run_experiment

    def spy(variant, **kwargs):
        cuts.append((variant.chunk_frames, kwargs["jobs"]))
        return real(variant, **{**kwargs, "jobs": 1, "executor": "inprocess"})

    monkeypatch.setattr(tune_module, "run_experiment", spy)
    tune(experiment, out_dir=tmp_path, trials=2, batch=2, presets=[], jobs=2)
    assert cuts and all(cut == (2, 2) for cut in cuts)  # 3 frames over 2 processes: units of 2 and 1


def test_a_candidates_run_lists_only_fields_that_apply_and_its_resolved_toml_loads_back(experiment, tmp_path):
    settings = experiment.shadow.replace(split="exponent", lambda_=0.75, distribution_exponent=3.5)
    changed = tune_module._changed(settings, experiment.shadow)
    assert changed["split"] == "exponent" and "lambda" not in changed and changed["distribution_exponent"] == 3.5
    tune(experiment, out_dir=tmp_path, trials=2, batch=2, presets=[], jobs=1,
         space={"split": ("choice", ("exponent",)), "lambda": ("range", 0.3, 0.9, False, None),
                "distribution_exponent": ("range", 2.0, 4.0, False, None)})
    runs = sorted((tmp_path / "runs").glob("*/config.resolved.toml"))
    assert runs and all(load_experiment(run).methods for run in runs)


def test_a_tunes_runs_share_one_workload_built_once(experiment, tmp_path, monkeypatch):
    built, given = [], []
    real_build, real_run = tune_module.build_workload, tune_module.run_experiment
    monkeypatch.setattr(tune_module, "build_workload", lambda e: built.append(real_build(e)) or built[-1])

    def spy(variant, **kwargs):
        given.append(kwargs["workload"])
        return real_run(variant, **kwargs)

    monkeypatch.setattr(tune_module, "run_experiment", spy)
    result = tune(experiment, out_dir=tmp_path, trials=4, batch=2, presets=[f"{METHODS}/exact.toml"])
    assert len(given) >= 3 and len(built) == 1 and all(w is built[0] for w in given)
    alone = run_experiment(dataclasses.replace(experiment, methods=(experiment.methods[0],)),
                           out_dir=tmp_path / "alone")
    assert result.trials and alone.summary["workload_hash"] == built[0].key
