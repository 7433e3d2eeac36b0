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
share each frame's view (keeping the metrics and cascade rows, not the report's images), the pool's processes
kept from one run to the next, and its summary is kept in ``OUT/cache/`` under a key of the workload hash,
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
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np

import csmlab
from csmlab import config
from csmlab.config import (CONFIGS_DIR, CameraConfig, Experiment, Method, ReportConfig, load_experiment,
                           workload_hash)
from csmlab.errors import InputError
from csmlab.executor import kept_processes
from csmlab.experiment import Workload, build_workload, run_experiment
from csmlab.metrics.cost import shadow_memory_bytes
from csmlab.metric_registry import METRICS
from csmlab.results import json_text, read_json, write_atomic
from csmlab.settings import APPLIES, ShadowSettings

__all__ = ["ALIASING_AXIS", "DEFAULT_OBJECTIVES", "ENGINES_DIR", "Budgets", "Candidate", "InfeasibleBudget",
           "TuneOptions", "TuneRequest", "TuneResult", "balanced_chunk_frames", "engine_presets", "flicker_limit",
           "objective_direction", "pareto_front", "parse_space", "reference_settings", "resolved_options",
           "sampler_name", "search", "settings_document", "tune", "tune_document", "tune_result", "write_outputs",
           "write_tune"]

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
    """The fields of ``settings`` that differ from ``base`` and apply to it (:data:`~csmlab.settings.APPLIES`): a
    run's resolved TOML lists them, and the loader refuses a field that does not apply (``lambda`` with
    ``split = "exponent"``)."""
    ours, theirs = settings_document(settings), settings_document(base)
    return {k: v for k, v in ours.items() if v != theirs[k] and (k not in APPLIES or APPLIES[k].holds(settings))}


def engine_presets(directory=None) -> list[Path]:
    """The engine presets: every ``*.toml`` of ``directory`` (default :data:`ENGINES_DIR`), sorted by name."""
    folder = Path(directory) if directory is not None else ENGINES_DIR
    return sorted(folder.glob("*.toml")) if folder.is_dir() else []


def _preset_settings(experiment: Experiment, preset: Path) -> ShadowSettings:
    """The settings of ``preset``'s method on ``experiment``'s ``[shadow]``, merged as ``extends`` merges them
    (the experiment's file, then the preset: :func:`csmlab.config.load_experiment`'s ``then_extends``)."""
    preset = Path(preset).resolve()
    merged = load_experiment(experiment.source, then_extends=(preset,))
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
    workload: Workload | None = None

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
                                          report=ReportConfig(snapshot_frames=()),
                                          chunk_frames=balanced_chunk_frames(self.experiment,
                                                                             jobs=self.run_options.get("jobs") or 1))
            batch = hashlib.sha256(" ".join(sorted(todo.values())).encode()).hexdigest()[:12]
            if self.workload is None:
                # Every run has the experiment's scene, path and light: built once, for the first.
                self.workload = build_workload(self.experiment)
            summary = run_experiment(variant, out_dir=self.runs_dir / batch, resume=True, workload=self.workload,
                                     images=False, **self.run_options).summary["methods"]
            for name, key in todo.items():
                values = {k: (None if v is None or (isinstance(v, float) and math.isnan(v)) else v)
                          for k, v in summary[f"k{key}"].items()}
                self.cache.put(key, named[name], values)
                found[key] = values
            self.computed += len(todo)
        fresh = set(todo.values())
        return {name: (found[key], key in fresh and todo.get(name) == key) for name, key in keys.items()}


def balanced_chunk_frames(experiment: Experiment, *, jobs: int) -> int:
    """Frames per unit of a candidates' run: the experiment's ``chunk_frames``, or fewer, so that each of ``jobs``
    processes has a unit.

    A tune's runs are short (``tune_default``: 12 frames, cut by the default 10 into units of 10 and 2 frames, one
    process idle most of each run). Cut in ``jobs`` equal units instead, each process but the first renders one
    frame again (the previous frame a unit's flicker needs); the numbers do not depend on the cut.
    """
    return max(1, min(experiment.chunk_frames, math.ceil(experiment.camera.frames / max(jobs, 1))))


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


