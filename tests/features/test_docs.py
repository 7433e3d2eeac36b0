"""docs/ stays true: the design documents every interface, and every file the docs name exists.

``docs/design.md`` is the contract users' scripts and CI jobs rely on: every ``csmlab`` subcommand
and option, every experiment TOML field, every ``metrics.csv`` metric and every ``summary.json``
key the code has must be written there (an interface added without its documentation fails here).
"""

from __future__ import annotations

import dataclasses
import inspect
import re

import pytest
from tests.locations import ROOT

DESIGN = ROOT / "docs" / "design.md"
DOCS = sorted((ROOT / "docs").glob("*.md"))


def _design() -> str:
    return DESIGN.read_text(encoding="utf-8")


def _words(text: str) -> set[str]:
    return set(re.findall(r"[A-Za-z_][\w]*", text))


def _cli_synopsis(command: str) -> str:
    """The lines of the design's command-line block that begin ``csmlab COMMAND``, with their continuations."""
    block = re.search(r"### Command line\n+```\n(.*?)```", _design(), flags=re.S)
    assert block, "docs/design.md should hold the command line in a fenced block under '### Command line'"
    found, inside = [], False
    for line in block.group(1).splitlines():
        if line.startswith("csmlab "):
            inside = line.split()[1] == command
        if inside:
            found.append(line)
    return "\n".join(found)


def test_the_design_documents_every_subcommand_and_option():
    import typer.main

    from csmlab.cli import app

    missing = []
    for name, command in typer.main.get_command(app).commands.items():
        synopsis = _cli_synopsis(name)
        if not synopsis:
            missing.append(f"csmlab {name}")
        missing += [f"csmlab {name} {option}" for p in command.params for option in p.opts
                    if option.startswith("--") and option != "--help" and option not in synopsis.split()
                    and not any(word.startswith(option) for word in synopsis.replace("[", " ").split())]
    assert not missing, f"docs/design.md, 'Command line', lacks: {', '.join(missing)}"


def _record_fields(record) -> set[str]:
    return {"lambda" if f.name == "lambda_" else f.name for f in dataclasses.fields(record)} - {"params", "space"}


def test_the_design_documents_every_experiment_field():
    from csmlab.config.records import CameraConfig, LightConfig, ReportConfig, SceneConfig, TaaConfig, TuneConfig
    from csmlab.settings import ShadowSettings

    words = _words(_design().split("### Experiment file (TOML)", 1)[1].split("### Results directory", 1)[0])
    missing = {table: sorted(_record_fields(record) - words)
               for table, record in [("scene", SceneConfig), ("camera", CameraConfig), ("light", LightConfig),
                                     ("shadow", ShadowSettings), ("report", ReportConfig), ("tune", TuneConfig),
                                     ("taa", TaaConfig)]}
    missing = {table: names for table, names in missing.items() if names}
    assert not missing, f"docs/design.md, 'Experiment file (TOML)', lacks: {missing}"


def test_the_design_documents_every_metric_and_summary_key():
    from csmlab import metric_registry
    from csmlab.metric_registry import METRICS
    from csmlab.results import write_summary

    text = _design()
    columns = _words(text.split("`metrics.csv` columns:", 1)[1].split("(C: the most", 1)[0])
    assert not [name for name in METRICS if name not in columns], "a metric of the registry is not in docs/design.md"
    derived = getattr(metric_registry, "DERIVED", {})
    assert not [name for name in derived if f"`{name}`" not in text], "a derived metric is not in docs/design.md"
    keys = [name for name in inspect.signature(write_summary).parameters if name not in ("path", "device")]
    summary = text.split("`summary.json`: ", 1)[1]
    assert not [key for key in keys if f'"{key}"' not in summary], "a summary.json key is not in docs/design.md"


@pytest.mark.parametrize("doc", DOCS, ids=[d.name for d in DOCS])
def test_every_file_and_folder_the_docs_name_exists(doc):
    text = doc.read_text(encoding="utf-8")
    top = "(?:csmlab|tests|benchmarks|experiments|configs|docs|data)"  # reports/ is output, made by runs
    files = set(re.findall(rf"`({top}/[a-z0-9_/.-]+\.(?:py|toml|md|png))`", text))
    folders = set(re.findall(rf"`({top}/(?:[a-z0-9_.-]+/)*)`", text))
    absent = sorted([n for n in files if not (ROOT / n).is_file()] + [n for n in folders if not (ROOT / n).is_dir()])
    assert not absent, f"{doc.name} names what is not there: {absent}"
