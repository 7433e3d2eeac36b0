"""Tuning: search one method's shadow settings for the best measured trade-off, with Optuna.

Each trial runs the experiment with the chosen method alone, its ``[shadow]`` fields set from the
search space, and reads the objectives from the run's summary (means over frames). Which way an
objective is better comes from the metric registry (:data:`csmlab.metric_registry.METRICS`):
flicker and error lower, SSIM higher, median ρ closest to 1. Optuna minimises each objective's
score (:meth:`csmlab.metric_registry.Metric.score`: the value, its negative, or ``|ln ρ|``, so that
ρ = 0.5 and ρ = 2 are equally far from the 1:1 ideal); the trials keep the measured values. One
objective uses the TPE sampler and reports the best trial; several use NSGA-II and report the
Pareto front — e.g. flicker against median ρ against memory, the trade-off an engine team actually
faces. Seeded samplers and deterministic runs make a tuning run repeatable.

References
----------
- Akiba et al., "Optuna: A Next-generation Hyperparameter Optimization Framework", KDD 2019.
"""

from __future__ import annotations

import dataclasses
import json
import math
from dataclasses import dataclass
from pathlib import Path

from csmlab.config import Experiment, Method
from csmlab.errors import InputError
from csmlab.experiment import run_experiment
from csmlab.metric_registry import METRICS
from csmlab.results import write_atomic
from csmlab.settings import ShadowSettings

__all__ = ["Trial", "TuneResult", "objective_direction", "parse_space", "tune"]

@dataclass(frozen=True)
class Trial:
    """One evaluated point of the search: shadow fields set, and the objectives measured."""

    number: int
    params: dict
    values: dict


@dataclass(frozen=True)
class TuneResult:
    """A tuning run.

    Attributes
    ----------
    method : str
        The method whose settings were searched.
    objectives : tuple of (str, str)
        Metric name and which way it is better: ``lower``, ``higher`` or ``one`` (closest to 1).
    trials : tuple of Trial
        Every completed trial, in order.
    best : tuple of Trial
        The best trial (one objective) or the Pareto front (several), by trial number.
    """

    method: str
    objectives: tuple[tuple[str, str], ...]
    trials: tuple[Trial, ...]
    best: tuple[Trial, ...]


def objective_direction(metric: str) -> str:
    """Which way a metrics.csv column is better (``lower``, ``higher`` or ``one``), from the registry.

    Raises
    ------
    InputError
        For a metric with no better direction or an unknown one; the message lists the valid ones.
    """
    declared = METRICS.get(metric)
    if declared is None or declared.better == "either":
        valid = ", ".join(m.name for m in METRICS.values() if m.better != "either")
        raise InputError(f"expected a metric that is better lower, higher or closest to 1 ({valid}), got {metric!r}",
                         field="--objective")
    return declared.better


def parse_space(specs, *, settings: ShadowSettings) -> dict[str, tuple]:
    """Search space from ``FIELD=LO:HI`` (a numeric range) or ``FIELD=A,B,C`` (choices) strings.

    A range takes the field's type (an int field gets integers); choices are parsed as the field's
    type too. Returns ``{toml_field: ("range", lo, hi) | ("choice", values)}``.

    Raises
    ------
    InputError
        On a malformed spec, an unknown field (valid ones listed) or values of the wrong type.
    """
    names = ShadowSettings.field_names()
    space = {}
    for spec in specs:
        field, sep, body = spec.partition("=")
        field = field.strip()
        if not sep or not body:
            raise InputError(f"expected FIELD=LO:HI or FIELD=A,B,C, got {spec!r}", field="--param")
        if field not in names:
            raise InputError(f"expected a [shadow] field ({', '.join(names)}), got {field!r}", field="--param")
        kind = type(getattr(settings, "lambda_" if field == "lambda" else field))
        try:
            if ":" in body and kind in (int, float):
                lo, hi = (kind(v) for v in body.split(":", 1))
                if not lo < hi:
                    raise ValueError(f"an empty range {lo}:{hi}")
                space[field] = ("range", lo, hi)
            else:
                space[field] = ("choice", tuple(_parsed(v.strip(), kind) for v in body.split(",")))
        except ValueError as exc:
            raise InputError(f"expected {kind.__name__} values, {exc}", field=f"--param {field}") from None
    if not space:
        raise InputError("expected at least one FIELD=LO:HI or FIELD=A,B,C to search", field="--param")
    return space