def _candidate_settings(settings: ShadowSettings, settle, camera) -> ShadowSettings:
    """``settings`` settled (its engine's derived fields) and checked as a run would check them: the fields' ranges,
    and the splits over ``camera``'s near and far planes (a split list of another count, a first far end beyond the
    shadow). Raises ValueError naming the field."""
    from csmlab.cascades.splits import split_boundaries

    settings = settle(settings).validated()
    split_boundaries(settings, near=camera.near, far=camera.far)
    return settings


def _describe(candidate: Candidate) -> str:
    return ", ".join(f"{k}={v}" for k, v in candidate.params.items()) or "as the experiment has it"


@dataclass(frozen=True)
class TuneRequest:
    """What the caller of :func:`tune` asks for (the command line's options); ``None`` leaves an option to the
    experiment's ``[tune]`` table, then to the defaults. :func:`resolved_options` checks and resolves it.

    Attributes
    ----------
    space : dict, optional
        Field → spec (:func:`parse_space`); merged over ``[tune]``'s, field by field.
    objectives : sequence of str, optional
        metrics.csv columns (means over frames); default ``rho_p05``.
    trials : int, optional
        Candidates of the search (an exhaustive grid may take fewer); default 20.
    method : str, optional
        A method of the experiment; default its first.
    seed : int, optional
        Sampler seed: the same seed repeats the search; default 0.
    memory_budget : int, optional
        Bytes of shadow-map memory.
    max_flicker : float or "best-preset", optional
        Limit of ``flicker_metric``; ``best-preset`` is the lowest among the engine presets within the
        memory budget.
    flicker_metric : str, optional
        Default ``flicker``.
    presets : sequence of path, optional
        Engine presets to compare with; default :func:`engine_presets`.
    batch : int
        Candidates asked of the sampler, and run, together (they share each frame's view). A resumed
        tune must use the same batch to replay the same candidates.
    jobs, executor, address, device
        Where each run's frames go (:func:`csmlab.experiment.run_experiment`).
    """

    space: dict | None = None
    objectives: tuple[str, ...] | list[str] | None = None
    trials: int | None = None
    method: str | None = None
    seed: int | None = None
    memory_budget: int | None = None
    max_flicker: float | str | None = None
    flicker_metric: str | None = None
    presets: tuple | list | None = None
    batch: int = 4
    jobs: int = 1
    executor: str = "inprocess"
    address: str | None = None
    device: str = "cpu"


@dataclass(frozen=True)
class TuneOptions:
    """One tune's options resolved: the request over the experiment's ``[tune]`` over the defaults, checked.

    Attributes
    ----------
    method : str
        The tuned method.
    start : ShadowSettings
        Its settings as the experiment has them: the search's starting point.
    space : dict
        Field → spec (:func:`parse_space`), every bound a valid setting of ``start``.
    goals : tuple of (str, str)
        Objective metric and which way it is better (:func:`objective_direction`).
    trials : int
        Candidates the search may run (at least 1).
    batch : int
        Candidates asked and run together (at least 1).
    seed : int
    memory_budget : int or None
        Bytes.
    max_flicker : float, "best-preset" or None
        ``best-preset`` until the engine presets are measured (:func:`flicker_limit`).
    flicker_metric : str
        A metrics.csv column, lower is better.
    presets : dict
        Engine preset name (its file's stem) → its method's settings on the experiment's ``[shadow]``.
    run_options : dict
        ``jobs``, ``executor``, ``address``, ``device`` for :func:`csmlab.experiment.run_experiment`.
    settle : callable
        ``settle(settings) -> settings``: an engine's derived fields set (the method an engine owns,
        :func:`csmlab.engines.tune_space`); the identity for any other method.
    camera : CameraConfig
        The experiment's camera: its planes check each candidate's splits.
    """

    method: str
    start: ShadowSettings
    space: dict
    goals: tuple[tuple[str, str], ...]
    trials: int
    batch: int
    seed: int
    memory_budget: int | None
    max_flicker: float | str | None
    flicker_metric: str
    presets: dict[str, ShadowSettings]
    run_options: dict
    settle: Callable[[ShadowSettings], ShadowSettings]
    camera: CameraConfig

    @property
    def device(self) -> str:
        """The device the candidates run on (part of every cache key)."""
        return self.run_options["device"]


