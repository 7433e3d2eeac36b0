"""The ``csmlab`` command (docs/design.md, "Interfaces").

``run`` an experiment, re-render its ``report``, ``regress`` it against a ``baseline``, ``compare`` two
runs of one workload, ``list`` what can be named in an experiment, ``show`` an experiment resolved,
``import`` an engine's own settings files as a method preset.
Exit codes: 0 success, 1 a regression found, 2 bad input — one line naming the file, the field and
what was expected, never a traceback.
"""

from __future__ import annotations

import os
import re
import sys
import time
from pathlib import Path

import typer
from rich.console import Console
from rich.markup import escape
from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeElapsedColumn, TimeRemainingColumn
from rich.table import Table

from csmlab.errors import InputError
from csmlab.executor import freeze_objects_at_exit

__all__ = ["app", "main"]

app = typer.Typer(
    name="csmlab",
    help="A laboratory for cascaded shadow maps: measure perspective aliasing and shadow flicker.",
    add_completion=False,
    no_args_is_help=True,
    pretty_exceptions_enable=False,
)



def _out() -> Console:
    console = Console(highlight=False)
    if not console.is_terminal:
        # Logs (CI) have no width; rich would squeeze tables into 80 columns.
        console.width = 160
    return console


def _err() -> Console:
    return Console(stderr=True, highlight=False, soft_wrap=True)


def _bad_input(error: ValueError) -> typer.Exit:
    """Print ``error`` as the one line of a bad input and return the exit to raise (code 2)."""
    typer.echo(f"csmlab: error: {error}", err=True)
    return typer.Exit(code=2)


def _output_file(path: Path, option: str) -> Path:
    """``path`` if a file can be written there: not a folder, in an existing writable folder; nothing is created.

    Raises
    ------
    InputError
        Naming ``option`` (``--out``): a folder where a file is expected, a missing parent folder, an
        unwritable folder or file.
    """
    if path.is_dir():
        raise InputError("expected a file to write, got an existing folder", file=path, field=option)
    parent = path.parent
    if not parent.is_dir():
        raise InputError(f"expected a file in an existing folder, but {parent} "
                         + ("is a file" if parent.exists() else "does not exist"), file=path, field=option)
    if not os.access(parent, os.W_OK | os.X_OK) or (path.exists() and not os.access(path, os.W_OK)):
        raise InputError("expected a file this user can write, got " + ("a read-only file" if path.exists()
                                                                         else f"the read-only folder {parent}"),
                         file=path, field=option)
    return path


def _output_folder(path: Path, option: str) -> Path:
    """``path`` if results can be written there: an existing writable folder, or a new one under an existing
    writable folder (missing folders between are created as before); nothing is created here.

    Raises
    ------
    InputError
        Naming ``option`` (``--out``): an existing file where a folder is expected, a file on the way,
        an unwritable folder.
    """
    if path.exists() and not path.is_dir():
        raise InputError("expected a folder for the results, got an existing file", file=path, field=option)
    existing = path
    while not existing.exists():
        if existing.parent == existing:
            break
        existing = existing.parent
    if not existing.is_dir():
        raise InputError(f"expected a folder for the results, but {existing} on its way is a file", file=path,
                         field=option)
    if not os.access(existing, os.W_OK | os.X_OK):
        raise InputError(f"expected a folder this user can write, got the read-only folder {existing}", file=path,
                         field=option)
    return path


def _count(value: int | None, option: str, *, minimum: int = 1) -> int | None:
    """``value`` (None: the default) if it is at least ``minimum``; InputError naming ``option`` otherwise."""
    if value is not None and value < minimum:
        raise InputError(f"expected an integer of at least {minimum}, got {value}", field=option)
    return value


def _method_name(name: str, option: str) -> str:
    """``name`` if it is a method name (letters, digits and ``_.+-``); InputError naming ``option`` otherwise."""
    from csmlab.config.presets import _METHOD_NAME

    if not _METHOD_NAME.match(name):
        raise InputError(f"expected a method name of letters, digits and _.+-, got {name!r}", field=option)
    return name


def _number(value) -> str:
    from csmlab.metric_registry import format_number

    return format_number(value)


