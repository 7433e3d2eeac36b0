"""README stays true: its map of the house, its list of experiments and its minimal experiment.

- "The house" (the first code block under that heading) names every module of ``csmlab/`` — a
  top-level module or package by its file name (``geometry.py``, ``kernels/``), a module inside a
  package by its name in that package's entry — every preset of ``configs/``, every file of
  ``docs/`` and ``benchmarks/``; and everything it names exists.
- The experiments table lists every ``experiments/*.toml`` with its ``description``, generated:
  ``python -m tests.features.test_readme`` prints the table to paste when an experiment is added.
- README's minimal experiment is ``experiments/minimal.toml`` byte for byte, and it runs as a user
  runs it (``csmlab run``, at a tiny size here) without Warp's CUDA-driver warning.
"""

from __future__ import annotations

import re
import subprocess
import sys
import tomllib
from pathlib import Path

import pytest
from tests.locations import ROOT

README = ROOT / "README.md"
PACKAGE = ROOT / "csmlab"

_NAMED = re.compile(r"^[A-Za-z_][\w.-]*(\.py|\.toml|\.md|\.png|/)$")


def _readme() -> str:
    return README.read_text(encoding="utf-8")


def house_block(text: str) -> str:
    """The first fenced block under README's "## The house"."""
    section = text.split("\n## The house", 1)[1]
    match = re.search(r"```[a-z]*\n(.*?)```", section, flags=re.S)
    assert match, "README's 'The house' should hold the map in a fenced code block"
    return match.group(1)


def house_map(block: str) -> dict[str, list[tuple[str, str]]]:
    """``{root: [(head, text), ...]}``: the map's top-level folders and, under each, its entries.

    A line at indent 0 opens a root (``csmlab/``), its words after the name an entry with an empty
    head; a line at indent 2 opens an entry, whose head is its first word; a more indented line
    continues the entry above it.
    """
    roots: dict[str, list[tuple[str, str]]] = {}
    root = None
    for line in block.splitlines():
        if not line.strip():
            continue
        indent = len(line) - len(line.lstrip(" "))
        words = line.split()
        if indent == 0:
            root = words[0]
            roots[root] = [("", " ".join(words[1:]))] if len(words) > 1 else []
        elif indent == 2:
            assert root is not None, f"map line outside a folder: {line!r}"
            roots[root].append((words[0], line.strip()))
        else:
            assert root is not None and roots[root], f"continuation line without an entry: {line!r}"
            head, text = roots[root][-1]
            roots[root][-1] = (head, f"{text} {line.strip()}")
    return roots


def _tokens(text: str) -> list[str]:
    """The file and folder names an entry's text mentions (``splits.py``, ``kernels/``)."""
    return [t for t in (w.strip(",;:()") for w in text.split()) if _NAMED.match(t)]


def _words(text: str) -> set[str]:
    return set(re.findall(r"[A-Za-z_][\w]*", text))


def _modules(package: Path) -> list[Path]:
    """Every module and subpackage below ``package``, ``__init__.py`` and caches left out."""
    found = []
    for path in sorted(package.rglob("*")):
        if "__pycache__" in path.parts:
            continue
        if path.is_file() and path.suffix == ".py" and path.name != "__init__.py":
            found.append(path)
        elif path.is_dir() and (path / "__init__.py").is_file():
            found.append(path)
    return found


def _description(path: Path) -> str:
    return tomllib.loads(path.read_text(encoding="utf-8")).get("description", "")


def experiments_table() -> str:
    """README's table of experiments, from each file's ``description``."""
    rows = ["| experiment | what it shows |", "| --- | --- |"]
    for path in sorted((ROOT / "experiments").glob("*.toml")):
        rows.append(f"| [`{path.stem}`](experiments/{path.name}) | {_description(path)} |")
    return "\n".join(rows) + "\n"


@pytest.fixture(scope="module")
def house():
    return house_map(house_block(_readme()))