@dataclass(frozen=True)
class _Judge:
    """Makes a :class:`Candidate` of a measured setting: its cache key, memory and budget violations."""

    budgets: Budgets
    cache: _Cache

    def __call__(self, label: str, kind: str, params: dict, settings: ShadowSettings, values: dict | None,
                 computed: bool) -> Candidate:
        memory = shadow_memory_bytes(settings)
        return Candidate(label=label, kind=kind, params=params, settings=settings, key=self.cache.key(settings),
                         memory_bytes=memory, values=values, violations=self.budgets.violations(memory, values),
                         computed=computed)


# --- the phases of a tune ---------------------------------------------------------------------------


def resolved_options(experiment: Experiment, request: TuneRequest) -> TuneOptions:
    """Phase 1: ``request`` over the experiment's ``[tune]`` over the defaults, every option checked.

    Raises
    ------
    InputError
        Naming the option: an unknown method, no search space, an objective or flicker metric with no
        better direction, fewer than 1 trial or candidate per batch, a bad flicker limit or fewer than 2
        frames to measure flicker, a bound of the space that is no valid setting, a malformed engine preset.
    """
    table = experiment.tune
    names = [m.name for m in experiment.methods]
    chosen = request.method or table.method or names[0]
    if chosen not in names:
        raise InputError(f"expected one of the experiment's methods {names}, got {chosen!r}", field="--method")
    space = {**dict(table.space), **(request.space or {})}
    from csmlab.engines import tune_space

    owner = tune_space(chosen)
    if owner is not None:
        # An engine preset is tuned in the engine's own space: values its files hold, derived fields settled.
        space = owner[1].restricted(space, engine=owner[0], method=chosen)
    settle = owner[1].settle if owner is not None else _unsettled
    if not space:
        raise InputError("expected a search space: a [tune] table of [shadow] fields or --param FIELD=LO:HI|A,B,C",
                         file=experiment.source, field="tune")
    goals = tuple((m, objective_direction(m)) for m in (request.objectives or table.objectives or DEFAULT_OBJECTIVES))
    trials = request.trials if request.trials is not None else (table.trials or 20)
    if trials < 1:
        raise InputError(f"expected at least 1 trial, got {trials}", field="--trials")
    if request.batch < 1:
        raise InputError(f"expected at least 1 candidate per batch, got {request.batch}", field="--batch")
    flicker_metric = request.flicker_metric or table.flicker_metric
    if objective_direction(flicker_metric) != "lower":
        raise InputError(f"expected a metric that is better lower, got {flicker_metric!r}", field="--flicker-metric")
    max_flicker = request.max_flicker if request.max_flicker is not None else table.max_flicker
    if max_flicker is not None and max_flicker != "best-preset" and not (
            isinstance(max_flicker, (int, float)) and max_flicker >= 0):
        raise InputError(f'expected a non-negative number or "best-preset", got {max_flicker!r}', field="--max-flicker")
    if max_flicker is not None and experiment.camera.frames < 2:
        raise InputError(f"expected at least 2 frames to measure flicker, got {experiment.camera.frames}",
                         field="--max-flicker")
    start = next(m for m in experiment.methods if m.name == chosen).settings
    _check_space(space, start, settle=settle, camera=experiment.camera, method=chosen)
    paths = engine_presets() if request.presets is None else [Path(p) for p in request.presets]
    return TuneOptions(method=chosen, start=start, space=space, goals=goals, trials=trials, batch=request.batch,
                       seed=request.seed if request.seed is not None else (table.seed or 0),
                       memory_budget=request.memory_budget if request.memory_budget is not None
                       else table.memory_budget,
                       max_flicker=max_flicker, flicker_metric=flicker_metric,
                       presets={p.stem: _preset_settings(experiment, p) for p in paths}, settle=settle,
                       camera=experiment.camera,
                       run_options=dict(jobs=request.jobs, executor=request.executor, address=request.address,
                                        device=request.device))