def _summary_table(summary: dict) -> Table:
    """Method × the registry's headline metrics (name over unit); a row per method and sweep point when the
    experiment sweeps."""
    from csmlab.metric_registry import HEADLINE

    table = Table(title=escape(f"{summary['name']}: mean over {summary['frames']} frames"), title_justify="left")
    table.add_column("method")
    swept = list(summary["points"]) != ["base"]
    if swept:
        table.add_column("point")
    rows = ([(m, p, v) for p, by_method in summary["points"].items() for m, v in by_method.items()] if swept
            else [(m, None, v) for m, v in summary["methods"].items()])
    # A column measured only under some setting (the *_taa columns without [taa]) is left out where empty.
    shown = [metric for metric in HEADLINE
             if not metric.name.endswith("_taa") or any(values.get(metric.name) is not None for *_, values in rows)]
    for metric in shown:
        table.add_column(f"{metric.name}\n{escape(metric.unit)}", justify="right")
    for method, point, values in rows:
        labels = (escape(method), escape(point)) if swept else (escape(method),)
        table.add_row(*labels, *(metric.shown(values.get(metric.name)) for metric in shown))
    return table


@app.command()
def run(
    experiment: str | None = typer.Argument(None, help="Experiment file, or the name of a built-in one; "
                                                          "default: the built-in default experiment."),
    out: Path | None = typer.Option(None, "--out", help="Results directory; default reports/<name>/."),
    frames: int | None = typer.Option(None, "--frames", help="Cap on frames (overrides camera.frames)."),
    jobs: int | None = typer.Option(None, "--jobs", help="Local worker processes; default all cores "
                                                            "(1 runs in this process; with --scheduler local: "
                                                            "Dask workers)."),
    scheduler: str | None = typer.Option(None, "--scheduler", help="Dask: 'local' (a LocalCluster) or "
                                                                      "tcp://HOST:PORT (a running scheduler)."),
    device: str = typer.Option("cpu", "--device", help="Warp device: cpu or cuda."),
    resume: bool = typer.Option(False, "--resume", help="Continue an interrupted run in the same directory."),
) -> None:
    """Run an experiment: every frame × method × sweep point → metrics.csv, summary.json, the report."""
    from csmlab.config import find_experiment, load_experiment
    from csmlab.executor import executor_for, start_process_server

    try:
        _count(frames, "--frames")
        loaded = load_experiment(find_experiment(experiment), frames=frames)
        executor, workers, address = executor_for(jobs=_count(jobs, "--jobs"), scheduler=scheduler)
    except ValueError as exc:
        raise _bad_input(exc) from None
    if executor == "pool":
        # Started once the experiment reads well, before anything else: the workers' process
        # server imports their modules while this process imports its own and builds the workload.
        start_process_server()
    from csmlab.experiment import check_device, run_experiment
    from csmlab.paths.timing import timing_lines
    from csmlab.paths.view_check import findings_line
    from csmlab.scene.gltf_materials import blend_line
    from csmlab.report import write_report

    try:
        check_device(device)
        out_dir = _output_folder(out if out is not None else Path("reports") / loaded.name, "--out")
    except ValueError as exc:
        raise _bad_input(exc) from None
    bar = Progress(TextColumn("[bold]{task.description}"), BarColumn(), MofNCompleteColumn(), TextColumn("frames"),
                   TimeElapsedColumn(), TextColumn("ETA"), TimeRemainingColumn(), console=_err(), transient=True)
    tasks = []

    def progress(done: int, total: int) -> None:
        # Started on the first report, after every input was read: a bad input prints its one line alone.
        if not tasks:
            bar.start()
            tasks.append(bar.add_task(loaded.name, total=total))
        bar.update(tasks[0], completed=done, total=total)

    try:
        result = run_experiment(loaded, out_dir=out_dir, jobs=workers, executor=executor, address=address,
                                device=device, resume=resume, progress=progress)
    except InputError as exc:
        raise _bad_input(exc) from None
    except KeyboardInterrupt:
        bar.stop()
        typer.echo(f"csmlab: interrupted; finished chunks are kept: add --resume to continue in {out_dir}", err=True)
        raise typer.Exit(code=130) from None
    finally:
        bar.stop()
    began = time.perf_counter()
    written = write_report(out_dir)
    report_seconds = time.perf_counter() - began
    console = _out()
    console.print(_summary_table(result.summary))
    for line in timing_lines(result.summary.get("recording")):
        console.print(line)
    for line in (findings_line(result.summary.get("view_check")), blend_line(result.summary.get("blend_materials"))):
        if line:
            _err().print(f"csmlab: warning: {escape(line)}")
    resumed = f", {result.chunks_resumed} unit(s) of work resumed" if result.chunks_resumed else ""
    where = (f"dask at {address}" if executor == "dask" and address != "local"
             else f"{executor}, {workers} process(es)")
    console.print(f"{result.frames} frames × {len(loaded.variants())} method/point(s) in {result.seconds:.1f} s "
                  f"({where}, {device}{resumed}); report in {report_seconds:.1f} s")
    console.print(f"results: {out_dir}/metrics.csv, {out_dir}/summary.json")
    console.print(_report_lines(written, label="report:  "))