def test_the_house_names_every_module_of_csmlab(house):
    entries = house["csmlab/"]
    named = {token for _, text in entries for token in _tokens(text)}
    missing = []
    for path in _modules(PACKAGE):
        relative = path.relative_to(PACKAGE)
        name = relative.name + ("/" if path.is_dir() else "")
        if len(relative.parts) == 1:
            if name not in named:
                missing.append(name)
            continue
        package = relative.parts[0] + "/"
        text = " ".join(t for head, t in entries if head == package)
        if not text:
            missing.append(package)
        elif path.stem not in _words(text) and name not in _tokens(text):
            missing.append(str(relative))
    assert not missing, f"README's 'The house' does not name: {', '.join(missing)}"


def test_every_name_in_the_house_exists(house):
    absent = []
    for root, entries in house.items():
        folder = ROOT / root
        if not folder.is_dir():
            absent.append(root)
            continue
        for head, text in entries:
            within = folder / head if head.endswith("/") and (folder / head).is_dir() else folder
            for token in _tokens(text):
                if not any((base / token.rstrip("/")).exists() for base in (within, folder)):
                    absent.append(f"{root}{token}")
    assert not absent, f"README's 'The house' names what is not there: {', '.join(absent)}"


def test_the_house_names_every_preset(house):
    configs = ROOT / "configs"
    entries = dict(house["configs/"])
    kinds = sorted(p.name + "/" for p in configs.iterdir() if p.is_dir())
    assert sorted(head for head in entries if head.endswith("/")) == kinds
    for kind in kinds:
        listed = sorted(_words(entries[kind].removeprefix(kind)))
        assert listed == sorted(p.stem for p in (configs / kind).glob("*.toml")), kind


@pytest.mark.parametrize("folder, pattern", [("docs", "*"), ("benchmarks", "*.py"), ("benchmarks", "*.toml")])
def test_the_house_names_every_file_of(house, folder, pattern):
    named = {token for _, text in house[f"{folder}/"] for token in _tokens(text)}
    files = sorted(p.name for p in (ROOT / folder).glob(pattern) if p.is_file())
    assert files and not [name for name in files if name not in named], folder


def test_the_experiments_table_lists_every_experiment_with_its_description():
    table = experiments_table()
    assert table in _readme(), ("README's experiments table should read (python -m tests.features.test_readme):\n"
                                f"{table}")


def test_every_experiment_and_preset_has_a_description():
    files = [*(ROOT / "experiments").glob("*.toml"), *(ROOT / "configs").glob("*/*.toml")]
    assert files and not [p.name for p in files if not _description(p).strip()]


def test_readme_holds_the_minimal_experiment_as_shipped():
    blocks = re.findall(r"```toml\n(.*?)```", _readme(), flags=re.S)
    minimal = (ROOT / "experiments" / "minimal.toml").read_text(encoding="utf-8")
    assert minimal in blocks, "README's minimal experiment should be experiments/minimal.toml, byte for byte"


TINY = """
extends = ["{path}"]
chunk_frames = 1

[scene]
resolution = 24
trees = 60
ring_trees = 60

[camera]
width = 32
height = 18

[shadow]
resolution = 64
"""


@pytest.mark.slow
def test_the_minimal_experiment_runs_on_the_cpu_without_warps_cuda_warning(tmp_path):
    # As a user runs it: the command line, a pool of two worker processes, each of which starts Warp.
    path = tmp_path / "minimal_tiny.toml"
    path.write_text(TINY.format(path=(ROOT / "experiments" / "minimal.toml").as_posix()))
    done = subprocess.run([sys.executable, "-m", "csmlab.cli", "run", str(path), "--frames", "3", "--jobs", "2",
                           "--out", str(tmp_path / "out")], capture_output=True, text=True, timeout=600, cwd=tmp_path)
    assert done.returncode == 0, done.stderr
    assert "CUDA" not in done.stderr and "Warp" not in done.stderr, done.stderr
    assert "3 frames × 2 method/point(s)" in done.stdout and "(pool, 2 process(es), cpu)" in done.stdout
    assert (tmp_path / "out" / "metrics.csv").is_file() and (tmp_path / "out" / "summary.json").is_file()


if __name__ == "__main__":
    print(experiments_table(), end="")
