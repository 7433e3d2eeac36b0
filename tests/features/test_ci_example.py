"""README's GitHub Actions job: valid YAML, and every csmlab command and flag it runs exists in the CLI."""

from __future__ import annotations

import re
import shlex
from pathlib import Path

import typer.main
import yaml

from csmlab.cli import app
from tests.locations import ROOT

README = ROOT / "README.md"


def _ci_job() -> dict:
    blocks = re.findall(r"```yaml\n(.*?)```", README.read_text(encoding="utf-8"), flags=re.S)
    jobs = [doc for doc in map(yaml.safe_load, blocks) if isinstance(doc, dict) and "jobs" in doc]
    assert len(jobs) == 1, "README.md should hold one GitHub Actions workflow in a ```yaml block"
    return jobs[0]


def _steps() -> list[dict]:
    return [step for job in _ci_job()["jobs"].values() for step in job["steps"]]


def _csmlab_calls(script: str) -> list[list[str]]:
    """Every ``csmlab`` invocation (any path to the console script) in a shell script, as argument lists."""
    calls = []
    for line in script.replace("\\\n", " ").splitlines():
        words = shlex.split(line.replace("(", " ").replace(")", " "))
        for k, word in enumerate(words):
            if Path(word).name == "csmlab":
                call = []
                for arg in words[k + 1:]:
                    if arg in ("&&", "||", ";", "|"):
                        break
                    call.append(arg)
                calls.append(call)
    return calls


def test_every_csmlab_subcommand_and_flag_of_the_readme_ci_job_exists():
    cli = typer.main.get_command(app)
    calls = [call for step in _steps() if "run" in step for call in _csmlab_calls(step["run"])]
    assert {call[0] for call in calls} >= {"run", "regress", "compare"}
    for call in calls:
        assert call[0] in cli.commands, f"csmlab has no subcommand {call[0]!r}"
        options = {opt for param in cli.commands[call[0]].params for opt in param.opts if opt.startswith("--")}
        flags = {arg.split("=")[0] for arg in call[1:] if arg.startswith("--")}
        assert flags <= options, f"csmlab {call[0]} has no {sorted(flags - options)}"


def test_readme_ci_job_publishes_the_files_the_gate_writes():
    steps = _steps()
    regress = next(c for s in steps if "run" in s for c in _csmlab_calls(s["run"]) if c[0] == "regress")
    junit, markdown = regress[regress.index("--junit") + 1], regress[regress.index("--markdown") + 1]
    run = next(c for s in steps if "run" in s for c in _csmlab_calls(s["run"]) if c[0] == "run")
    report_dir = run[run.index("--out") + 1]
    uploaded = [s["with"]["path"] for s in steps if s.get("uses", "").startswith("actions/upload-artifact")]
    assert [p.rstrip("/") for p in uploaded] == [report_dir]
    published = [s["with"]["report_paths"] for s in steps if "junit" in s.get("uses", "")]
    assert published == [junit]
    assert any(markdown in s.get("run", "") and "$GITHUB_STEP_SUMMARY" in s["run"] for s in steps)
    assert all(s.get("if") == "always()" for s in steps if "uses" in s and "with" in s and "path" in s["with"])