@app.command()
def report(results_dir: Path = typer.Argument(..., help="A results directory of csmlab run.")) -> None:
    """Re-render the HTML report of a results directory from its files."""
    from csmlab.report import write_report
    from csmlab.results import read_summary

    try:
        read_summary(results_dir)
    except ValueError as exc:
        raise _bad_input(exc) from None
    _out().print(_report_lines(write_report(results_dir), label="report: "))


def _report_lines(written, *, label: str) -> str:
    """``label`` and the page of a :class:`csmlab.report.WrittenReport` (the line scripts read the path
    from, as before), then, when it has Explore, a line of what its size budget kept."""
    page = f"{label}{escape(str(written.page))}"
    return page if written.kept is None else f"{page}\nbudget:  {escape(written.kept)}"


@app.command()
def jod(results_dir: Path = typer.Argument(..., help="A results directory of csmlab run."),
        display: str = typer.Option("standard_fhd", "--display", help="ColorVideoVDP's display model.")) -> None:
    """Score each method's sequence with ColorVideoVDP (JOD) against the ray-traced one; redraw the report."""
    from csmlab.report import write_report
    from csmlab.report.video_quality import cvvdp_missing, write_jod

    missing = cvvdp_missing()
    if missing:
        raise _bad_input(InputError(missing, field="jod"))
    try:
        scores = write_jod(results_dir, display=display)
    except ValueError as exc:
        raise _bad_input(exc) from None
    console = _out()
    for name, by_stem in scores["sequences"].items():
        for stem, value in by_stem.items():
            console.print(f"{name}  {escape(stem)}  JOD {value:.3f}")
    console.print(_report_lines(write_report(results_dir), label="report: "))


def _regress_table(result) -> Table:
    table = Table(title=escape(f"regress against {result.baseline} (per-cascade metrics shown when they fail)"),
                  title_justify="left")
    for name, justify in (("metric", "left"), ("method", "left"), ("point", "left"), ("baseline", "right"),
                          ("now", "right"), ("delta", "right"), ("allowed", "right"), ("verdict", "left")):
        table.add_column(name, justify=justify)
    styles = {"regression": "bold red", "missing": "bold red", "invariant broken": "bold red", "better": "green",
              "invariant": "green"}
    shown = [c for c in result.checks if c.failed or not re.search(r"_c\d+$", c.metric)]
    for c in sorted(shown, key=lambda c: not c.failed):
        style = styles.get(c.verdict, "")
        table.add_row(c.metric, escape(c.method), escape(c.point), _number(c.baseline), _number(c.now),
                      "—" if c.delta is None else f"{c.delta:+.4g}", _number(c.allowed),
                      f"[{style}]{c.verdict}[/]" if style else c.verdict)
    return table


@app.command()
def regress(
    results_dir: Path = typer.Argument(..., help="A results directory of csmlab run."),
    baseline: Path = typer.Option(..., "--baseline", help="A baseline file (csmlab baseline writes one)."),
    tolerances: Path | None = typer.Option(None, "--tolerances", help="TOML of metric = { abs = …, rel = … } "
                                                                         "overrides."),
    junit: Path | None = typer.Option(None, "--junit", help="Also write the verdict as JUnit XML (one test case "
                                                               "per method × metric check) for the CI's test report."),
    markdown: Path | None = typer.Option(None, "--markdown", help="Also write a Markdown summary (verdict, what "
                                                                     "moved, worst frames) for a PR comment."),
) -> None:
    """Compare a run's summary with a baseline: exit 1 when a metric moved the wrong way beyond tolerance."""
    from csmlab.config import load_tolerances
    from csmlab.regress import regress as compare_with_baseline
    from csmlab.report import write_report
    from csmlab.verdict import write_junit, write_markdown

    try:
        for path, option in ((junit, "--junit"), (markdown, "--markdown")):
            if path is not None:
                _output_file(path, option)
        overrides = load_tolerances(tolerances) if tolerances is not None else None
        result = compare_with_baseline(results_dir, baseline, tolerances=overrides)
        if junit is not None:
            write_junit(result, results_dir, junit)
        if markdown is not None:
            write_markdown(result, results_dir, markdown)
    except ValueError as exc:
        raise _bad_input(exc) from None
    console = _out()
    console.print(_regress_table(result))
    write_report(results_dir)
    if result.passed:
        console.print(f"regress: pass ({len(result.checks)} checks)")
        return
    names = dict.fromkeys(f"{c.metric} of {c.method}" + ("" if c.point == "*" else f" at {c.point}")
                          for c in result.failures)
    console.print(f"regress: FAIL — {len(names)} regression(s): {', '.join(names)}")
    raise typer.Exit(code=1)


