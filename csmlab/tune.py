"""Tuning: the best shadow setting inside memory and flicker budgets, measured against every engine preset.

A *candidate* is one method's ``[shadow]`` settings run on the experiment's workload (scene, camera
path, light, frames). The search space comes from the experiment's ``[tune]`` table or from
``--param FIELD=LO:HI|A,B,C``; the objectives are metrics.csv columns (means over frames), each
minimised as the registry's score of its direction (:func:`objective_direction`): lower, higher, or closest to 1.

Budgets are constraints, not objectives: shadow-map memory (``memory_bytes``) at most a budget, and a
flicker column at most a limit. Optuna's constrained samplers (TPE for one objective, NSGA-II for
several) receive each trial's violations (``Trial.set_constraint``), so they learn where the
feasible region is; a candidate whose memory — known from its settings alone — is over the budget is
not run at all (samplers rank infeasible trials by their violation only, never by their values). No
candidate over a budget is ever recommended; when none meets them, :class:`InfeasibleBudget` names
the budget and the cheapest candidate seen. A space of choices only whose grid fits in the trials is
searched exhaustively, in grid order.

Every candidate is evaluated through :func:`csmlab.experiment.run_experiment` (the runner's
executors: in-process, a process pool or Dask), several at a time as methods of one run so that they
share each frame's view, and its summary is kept in ``OUT/cache/`` under a key of the workload hash,
the device and the settings: a repeated or resumed tune recomputes nothing, and the seeded sampler,
told the same values, proposes the same candidates again.

Beside the search, the starting setting (the tuned method as the experiment has it) and every engine
preset (``configs/engines/*.toml``, each a method preset naming its ``[[methods]]`` entry after the
file) are evaluated on the same frames. Under a memory budget a preset over it is evaluated at the
largest power-of-two fraction of its resolution that fits ("ue5 @ 512²"), a virtual clipmap at that
fraction of its page pool ("ue5_vsm @ 256 pages"): what an engine team would do to meet the budget.

References
----------
- Akiba et al., "Optuna: A Next-generation Hyperparameter Optimization Framework", KDD 2019.
- Deb et al., "A fast and elitist multiobjective genetic algorithm: NSGA-II", IEEE TEC 2002 (its
  constrained domination).
"""

from __future__ import annotations

import dataclasses
import hashlib
import itertools
import json
import math
import tempfile
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np

import csmlab
from csmlab import config
from csmlab.config import CONFIGS_DIR, Experiment, Method, ReportConfig, load_experiment, workload_hash
from csmlab.errors import InputError
from csmlab.experiment import run_experiment
from csmlab.metrics.cost import shadow_memory_bytes
from csmlab.metric_registry import METRICS
from csmlab.results import json_text, read_json, write_atomic
from csmlab.settings import ShadowSettings

__all__ = ["ALIASING_AXIS", "DEFAULT_OBJECTIVES", "ENGINES_DIR", "Budgets", "Candidate", "InfeasibleBudget",
           "TuneResult", "engine_presets", "objective_direction", "pareto_front", "parse_space",
           "settings_document", "tune", "tune_document", "write_outputs"]

ENGINES_DIR = CONFIGS_DIR / "engines"
"""The engine presets every tune is compared with."""
DEFAULT_OBJECTIVES = ("rho_p05",)
"""The sharpest setting: the 5th percentile of ρ (texels per pixel where shadows are blockiest), raised."""
ALIASING_AXIS = "rho_p05"
"""The aliasing axis of the Pareto front (memory × aliasing × flicker)."""