def _unsettled(settings: ShadowSettings) -> ShadowSettings:
    """A method no engine owns: its settings as they are."""
    return settings


def _check_space(space: dict, start: ShadowSettings, *, settle, camera, method: str) -> None:
    """Every choice and range bound of ``space`` must make ``start``, settled, a valid setting over ``camera``
    (:func:`_candidate_settings`); else an InputError naming the method, field and value."""
    for field, spec in space.items():
        for value in (spec[1] if spec[0] == "choice" else spec[1:3]):
            try:
                _candidate_settings(start.replace(**{field: value}), settle, camera)
            except ValueError as exc:
                raise InputError(f"method {method}, {field} = {value!r}: {exc}", field=f"--param {field}") from None


def reference_settings(options: TuneOptions) -> dict[str, ShadowSettings]:
    """Phase 2a: the settings every tune is compared with, by label: ``start``, then each engine preset, fitted to
    the memory budget where it is over it (``ue5 @ 512²``, :func:`_fitted`)."""
    references = {"start": options.start}
    for name, settings in options.presets.items():
        fitted = _fitted(settings, options.memory_budget)
        references[name if fitted == settings else _fitted_label(name, fitted)] = fitted
    return references


def flicker_limit(options: TuneOptions, references: dict[str, ShadowSettings],
                  measured: dict[str, tuple[dict, bool]]) -> float | None:
    """Phase 2b: the flicker limit; ``best-preset`` resolved to the lowest ``flicker_metric`` among the measured
    engine presets within the memory budget.

    Raises
    ------
    InputError
        ``best-preset`` with no such preset.
    """
    if options.max_flicker != "best-preset":
        return options.max_flicker
    within = [measured[label][0].get(options.flicker_metric) for label, s in references.items()
              if label != "start" and (options.memory_budget is None
                                       or shadow_memory_bytes(s) <= options.memory_budget)]
    within = [v for v in within if v is not None]
    if not within:
        raise InputError("expected an engine preset within the memory budget with a measured flicker to set "
                         "the limit from, got none", field="--max-flicker")
    return min(within)


def sampler_name(options: TuneOptions) -> str:
    """``grid`` when the space is choices only and its grid fits in the trials (searched exhaustively), else
    ``tpe`` for one objective and ``nsga2`` for several."""
    grid = _grid(options.space)
    if grid is not None and len(grid) <= options.trials:
        return "grid"
    return "tpe" if len(options.goals) == 1 else "nsga2"