@app.command()
def baseline(
    results_dir: Path = typer.Argument(..., help="A results directory of csmlab run."),
    out: Path = typer.Option(..., "--out", help="The baseline file to write (JSON)."),
) -> None:
    """Write a baseline of a run deliberately, for csmlab regress."""
    from csmlab.regress import write_baseline

    try:
        path = write_baseline(results_dir, _output_file(out, "--out"))
    except ValueError as exc:
        raise _bad_input(exc) from None
    _out().print(f"baseline: {path}")


@app.command()
def compare(
    run_a: Path = typer.Argument(..., help="Results directory of run A (the reference)."),
    run_b: Path = typer.Argument(..., help="Results directory of run B (the change), of the same workload."),
    out: Path | None = typer.Option(None, "--out", help="Where the comparison report goes; default "
                                                          "reports/compare/<A>-vs-<B>/."),
) -> None:
    """Compare two runs of one workload, A against B: metric deltas, per-frame curves, images, settings."""
    from csmlab.report.comparison import write_comparison_report

    out_dir = out if out is not None else Path("reports") / "compare" / f"{run_a.name}-vs-{run_b.name}"
    try:
        page = write_comparison_report(run_a, run_b, _output_folder(out_dir, "--out"))
    except ValueError as exc:
        raise _bad_input(exc) from None
    _out().print(f"comparison: {page}")


def _names_table(title: str, rows) -> Table:
    table = Table(title=escape(title), title_justify="left", show_header=False)
    table.add_column("name", style="bold")
    table.add_column("about")
    for name, about in rows:
        table.add_row(escape(name), escape(about))
    return table


def _about(obj) -> str:
    """A registry entry's ``description``, else the first line of its docstring."""
    doc = getattr(obj, "description", None) or getattr(obj, "__doc__", None) or ""
    return doc.strip().splitlines()[0] if doc.strip() else ""


@app.command("list")
def list_names() -> None:
    """List scenes, camera paths, file formats, conventions, settings by group, methods, presets, experiments and
    importers."""
    from dataclasses import fields

    from csmlab.config import TaaConfig, list_experiments, list_presets, shadow_method_registries
    from csmlab.config.records import TAA_CLAMPS
    from csmlab.engines import IMPORT_METHODS
    from csmlab.paths import CONVENTIONS, PATH_FORMATS, PATH_GENERATORS
    from csmlab.scene import SCENE_KINDS
    from csmlab.settings import SETTING_GROUPS

    console = _out()
    console.print(_names_table("scenes ([scene] kind)", [(k, _about(v)) for k, v in SCENE_KINDS.items()]))
    console.print(_names_table("camera paths ([camera] path)",
                               [(k, _about(v)) for k, v in PATH_GENERATORS.items()]))
    console.print(_names_table("path file formats ([camera] format)",
                               [(k, _about(v)) for k, v in PATH_FORMATS.items()]))
    console.print(_names_table("camera conventions ([camera] convention)",
                               [(k, _about(v)) for k, v in CONVENTIONS.items()]))
    console.print(_names_table("settings by group ([shadow] and [[methods]] fields; the [taa] table)", [
        *((group.name, f"{group.title}{f' (only with {group.applies.when})' if group.applies else ''}: "
                       f"{', '.join(group.fields)}") for group in SETTING_GROUPS),
        ("[taa]", f"temporal anti-aliasing of every method: {', '.join(f.name for f in fields(TaaConfig))}")]))
    console.print(_names_table("shadow methods ([shadow] and [[methods]] fields; the [taa] clamp)", [
        *((field, ", ".join(registry)) for field, registry in shadow_method_registries().items()),
        ("[taa] clamp", ", ".join(TAA_CLAMPS))]))
    console.print(_names_table("presets (extends = [...])", list_presets().items()))
    console.print(_names_table("experiments (csmlab run NAME)", list_experiments().items()))
    console.print(_names_table("engine files (csmlab import ENGINE FILE...)",
                               [(k, v.files) for k, v in IMPORT_METHODS.items()]))