def objective_direction(metric: str) -> str:
    """Which way a metrics.csv column is better (``lower``, ``higher`` or ``one``), from the registry.

    The one place tune reads a metric's direction (:data:`csmlab.metric_registry.METRICS`). Optuna
    minimises every objective as the registry's score (:meth:`csmlab.metric_registry.Metric.score`):
    the value, its negative, or ``|ln ρ|`` for a metric best at 1.

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
    type too. Returns ``{toml_field: ("range", lo, hi, log, step) | ("choice", values)}``, the form of
    :attr:`csmlab.config.TuneConfig.space`.

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
                space[field] = ("range", lo, hi, False, None)
            else:
                space[field] = ("choice", tuple(_parsed(v.strip(), kind) for v in body.split(",")))
        except ValueError as exc:
            raise InputError(f"expected {kind.__name__} values, {exc}", field=f"--param {field}") from None
    return space


def _parsed(text: str, kind):
    if kind is bool:
        if text not in ("true", "false"):
            raise ValueError(f"got {text!r} (true or false)")
        return text == "true"
    return kind(text)


@dataclass(frozen=True)
class Budgets:
    """What a recommended setting must not exceed.

    Attributes
    ----------
    memory_bytes : int, optional
        Shadow-map memory ``C · R² · depth_bytes`` in bytes.
    max_flicker : float, optional
        Largest mean over frames of ``flicker_metric``.
    flicker_metric : str
        A metrics.csv column, lower is better.
    """

    memory_bytes: int | None = None
    max_flicker: float | None = None
    flicker_metric: str = "flicker"

    def violations(self, memory_bytes: float, values: dict | None) -> dict[str, float]:
        """Each budget's violation: ``value / limit − 1`` (``value − limit`` for a zero limit); > 0 is over.

        A flicker the run could not measure (``None``: one frame) counts as over by 1.
        """
        out = {}
        if self.memory_bytes is not None:
            out["memory"] = memory_bytes / self.memory_bytes - 1.0
        if self.max_flicker is not None:
            value = None if values is None else values.get(self.flicker_metric)
            if value is None:
                out["flicker"] = 1.0
            else:
                out["flicker"] = value / self.max_flicker - 1.0 if self.max_flicker > 0 else value - self.max_flicker
        return out


@dataclass(frozen=True)
class Candidate:
    """One evaluated setting: a trial of the search, the starting setting or an engine preset.

    Attributes
    ----------
    label : str
        ``trial 7``, ``start``, ``ue5`` or ``ue5 @ 512²``.
    kind : str
        ``trial``, ``start`` or ``preset``.
    params : dict
        A trial's searched fields; for the start and the presets, the fields that differ from the
        experiment's ``[shadow]``.
    settings : ShadowSettings
    key : str
        The cache key (workload hash, device, settings).
    memory_bytes : int
    values : dict or None
        The run's summary for this method (metric → mean over frames, ``None`` where undefined);
        ``None`` when it was not run (over the memory budget).
    violations : dict
        Budget name → violation (> 0: over the budget), for every budget set.
    computed : bool
        Run by this tune (False: taken from the cache, or not run).
    """

    label: str
    kind: str
    params: dict
    settings: ShadowSettings
    key: str
    memory_bytes: int
    values: dict | None
    violations: dict
    computed: bool

    @property
    def feasible(self) -> bool:
        """Measured and within every budget."""
        return self.values is not None and all(v <= 0 for v in self.violations.values())


@dataclass(frozen=True)
class TuneResult:
    """A tune.

    Attributes
    ----------
    name, method : str
        The experiment and the tuned method.
    objectives : tuple of (str, str)
        Metric and which way it is better: ``lower``, ``higher`` or ``one`` (closest to 1).
    budgets : Budgets
        With ``max_flicker`` resolved (``best-preset`` replaced by its value).
    space : dict
        Field → spec (:func:`parse_space`).
    sampler : str
        ``tpe``, ``nsga2`` or ``grid`` (exhaustive).
    seed : int
    trials : tuple of Candidate
        The search's candidates, in trial order.
    references : tuple of Candidate
        The starting setting, then every engine preset.
    front : tuple of str
        Labels of the trials on the Pareto front over memory, aliasing and flicker (:func:`pareto_front`).
    recommended : Candidate or None
        The feasible trial best in the first objective (ties: the next ones); None when no trial is feasible.
    runs_computed : int
        Candidates run by this tune (the rest came from the cache or were not run).
    frames : int
    """

    name: str
    method: str
    objectives: tuple[tuple[str, str], ...]
    budgets: Budgets
    space: dict
    sampler: str
    seed: int
    trials: tuple[Candidate, ...]
    references: tuple[Candidate, ...]
    front: tuple[str, ...]
    recommended: Candidate | None
    runs_computed: int
    frames: int


class InfeasibleBudget(InputError):
    """No candidate met the budgets (exit code 2): the message names the budget and the cheapest candidate."""


# --- settings, presets, cache --------------------------------------------------------------------------


def settings_document(settings: ShadowSettings) -> dict:
    """Every ``[shadow]`` field by its TOML name, as plain data (tuples as lists)."""
    return {name: (list(v) if isinstance(v := getattr(settings, "lambda_" if name == "lambda" else name), tuple)
                   else v) for name in ShadowSettings.field_names()}


def _changed(settings: ShadowSettings, base: ShadowSettings) -> dict:
    ours, theirs = settings_document(settings), settings_document(base)
    return {k: v for k, v in ours.items() if v != theirs[k]}


def engine_presets(directory=None) -> list[Path]:
    """The engine presets: every ``*.toml`` of ``directory`` (default :data:`ENGINES_DIR`), sorted by name."""
    folder = Path(directory) if directory is not None else ENGINES_DIR
    return sorted(folder.glob("*.toml")) if folder.is_dir() else []


def _preset_settings(experiment: Experiment, preset: Path) -> ShadowSettings:
    """The settings of ``preset``'s method on ``experiment``'s ``[shadow]``, merged as ``extends`` merges them."""
    preset = Path(preset).resolve()
    with tempfile.TemporaryDirectory() as folder:
        probe = Path(folder) / "preset_probe.toml"
        probe.write_text(f"extends = [{json.dumps(str(Path(experiment.source).resolve()))}, "
                         f"{json.dumps(str(preset))}]\n", encoding="utf-8")
        merged = load_experiment(probe)
    method = next((m for m in merged.methods if m.name == preset.stem), None)
    if method is None:
        raise InputError(f"expected a [[methods]] entry named {preset.stem!r} (the file's name) in an engine preset, "
                         f"got {[m.name for m in merged.methods]}", file=preset, field="methods")
    return method.settings


def _fitted(settings: ShadowSettings, budget: int | None) -> ShadowSettings:
    """``settings`` with its resolution halved until its memory fits ``budget`` (not below 16 texels); a virtual
    clipmap's page pool halved instead (not below one page), its memory (:func:`csmlab.storage.memory_bytes`)."""
    size, least = ("physical_pages", 1) if settings.shadow_map == "virtual_clipmap" else ("resolution", 16)
    while budget is not None and shadow_memory_bytes(settings) > budget and getattr(settings, size) // 2 >= least:
        settings = settings.replace(**{size: getattr(settings, size) // 2})
    return settings


def _fitted_label(name: str, fitted: ShadowSettings) -> str:
    """How a preset measured at a smaller size is named: ``ue5 @ 512²``, ``ue5_vsm @ 256 pages``."""
    if fitted.shadow_map == "virtual_clipmap":
        return f"{name} @ {fitted.physical_pages} pages"
    return f"{name} @ {fitted.resolution}²"


class _Cache:
    """Summaries of evaluated settings on one workload and device, one JSON file per key under ``folder``."""

    def __init__(self, folder: Path, *, workload: str, device: str):
        self.folder = folder
        self.workload = workload
        self.device = device

    def key(self, settings: ShadowSettings) -> str:
        document = {"workload": self.workload, "device": self.device, "csmlab": csmlab.__version__,
                    "settings": settings_document(settings)}
        return hashlib.sha256(json.dumps(document, sort_keys=True).encode()).hexdigest()[:16]

    def get(self, key: str) -> dict | None:
        path = self.folder / f"{key}.json"
        if not path.is_file():
            return None
        try:
            return read_json(path, required=("values",))["values"]
        except InputError:
            return None  # a damaged entry is recomputed, not trusted

    def put(self, key: str, settings: ShadowSettings, values: dict) -> None:
        write_atomic(self.folder / f"{key}.json", json_text({
            "key": key, "workload_hash": self.workload, "device": self.device, "csmlab_version": csmlab.__version__,
            "settings": settings_document(settings), "values": values}))


@dataclass
class _Evaluator:
    """Runs settings on the experiment's workload, several at a time, through the cache."""

    experiment: Experiment
    cache: _Cache
    runs_dir: Path
    run_options: dict
    computed: int = 0

    def __call__(self, named: dict[str, ShadowSettings]) -> dict[str, tuple[dict, bool]]:
        """``{name: settings}`` → ``{name: (values, computed_now)}``; equal settings are run once."""
        keys = {name: self.cache.key(s) for name, s in named.items()}
        found = {key: self.cache.get(key) for key in set(keys.values())}
        todo = {}
        for name, key in keys.items():
            if found[key] is None and key not in todo.values():
                todo[name] = key
        if todo:
            methods = tuple(Method(name=f"k{key}", overrides=_changed(named[name], self.experiment.shadow),
                                   settings=named[name]) for name, key in todo.items())
            variant = dataclasses.replace(self.experiment, methods=methods, sweep=(),
                                          report=ReportConfig(snapshot_frames=()))
            batch = hashlib.sha256(" ".join(sorted(todo.values())).encode()).hexdigest()[:12]
            summary = run_experiment(variant, out_dir=self.runs_dir / batch, resume=True,
                                     **self.run_options).summary["methods"]
            for name, key in todo.items():
                values = {k: (None if v is None or (isinstance(v, float) and math.isnan(v)) else v)
                          for k, v in summary[f"k{key}"].items()}
                self.cache.put(key, named[name], values)
                found[key] = values
            self.computed += len(todo)
        fresh = set(todo.values())
        return {name: (found[key], key in fresh and todo.get(name) == key) for name, key in keys.items()}


# --- the search ---------------------------------------------------------------------------------------


def _objective_values(values: dict | None, goals) -> tuple[float, ...]:
    """Values told to Optuna: a metric the run could not define (None), or a run not made, is the worst."""
    return tuple(math.inf if values is None or values.get(m) is None else METRICS[m].score(float(values[m]))
                 for m, _ in goals)


def pareto_front(candidates, *, flicker_metric: str) -> list[str]:
    """Labels of the measured ``candidates`` that no other one dominates over memory (lower), aliasing
    (:data:`ALIASING_AXIS`, higher) and ``flicker_metric`` (lower); a candidate lacking one is left out."""
    from csmlab.report.figures import pareto_optimal

    measured = [c for c in candidates if c.values is not None]
    rows = [[c.memory_bytes, -_number(c.values.get(ALIASING_AXIS)), _number(c.values.get(flicker_metric))]
            for c in measured]
    optimal = pareto_optimal(np.asarray(rows, dtype=np.float64).reshape(-1, 3))
    return [c.label for c, keep in zip(measured, optimal) if keep]


def _number(value) -> float:
    return math.nan if value is None else float(value)


def _recommended(trials, goals) -> Candidate | None:
    feasible = [c for c in trials if c.feasible and all(c.values.get(m) is not None for m, _ in goals)]
    if not feasible:
        return None
    return min(feasible, key=lambda c: tuple(METRICS[m].score(c.values[m]) for m, _ in goals))


def _grid(space: dict) -> list[dict] | None:
    """Every point of a space of choices only, in order (last field fastest); None when it has a range."""
    if any(spec[0] != "choice" for spec in space.values()):
        return None
    return [dict(zip(space, values)) for values in itertools.product(*(spec[1] for spec in space.values()))]


def _distribution(spec: tuple):
    import optuna

    if spec[0] == "choice":
        return optuna.distributions.CategoricalDistribution(list(spec[1]))
    _, lo, hi, log, step = spec
    if isinstance(lo, int):
        return optuna.distributions.IntDistribution(lo, hi, log=log, step=step or 1)
    return optuna.distributions.FloatDistribution(lo, hi, log=log, step=step)


def _holds(spec: tuple, value) -> bool:
    return value in spec[1] if spec[0] == "choice" else spec[1] <= value <= spec[2]


def _infeasible_message(candidates, budgets: Budgets, goals) -> tuple[str, str]:
    """The option to blame when no candidate can be recommended, and why: the budget no candidate met
    with the candidate closest to meeting it, or an objective no run defined."""
    memory = METRICS["memory_bytes"]

    def mib(n):
        return f"{memory.shown(n, digits=4)} {memory.unit}"

    if budgets.memory_bytes is not None and all(c.violations["memory"] > 0 for c in candidates):
        cheapest = min(candidates, key=lambda c: c.memory_bytes)
        return ("--memory-budget", f"no candidate fits the memory budget of {mib(budgets.memory_bytes)} "
                                   f"({budgets.memory_bytes} bytes): the cheapest seen is {cheapest.label} "
                                   f"({_describe(cheapest)}) at {mib(cheapest.memory_bytes)}")
    within = [c for c in candidates if c.violations.get("memory", 0) <= 0 and c.values is not None]
    if budgets.max_flicker is not None and not any(c.violations["flicker"] <= 0 for c in within):
        measured = [c for c in within if c.values.get(budgets.flicker_metric) is not None]
        least = min(measured, key=lambda c: c.values[budgets.flicker_metric], default=None)
        seen = (f"the least flickering seen is {least.label} ({_describe(least)}) with {budgets.flicker_metric} = "
                f"{least.values[budgets.flicker_metric]:.6g}" if least else "no run measured it")
        return ("--max-flicker", f"no candidate within the memory budget meets the flicker limit "
                                 f"{budgets.flicker_metric} ≤ {budgets.max_flicker:.6g}: {seen}")
    undefined = [m for m, _ in goals if all(c.values is None or c.values.get(m) is None for c in within)]
    return ("--objective", f"expected objectives the runs define, got {undefined or [m for m, _ in goals]} undefined "
                           f"for every candidate within the budgets (a 1-frame run has no temporal metrics)")


def _describe(candidate: Candidate) -> str:
    return ", ".join(f"{k}={v}" for k, v in candidate.params.items()) or "as the experiment has it"


def tune(experiment: Experiment, *, out_dir, space: dict | None = None, objectives=None, trials: int | None = None,
         method: str | None = None, seed: int | None = None, memory_budget: int | None = None,
         max_flicker: float | str | None = None, flicker_metric: str | None = None, presets=None, batch: int = 4,
         jobs: int = 1, executor: str = "inprocess", address: str | None = None, device: str = "cpu",
         progress: Callable[[int, int, str], None] | None = None) -> TuneResult:
    """Search one method's shadow settings under budgets; write ``tune.json`` and the outputs beside it.

    Every argument left ``None`` is taken from the experiment's ``[tune]`` table, then from the
    defaults (first method, ``rho_p05``, 20 trials, seed 0, no budgets, the ``flicker`` column).

    Parameters
    ----------
    experiment : Experiment
        The workload and the method to start from.
    out_dir : path
        ``tune.json``, ``cache/`` (one summary per evaluated setting) and ``runs/`` (the batches' results
        folders) go here.
    space : dict, optional
        Field → spec (:func:`parse_space`); merged over ``[tune]``'s, field by field.
    objectives : sequence of str, optional
        metrics.csv columns (means over frames).
    trials : int, optional
        Candidates of the search (an exhaustive grid may take fewer).
    method : str, optional
        A method of ``experiment``.
    seed : int, optional
        Sampler seed: the same seed repeats the search.
    memory_budget : int, optional
        Bytes of shadow-map memory.
    max_flicker : float or "best-preset", optional
        Limit of ``flicker_metric``; ``best-preset`` is the lowest among the engine presets within the
        memory budget.
    flicker_metric : str, optional
    presets : sequence of path, optional
        Engine presets to compare with; default :func:`engine_presets`.
    batch : int
        Candidates asked of the sampler, and run, together (they share each frame's view). A resumed
        tune must use the same batch to replay the same candidates.
    jobs, executor, address, device
        Where each run's frames go (:func:`csmlab.experiment.run_experiment`).
    progress : callable, optional
        ``progress(done, total, label)`` after each candidate.

    Returns
    -------
    TuneResult

    Raises
    ------
    InputError
        On bad options (naming the option), before any run.
    InfeasibleBudget
        When no trial meets the budgets, after the outputs are written.
    """
    import optuna

    config = experiment.tune
    names = [m.name for m in experiment.methods]
    chosen = method or config.method or names[0]
    if chosen not in names:
        raise InputError(f"expected one of the experiment's methods {names}, got {chosen!r}", field="--method")
    space = {**dict(config.space), **(space or {})}
    if not space:
        raise InputError("expected a search space: a [tune] table of [shadow] fields or --param FIELD=LO:HI|A,B,C",
                         file=experiment.source, field="tune")
    goals = tuple((m, objective_direction(m)) for m in (objectives or config.objectives or DEFAULT_OBJECTIVES))
    trials = trials if trials is not None else (config.trials or 20)
    if trials < 1:
        raise InputError(f"expected at least 1 trial, got {trials}", field="--trials")
    if batch < 1:
        raise InputError(f"expected at least 1 candidate per batch, got {batch}", field="--batch")
    seed = seed if seed is not None else (config.seed or 0)
    flicker_metric = flicker_metric or config.flicker_metric
    if objective_direction(flicker_metric) != "lower":
        raise InputError(f"expected a metric that is better lower, got {flicker_metric!r}", field="--flicker-metric")
    memory_budget = memory_budget if memory_budget is not None else config.memory_budget
    max_flicker = max_flicker if max_flicker is not None else config.max_flicker
    if max_flicker is not None and max_flicker != "best-preset" and not (
            isinstance(max_flicker, (int, float)) and max_flicker >= 0):
        raise InputError(f'expected a non-negative number or "best-preset", got {max_flicker!r}', field="--max-flicker")
    if max_flicker is not None and experiment.camera.frames < 2:
        raise InputError(f"expected at least 2 frames to measure flicker, got {experiment.camera.frames}",
                         field="--max-flicker")
    base = next(m for m in experiment.methods if m.name == chosen)
    for field, spec in space.items():
        for value in (spec[1] if spec[0] == "choice" else spec[1:3]):
            try:
                base.settings.replace(**{field: value}).validated()
            except ValueError as exc:
                raise InputError(str(exc), field=f"--param {field}") from None
    preset_paths = engine_presets() if presets is None else [Path(p) for p in presets]
    preset_settings = {Path(p).stem: _preset_settings(experiment, p) for p in preset_paths}

    out_dir = Path(out_dir)
    cache = _Cache(out_dir / "cache", workload=workload_hash(experiment, frames=experiment.camera.frames),
                   device=device)
    evaluate = _Evaluator(experiment, cache, out_dir / "runs",
                          dict(jobs=jobs, executor=executor, address=address, device=device))
    grid = _grid(space)
    exhaustive = grid is not None and len(grid) <= trials
    total_trials = len(grid) if exhaustive else trials
    total = total_trials + 1 + len(preset_settings)
    done = 0

    def tick(label: str) -> None:
        nonlocal done
        done += 1
        if progress is not None:
            progress(done, total, label)

    if progress is not None:
        progress(0, total, "start and engine presets")
    budgets = Budgets(memory_bytes=memory_budget, flicker_metric=flicker_metric)
    reference_settings = {"start": base.settings}
    for name, settings in preset_settings.items():
        fitted = _fitted(settings, memory_budget)
        reference_settings[name if fitted == settings else _fitted_label(name, fitted)] = fitted
    measured = evaluate(reference_settings)
    for label in reference_settings:
        tick(label)
    if max_flicker == "best-preset":
        within = [measured[label][0].get(flicker_metric) for label, s in reference_settings.items()
                  if label != "start" and (memory_budget is None or shadow_memory_bytes(s) <= memory_budget)]
        within = [v for v in within if v is not None]
        if not within:
            raise InputError("expected an engine preset within the memory budget with a measured flicker to set "
                             "the limit from, got none", field="--max-flicker")
        max_flicker = min(within)
    budgets = dataclasses.replace(budgets, max_flicker=max_flicker)

    def candidate(label, kind, params, settings, values, computed) -> Candidate:
        memory = shadow_memory_bytes(settings)
        return Candidate(label=label, kind=kind, params=params, settings=settings, key=cache.key(settings),
                         memory_bytes=memory, values=values, violations=budgets.violations(memory, values),
                         computed=computed)

    references = tuple(candidate(label, "start" if label == "start" else "preset",
                                 _changed(settings, experiment.shadow), settings, *measured[label])
                       for label, settings in reference_settings.items())

    directions = ["minimize"] * len(goals)
    if exhaustive:
        sampler_name = "grid"
    elif len(goals) == 1:
        sampler_name = "tpe"
    else:
        sampler_name = "nsga2"
    optuna.logging.set_verbosity(optuna.logging.WARNING)
    # Constrained sampling reads each trial's Trial.set_constraint values (Optuna ≥ 5).
    sampler = (optuna.samplers.NSGAIISampler(seed=seed) if sampler_name == "nsga2"
               else optuna.samplers.TPESampler(seed=seed))
    study = optuna.create_study(directions=directions, sampler=sampler)
    distributions = {field: _distribution(spec) for field, spec in space.items()}
    start_params = {f: v for f, v in settings_document(base.settings).items() if f in space and _holds(space[f], v)}
    if not exhaustive and start_params:
        # The search starts where the user is: the start's values of the fields it can hold.
        study.enqueue_trial(start_params)
    found: list[Candidate] = []
    number = 0
    while number < total_trials:
        size = min(batch, total_trials - number)
        asked = [None if exhaustive else study.ask(distributions) for _ in range(size)]
        points = grid[number:number + size] if exhaustive else [dict(t.params) for t in asked]
        named, skipped = {}, {}
        for offset, params in enumerate(points):
            label = f"trial {number + offset}"
            try:
                settings = base.settings.replace(**params).validated()
            except ValueError as exc:
                raise InputError(f"a candidate of the search space is not a valid setting: {exc}",
                                 field="--param") from None
            over = memory_budget is not None and shadow_memory_bytes(settings) > memory_budget
            (skipped if over else named)[label] = (params, settings)
        results = evaluate({label: s for label, (_, s) in named.items()})
        for offset, params in enumerate(points):
            label = f"trial {number + offset}"
            _, settings = named.get(label) or skipped[label]
            values, computed = results.get(label, (None, False))
            record = candidate(label, "trial", params, settings, values, computed)
            found.append(record)
            if not exhaustive:
                trial = asked[offset]
                for budget, violation in record.violations.items():
                    trial.set_constraint(budget, violation)
                study.tell(trial, list(_objective_values(values, goals)))
            tick(label)
        number += size

    trials_found = tuple(found)
    result = TuneResult(name=experiment.name, method=chosen, objectives=goals, budgets=budgets, space=space,
                        sampler=sampler_name, seed=seed, trials=trials_found, references=references,
                        front=tuple(pareto_front(trials_found, flicker_metric=flicker_metric)),
                        recommended=_recommended(trials_found, goals), runs_computed=evaluate.computed,
                        frames=experiment.camera.frames)
    write_atomic(out_dir / "tune.json", json_text(tune_document(result)))
    write_outputs(result, out_dir, near=experiment.camera.near, far=experiment.camera.far)
    if result.recommended is None:
        option, message = _infeasible_message(trials_found, budgets, goals)
        raise InfeasibleBudget(message, field=option)
    return result


_SUFFIXES = {"ini": ("ini", ";"), "csharp": ("cs", "//"), "gdscript": ("txt", "#"), "rust": ("rs", "//"),
             "javascript": ("js", "//"), "yaml": ("asset", "#"), "json": ("txt", "//"),
             "sdscene": ("sdscene", "#")}


def write_outputs(result: TuneResult, out_dir, *, near: float, far: float) -> Path:
    """Write the recommended setting as ``recommended.toml``, its engine snippets as ``exports/<engine>.*``
    (the knobs an engine lacks as comments) and the report ``index.html``; return the report's path.

    ``near`` and ``far`` are the camera's planes, metres (where the exported splits start and end).
    """
    from csmlab.engines import EXPORT_METHODS, export
    from csmlab.report.tune_page import write_tune_report

    out_dir = Path(out_dir)
    best = result.recommended
    if best is None:
        return write_tune_report(out_dir, result, snippets=[], preset_file="")
    values = best.values
    summary = ", ".join(f"{m} {values[m]:.4g}" for m in (ALIASING_AXIS, "rho_median", result.budgets.flicker_metric)
                        if values.get(m) is not None)
    header = (f"csmlab tune of {result.name}: {best.label} of {len(result.trials)}, {result.frames} frames\n"
              f"memory {best.memory_bytes} bytes; {summary}")
    write_atomic(out_dir / "recommended.toml", config.method_preset_toml(
        f"{result.name}_tuned", best.settings, header=header,
        description=f"tuned on {result.name} ({result.method}): {_describe(best)}"))
    snippets = [export(best.settings, near=near, far=far, engine=engine) for engine in EXPORT_METHODS]
    for snippet in snippets:
        suffix, comment = _SUFFIXES[snippet.language]
        lacking = "".join(f"{comment} lacks: {item}\n" for item in snippet.lacking)
        write_atomic(out_dir / "exports" / f"{snippet.engine}.{suffix}",
                     f"{comment} {snippet.title} — csmlab tune of {result.name}, {best.label}\n{snippet.text}{lacking}")
        for name, text in snippet.files:
            # The engine's own files, as the engine writes them: csmlab import ENGINE reads them back.
            write_atomic(out_dir / "exports" / snippet.engine / name, text)
    return write_tune_report(out_dir, result, snippets=snippets, preset_file="recommended.toml")


def _candidate_document(c: Candidate) -> dict:
    return {"label": c.label, "kind": c.kind, "params": c.params, "key": c.key, "memory_bytes": c.memory_bytes,
            "feasible": c.feasible, "violations": c.violations, "computed": c.computed,
            "settings": settings_document(c.settings), "values": c.values}


def tune_document(result: TuneResult) -> dict:
    """``tune.json``: the options, every candidate with its summary, the front and the recommendation."""
    return {
        "name": result.name,
        "method": result.method,
        "objectives": [{"metric": m, "direction": d} for m, d in result.objectives],
        "budgets": dataclasses.asdict(result.budgets),
        "space": {f: ({"choices": list(spec[1])} if spec[0] == "choice"
                      else {"min": spec[1], "max": spec[2], "log": spec[3], "step": spec[4]})
                  for f, spec in result.space.items()},
        "sampler": result.sampler,
        "seed": result.seed,
        "frames": result.frames,
        "runs_computed": result.runs_computed,
        "recommended": result.recommended.label if result.recommended else None,
        "front": list(result.front),
        "references": [_candidate_document(c) for c in result.references],
        "trials": [_candidate_document(c) for c in result.trials],
    }