def _parsed(text: str, kind):
    if kind is bool:
        if text not in ("true", "false"):
            raise ValueError(f"got {text!r} (true or false)")
        return text == "true"
    return kind(text)


def tune(experiment: Experiment, *, space: dict, objectives, trials: int, out_dir, method: str | None = None,
         seed: int = 0, jobs: int = 1, executor: str = "inprocess") -> TuneResult:
    """Search ``space`` for one method of ``experiment``; write ``OUT/tune.json``.

    Parameters
    ----------
    experiment : Experiment
        The workload (scene, camera, light, frames) and the method to start from.
    space : dict
        From :func:`parse_space`.
    objectives : sequence of str
        metrics.csv columns (means over frames), each improved the way :func:`objective_direction` says.
    trials : int
        Runs of the experiment.
    out_dir : path
        ``tune.json`` and one results folder per trial (``trials/NNN``) go here.
    method : str, optional
        A method of ``experiment``; its first method when None.
    seed : int
        Sampler seed.
    jobs, executor : int, str
        Where each trial's frames run (:mod:`csmlab.executor`).
    """
    import optuna

    names = [m.name for m in experiment.methods]
    chosen = names[0] if method is None else method
    if chosen not in names:
        raise InputError(f"expected one of the experiment's methods {names}, got {method!r}", field="--method")
    if trials < 1:
        raise InputError(f"expected at least 1 trial, got {trials}", field="--trials")
    goals = tuple((metric, objective_direction(metric)) for metric in objectives)
    base = next(m for m in experiment.methods if m.name == chosen)
    out_dir = Path(out_dir)

    def run_trial(trial) -> tuple[float, ...]:
        params = {field: _suggest(trial, field, spec) for field, spec in space.items()}
        try:
            settings = base.settings.replace(**params).validated()
        except ValueError as exc:
            raise InputError(str(exc), field="--param") from None
        variant = dataclasses.replace(experiment, methods=(Method(chosen, {**base.overrides, **params}, settings),),
                                      sweep=())
        summary = run_experiment(variant, out_dir=out_dir / "trials" / f"{trial.number:03d}", jobs=jobs,
                                 executor=executor).summary["methods"][chosen]
        values = {metric: _finite(summary[metric]) for metric, _ in goals}
        trial.set_user_attr("params", params)
        trial.set_user_attr("values", values)
        return tuple(math.nan if values[metric] is None else METRICS[metric].score(values[metric])
                     for metric, _ in goals)

    optuna.logging.set_verbosity(optuna.logging.WARNING)
    sampler = (optuna.samplers.TPESampler(seed=seed) if len(goals) == 1
               else optuna.samplers.NSGAIISampler(seed=seed))
    study = optuna.create_study(directions=["minimize"] * len(goals), sampler=sampler)
    study.optimize(run_trial, n_trials=trials, catch=())
    done = tuple(_trial_record(t) for t in study.trials if t.state == optuna.trial.TrialState.COMPLETE)
    best_numbers = sorted(t.number for t in study.best_trials)
    result = TuneResult(method=chosen, objectives=goals, trials=done,
                        best=tuple(t for t in done if t.number in best_numbers))
    write_atomic(out_dir / "tune.json", json.dumps(_document(result, space, seed), indent=2) + "\n")
    return result


def _suggest(trial, field: str, spec: tuple):
    if spec[0] == "choice":
        return trial.suggest_categorical(field, list(spec[1]))
    _, lo, hi = spec
    if isinstance(lo, int):
        return trial.suggest_int(field, lo, hi)
    return trial.suggest_float(field, lo, hi)


def _finite(value) -> float | None:
    return None if value is None or not math.isfinite(float(value)) else float(value)


def _trial_record(trial) -> Trial:
    return Trial(number=trial.number, params=dict(trial.user_attrs["params"]), values=dict(trial.user_attrs["values"]))


def _document(result: TuneResult, space: dict, seed: int) -> dict:
    return {
        "method": result.method,
        "objectives": [{"metric": m, "direction": d} for m, d in result.objectives],
        "space": {f: list(spec[1:]) if spec[0] == "range" else {"choices": list(spec[1])} for f, spec in space.items()},
        "seed": seed,
        "best": [dataclasses.asdict(t) for t in result.best],
        "trials": [dataclasses.asdict(t) for t in result.trials],
    }