@app.command()
def show(experiment: str | None = typer.Argument(None, help="Experiment file or built-in name; default: the "
                                                               "default experiment.")) -> None:
    """Print an experiment resolved: presets merged, every field with its documentation, and its hashes; then its
    scene, camera path and light as loaded and checked (a bad mesh, path or sun stops here, not at run)."""
    from csmlab.config import config_hash, experiment_toml, find_experiment, load_experiment
    from csmlab.experiment import build_workload

    try:
        loaded = load_experiment(find_experiment(experiment))
        hash_ = config_hash(loaded)
        workload = build_workload(loaded)
    except ValueError as exc:
        raise _bad_input(exc) from None
    typer.echo(experiment_toml(loaded))
    typer.echo(f"# config hash {hash_}; {len(loaded.variants())} method/point(s)")
    for line in _workload_lines(loaded, workload):
        typer.echo(f"# {line}")


def _workload_lines(loaded, workload) -> list[str]:
    """What ``csmlab show`` says of the loaded scene, camera path, light and their checks (comment lines)."""
    from csmlab.experiment import fits_level
    from csmlab.paths.view_check import findings_line
    from csmlab.scene.gltf_materials import blend_line

    scene, path, light = workload.scene, workload.path, loaded.light
    lo, hi = scene.bounds
    masked = f", {int((scene.vertex_mask[scene.triangles[:, 0]] >= 0).sum())} alpha-tested" if scene.masked else ""
    how = ("fitted to the level" if fits_level(loaded) else "as generated") if loaded.camera.path else "from the file"
    source = loaded.camera.path or Path(loaded.camera.file).name
    if light.from_scene:
        sun = "the scene file's sun (KHR_lights_punctual)"
    elif light.direction is not None:
        sun = "direction"
    else:
        sun = "sun angles" + ("" if light.is_static else ", moving")
    lines = [
        f"scene: {scene.name}, {scene.triangle_count} triangles{masked}, bounds "
        f"({lo[0]:.4g}, {lo[1]:.4g}, {lo[2]:.4g}) to ({hi[0]:.4g}, {hi[1]:.4g}, {hi[2]:.4g}) m",
        f"camera: {len(path)} frames of {source} ({how}), {workload.width}×{workload.height}, first eye at "
        f"({path.positions[0, 0]:.4g}, {path.positions[0, 1]:.4g}, {path.positions[0, 2]:.4g}) m",
        "light: {} → ({:.4f}, {:.4f}, {:.4f}) at frame 0".format(sun, *workload.light.direction(0)),
        findings_line(None if workload.views is None else workload.views.as_dict())
        or ("view check: off" if workload.views is None else f"view check: all {len(path)} views fit the scene"),
    ]
    blend = blend_line(workload.blend)
    return lines + ([blend] if blend else [])