def search(options: TuneOptions, evaluate: Callable[[dict], dict], judge: Callable[..., Candidate],
           tick: Callable[[str], None]) -> tuple[Candidate, ...]:
    """Phase 3: the search's candidates in trial order, ``batch`` at a time.

    Parameters
    ----------
    options : TuneOptions
    evaluate : callable
        ``evaluate({label: settings}) -> {label: (values, computed)}`` (:class:`_Evaluator`).
    judge : callable
        ``judge(label, kind, params, settings, values, computed) -> Candidate`` (budget violations).
    tick : callable
        ``tick(label)`` after each candidate.

    A grid (:func:`sampler_name`) is walked in order; otherwise Optuna's seeded sampler is asked for each
    batch and told each candidate's objective values and budget violations. A candidate over the memory
    budget is not run.

    Raises
    ------
    InputError
        A candidate of the space that is no valid setting.
    """
    name = sampler_name(options)
    grid = _grid(options.space) if name == "grid" else None
    total = len(grid) if grid is not None else options.trials
    study = None if grid is not None else _study(options, name)
    distributions = {field: _distribution(spec) for field, spec in options.space.items()}
    found: list[Candidate] = []
    for number in range(0, total, options.batch):
        size = min(options.batch, total - number)
        asked = [None] * size if study is None else [study.ask(distributions) for _ in range(size)]
        points = grid[number:number + size] if grid is not None else [dict(t.params) for t in asked]
        labels = [f"trial {number + offset}" for offset in range(size)]
        labelled = {label: (params, _trial_settings(options, label, params)) for label, params in zip(labels, points)}
        results = evaluate({label: s for label, (_, s) in labelled.items() if not _over_memory(options, s)})
        for trial, (label, (params, settings)) in zip(asked, labelled.items()):
            values, computed = results.get(label, (None, False))
            record = judge(label, "trial", params, settings, values, computed)
            found.append(record)
            if study is not None:
                for budget, violation in record.violations.items():
                    trial.set_constraint(budget, violation)
                study.tell(trial, list(_objective_values(values, options.goals)))
            tick(label)
    return tuple(found)


def _study(options: TuneOptions, name: str):
    """A seeded Optuna study minimising every goal, the start's values of the searched fields enqueued first."""
    import optuna

    optuna.logging.set_verbosity(optuna.logging.WARNING)
    # Constrained sampling reads each trial's Trial.set_constraint values (Optuna ≥ 5).
    sampler = (optuna.samplers.NSGAIISampler(seed=options.seed) if name == "nsga2"
               else optuna.samplers.TPESampler(seed=options.seed))
    study = optuna.create_study(directions=["minimize"] * len(options.goals), sampler=sampler)
    start = {f: v for f, v in settings_document(options.start).items()
             if f in options.space and _holds(options.space[f], v)}
    if start:
        # The search starts where the user is: the start's values of the fields it can hold.
        study.enqueue_trial(start)
    return study


def _trial_settings(options: TuneOptions, label: str, params: dict) -> ShadowSettings:
    """The start with a trial's ``params``, settled and checked (:func:`_candidate_settings`); else an InputError."""
    try:
        return _candidate_settings(options.start.replace(**params), options.settle, options.camera)
    except ValueError as exc:
        tried = ", ".join(f"{k}={v!r}" for k, v in params.items())
        raise InputError(f"{label}, method {options.method}: {exc} (the candidate: {tried})", field="--param") from None


def _over_memory(options: TuneOptions, settings: ShadowSettings) -> bool:
    return options.memory_budget is not None and shadow_memory_bytes(settings) > options.memory_budget


def tune_result(experiment: Experiment, options: TuneOptions, *, budgets: Budgets, references: tuple[Candidate, ...],
                trials: tuple[Candidate, ...], runs_computed: int) -> TuneResult:
    """Phase 4: the tune's record: the Pareto front of the trials and the recommended one."""
    return TuneResult(name=experiment.name, method=options.method, objectives=options.goals, budgets=budgets,
                      space=options.space, sampler=sampler_name(options), seed=options.seed, trials=trials,
                      references=references,
                      front=tuple(pareto_front(trials, flicker_metric=options.flicker_metric)),
                      recommended=_recommended(trials, options.goals), runs_computed=runs_computed,
                      frames=experiment.camera.frames)