@app.command()
def tune(
    experiment: str = typer.Argument(..., help="Experiment file or built-in name: the workload, the method and "
                                               "its \\[tune] table."),
    param: list[str] | None = typer.Option(None, "--param", help="A \\[shadow] field to search: FIELD=LO:HI (a "
                                              "range) or FIELD=A,B,C (choices); repeat for more; adds to \\[tune]."),
    objective: list[str] | None = typer.Option(None, "--objective", help="A metrics.csv column to improve (mean "
                                                  "over frames); repeat for several. Default: \\[tune] objectives, "
                                                  "else rho_p05."),
    memory_budget: str | None = typer.Option(None, "--memory-budget", help="Shadow-map memory a recommended "
                                                "setting may not exceed: 64MiB, 16MB or bytes."),
    max_flicker: str | None = typer.Option(None, "--max-flicker", help="Largest flicker (--flicker-metric) a "
                                              "recommended setting may have: a number, or best-preset."),
    flicker_metric: str | None = typer.Option(None, "--flicker-metric", help="The flicker column the limit "
                                                 "applies to; default flicker."),
    method: str | None = typer.Option(None, "--method", help="The method to tune; default the first."),
    trials: int | None = typer.Option(None, "--trials", help="Candidates to search; default \\[tune] trials, "
                                                                "else 20."),
    batch: int = typer.Option(4, "--batch", help="Candidates run together (they share each frame's view); a "
                                                 "resumed tune must use the same."),
    frames: int | None = typer.Option(None, "--frames", help="Cap on frames (overrides camera.frames)."),
    out: Path | None = typer.Option(None, "--out", help="Where the tune goes; default reports/<name>/tune/."),
    jobs: int | None = typer.Option(None, "--jobs", help="Local worker processes per run; default all cores."),
    scheduler: str | None = typer.Option(None, "--scheduler", help="Dask: 'local' or tcp://HOST:PORT."),
    device: str = typer.Option("cpu", "--device", help="Warp device: cpu or cuda."),
    seed: int | None = typer.Option(None, "--seed", help="Sampler seed (the same seed repeats the search)."),
    presets: Path | None = typer.Option(None, "--presets", help="A folder of method presets to compare with; "
                                                                   "default configs/engines."),
) -> None:
    """Find the best shadow setting within memory and flicker budgets, against every engine preset."""
    from csmlab.config import find_experiment, load_experiment, parse_size
    from csmlab.executor import executor_for
    from csmlab.tune import InfeasibleBudget, engine_presets, parse_space, tune as run_tuning

    from csmlab.experiment import check_device

    try:
        _count(frames, "--frames")
        _count(trials, "--trials")
        _count(batch, "--batch")
        loaded = load_experiment(find_experiment(experiment), frames=frames)
        executor, workers, address = executor_for(jobs=_count(jobs, "--jobs"), scheduler=scheduler)
        check_device(device)
        base = next((m.settings for m in loaded.methods if m.name == method), loaded.methods[0].settings)
        space = parse_space(param or [], settings=base)
        try:
            budget = None if memory_budget is None else parse_size(
                int(memory_budget) if memory_budget.isdigit() else memory_budget)
        except ValueError as exc:
            raise InputError(str(exc), field="--memory-budget") from None
        try:
            limit = max_flicker if max_flicker in (None, "best-preset") else float(max_flicker)
        except ValueError:
            raise InputError(f'expected a non-negative number or "best-preset", got {max_flicker!r}',
                             field="--max-flicker") from None
        out_dir = _output_folder(out if out is not None else Path("reports") / loaded.name / "tune", "--out")
        if presets is not None and not presets.is_dir():
            raise InputError("expected a folder of method presets (*.toml), got no such folder", file=presets,
                             field="--presets")
    except ValueError as exc:
        raise _bad_input(exc) from None
    bar = Progress(TextColumn("[bold]{task.description}"), BarColumn(), MofNCompleteColumn(), TextColumn("candidates"),
                   TimeElapsedColumn(), TextColumn("ETA"), TimeRemainingColumn(), console=_err(), transient=True)
    tasks = []

    def progress(done: int, total: int, label: str) -> None:
        if not tasks:
            bar.start()
            tasks.append(bar.add_task(f"tuning {loaded.name}", total=total))
        bar.update(tasks[0], completed=done, total=total, description=f"tuning {loaded.name}: {label}")

    try:
        result = run_tuning(loaded, out_dir=out_dir, space=space, objectives=objective, trials=trials, method=method,
                            seed=seed, memory_budget=budget, max_flicker=limit, flicker_metric=flicker_metric,
                            batch=batch, jobs=workers, executor=executor, address=address, device=device,
                            presets=None if presets is None else engine_presets(presets), progress=progress)
    except InfeasibleBudget as exc:
        bar.stop()
        typer.echo(f"csmlab: every trial is in the tune report {out_dir / 'index.html'}", err=True)
        raise _bad_input(exc) from None
    except ValueError as exc:
        raise _bad_input(exc) from None
    finally:
        bar.stop()
    console = _out()
    console.print(_tune_table(result))
    console.print(f"{len(result.trials)} trial(s) ({result.sampler}), {result.runs_computed} run now, the rest cached")
    console.print(f"recommended: {result.recommended.label} → {out_dir / 'recommended.toml'}; engine snippets in "
                  f"{out_dir / 'exports'}")
    console.print(f"report:  {out_dir / 'index.html'}")


@app.command("import")
def import_(
    engine: str = typer.Argument(..., help="The engine (csmlab list names each with its files)."),
    files: list[Path] = typer.Argument(..., help="The engine's own files (README.md, 'Your engine's settings')."),
    out: Path = typer.Option(..., "--out", help="The method preset to write (TOML, for extends)."),
    name: str | None = typer.Option(None, "--name", help="The method's name; default the file's stem."),
) -> None:
    """Read an engine's shadow settings from its own files as a method preset: each field commented with the file
    and key it came from, the engine settings csmlab cannot model listed. A Godot scene that instances glTF files
    also gives the level (``[scene]`` parts placed by the nodes' transforms, and a walk in it): the file then runs;
    instances csmlab cannot read are listed as not imported."""
    import tempfile

    from csmlab.config import load_experiment
    from csmlab.engines import import_settings, level_instances, level_toml, preset_toml
    from csmlab.files import write_atomic

    try:
        method = _method_name(name, "--name") if name is not None else _method_name(out.stem, "--out")
        _output_file(out, "--out")
        imported = import_settings(files, engine=engine)
        instances, not_imported = level_instances(files, engine=engine)
        preset = preset_toml(imported, name=method, files=files) + "".join(
            f"# not imported: {' '.join(line.split())}\n" for line in not_imported)
        text = preset + level_toml(instances, out=out)
        with tempfile.TemporaryDirectory() as folder:
            # The preset must load as csmlab loads it: a value the engine allows but csmlab refuses is bad input.
            probe = preset + level_toml(instances, out=Path(folder) / "preset.toml")
            (Path(folder) / "preset.toml").write_text(probe, encoding="utf-8")
            (Path(folder) / "probe.toml").write_text('extends = ["preset.toml"]\n[camera]\npath = "walk"\n',
                                                      encoding="utf-8")
            try:
                load_experiment(Path(folder) / "probe.toml")
            except InputError as exc:
                # Name the engine's file and key the refused value came from (origins: "file name: key = value").
                field = (exc.field or "").rsplit(".", 1)[-1]
                origin = imported.origins.get("lambda_" if field == "lambda" else field, "")
                source, _, key = origin.partition(": ")
                raise InputError(exc.detail, file=next((f for f in files if f.name == source), files[0]),
                                 field=key.split(" = ", 1)[0] or field) from None
    except ValueError as exc:
        raise _bad_input(exc) from None
    write_atomic(out, text)
    console = _out()
    console.print(f"{engine}: {len(imported.origins)} field(s) from {len(files)} file(s), "
                  f"{len(imported.unmodelled)} setting(s) not modelled → {out}")
    for item in imported.unmodelled:
        console.print(f"  not modelled: {escape(item)}")
    if instances:
        console.print(escape(f"  level: {len(instances)} glTF instance(s) as [[scene.parts]], a walk in it as "
                             "[camera]"))
    for line in not_imported:
        console.print(f"  not imported: {escape(line)}")


def _tune_table(result) -> Table:
    """The recommended setting, the start and every engine preset: memory, ρ and flicker (name over unit, as the
    registry shows them)."""
    from csmlab.metric_registry import METRICS

    flicker = result.budgets.flicker_metric
    names = ["rho_p05", "rho_median", "flicker_same", *([flicker] if flicker != "flicker_same" else []), "flip_rate"]
    metrics = [METRICS[name] for name in names]
    memory = METRICS["memory_bytes"]
    table = Table(title=escape(f"{result.name}: {result.method} tuned over {result.frames} frames"),
                  title_justify="left")
    table.add_column("setting")
    table.add_column("changes")
    for metric in (memory, *metrics):
        table.add_column(f"{metric.name}\n{escape(metric.unit)}", justify="right")
    table.add_column("budgets")
    rows = [result.recommended, *result.references]
    for c in rows:
        changes = ", ".join(f"{k}={v:.4g}" if isinstance(v, float) else f"{k}={v}" for k, v in c.params.items())
        over = [name for name, v in c.violations.items() if v > 0]
        label = f"[bold]{escape(c.label)} (recommended)[/]" if c is result.recommended else escape(c.label)
        table.add_row(label, escape(changes or "—"), memory.shown(c.memory_bytes),
                      *(m.shown(None if c.values is None else c.values.get(m.name)) for m in metrics),
                      "over " + ", ".join(over) if over else "within")
    return table


def main() -> None:
    """Entry point of the ``csmlab`` console script."""
    freeze_objects_at_exit()
    app(prog_name="csmlab")


if __name__ == "__main__":
    sys.exit(main())