def write_tune(result: TuneResult, out_dir, *, near: float, far: float) -> None:
    """Phase 5: ``tune.json`` and the outputs (:func:`write_outputs`) under ``out_dir``.

    Raises
    ------
    InfeasibleBudget
        When no trial is recommended, after everything is written: the budget no candidate met.
    """
    write_atomic(Path(out_dir) / "tune.json", json_text(tune_document(result)))
    write_outputs(result, out_dir, near=near, far=far)
    if result.recommended is None:
        option, message = _infeasible_message(result.trials, result.budgets, result.objectives)
        raise InfeasibleBudget(message, field=option)


def tune(experiment: Experiment, *, out_dir, progress: Callable[[int, int, str], None] | None = None,
         **request) -> TuneResult:
    """Search one method's shadow settings under budgets; write ``tune.json`` and the outputs beside it.

    The phases, each its own function: :func:`resolved_options`, the references (:func:`reference_settings`,
    measured, then :func:`flicker_limit`), :func:`search`, :func:`tune_result`, :func:`write_tune`.

    Parameters
    ----------
    experiment : Experiment
        The workload and the method to start from.
    out_dir : path
        ``tune.json``, ``cache/`` (one summary per evaluated setting) and ``runs/`` (the batches' results
        folders) go here.
    progress : callable, optional
        ``progress(done, total, label)`` after each candidate.
    **request
        The fields of :class:`TuneRequest` (``trials=``, ``memory_budget=``, …); each left out or ``None`` is
        taken from the experiment's ``[tune]`` table, then from the defaults.

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
    options = resolved_options(experiment, TuneRequest(**request))
    out_dir = Path(out_dir)
    cache = _Cache(out_dir / "cache", workload=workload_hash(experiment, frames=experiment.camera.frames),
                   device=options.device)
    evaluate = _Evaluator(experiment, cache, out_dir / "runs", options.run_options)
    grid = _grid(options.space)
    searched = len(grid) if sampler_name(options) == "grid" else options.trials
    total = searched + 1 + len(options.presets)
    done = 0

    def tick(label: str) -> None:
        nonlocal done
        done += 1
        if progress is not None:
            progress(done, total, label)

    if progress is not None:
        progress(0, total, "start and engine presets")
    references = reference_settings(options)
    # The runs' processes, their kernels and prepared scene kept from one batch of candidates to the next.
    with kept_processes():
        measured = evaluate(references)
        for label in references:
            tick(label)
        budgets = Budgets(memory_bytes=options.memory_budget, max_flicker=flicker_limit(options, references, measured),
                          flicker_metric=options.flicker_metric)
        judge = _Judge(budgets, cache)
        compared = tuple(judge(label, "start" if label == "start" else "preset", _changed(settings, experiment.shadow),
                               settings, *measured[label]) for label, settings in references.items())
        trials = search(options, evaluate, judge, tick)
    result = tune_result(experiment, options, budgets=budgets, references=compared, trials=trials,
                         runs_computed=evaluate.computed)
    write_tune(result, out_dir, near=experiment.camera.near, far=experiment.camera.far)
    return result


_SUFFIXES = {"ini": ("ini", ";"), "csharp": ("cs", "//"), "gdscript": ("txt", "#"), "rust": ("rs", "//"),
             "javascript": ("js", "//"), "yaml": ("asset", "#"), "json": ("txt", "//"),
             "sdscene": ("sdscene", "#")}


def write_outputs(result: TuneResult, out_dir, *, near: float, far: float) -> Path:
    """Write the recommended setting as ``recommended.toml``, its engine snippets as ``exports/<engine>.*``
    (the knobs an engine lacks as comments, headed by their group's title) and the report ``index.html``; return
    the report's path.

    ``near`` and ``far`` are the camera's planes, metres (where the exported splits start and end).
    """
    from csmlab.engines import EXPORT_METHODS, export
    from csmlab.engines.common import lacking_by_group
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
        lacking = "".join(f"{comment} {title}:\n" + "".join(f"{comment} lacks: {item}\n" for item in items)
                          for title, items in lacking_by_group(snippet.lacking))
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
