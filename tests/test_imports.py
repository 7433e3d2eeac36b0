"""Imports point downward only: every ``csmlab`` import names a module of the same or a lower layer.

:data:`LAYERS` is the house's layering, bottom first, after docs/design.md's direction (cli → experiment →
render/metrics → cascades/scene/paths → geometry/kernels) fitted to the real tree: the settings
and the filter records sit under the kernels (the kernels switch on the records' codes), and the
records a run writes and reads, the judgement and the reports sit between the metrics and the
experiment. Every import statement counts, at module level or inside a function, including those
under ``if TYPE_CHECKING``. A module belongs to the entry naming it or its closest package, so a new
module inside a listed package (``csmlab.kernels.*``, ``csmlab.report.*``) needs no new entry; a new
top-level module fails :func:`test_every_module_has_a_layer` until it is placed here. Within a layer
imports may point either way, but never round: :func:`test_no_module_imports_itself_through_others`
reads the whole graph, module by module, for a circle.
"""

from __future__ import annotations

import ast
import subprocess
import sys
from pathlib import Path

import pytest

PACKAGE = Path(__file__).resolve().parent.parent / "csmlab"

LAYERS: tuple[tuple[str, tuple[str, ...]], ...] = (
    ("foundations", ("csmlab", "csmlab.errors", "csmlab.files", "csmlab.documents", "csmlab.registry",
                     "csmlab.geometry", "csmlab.srgb", "csmlab.metric_registry")),
    ("settings", ("csmlab.lookup_choices", "csmlab.culling", "csmlab.fades", "csmlab.shadow_policies",
                  "csmlab.settings")),
    ("kernels", ("csmlab.kernels",)),
    ("world", ("csmlab.camera", "csmlab.light", "csmlab.scene", "csmlab.paths", "csmlab.cascades", "csmlab.texels",
               "csmlab.quads", "csmlab.storage", "csmlab.scrolling", "csmlab.clipmaps", "csmlab.frame")),
    ("lookup and render", ("csmlab.filters", "csmlab.render")),
    ("metrics", ("csmlab.metrics",)),
    ("run records", ("csmlab.config", "csmlab.results", "csmlab.executor", "csmlab.engines", "csmlab.invariants")),
    ("judgement and reports", ("csmlab.regress", "csmlab.compare", "csmlab.verdict", "csmlab.report")),
    ("experiment", ("csmlab.experiment", "csmlab.worker_imports")),
    ("tune", ("csmlab.tune",)),
    ("command line", ("csmlab.cli",)),
)
"""The layers, bottom first: a module may import modules of its own layer or of a layer listed before it."""


def module_names() -> dict[str, Path]:
    """Every module of the package by dotted name (a package by its own name, not ``__init__``)."""
    out = {}
    for path in sorted(PACKAGE.rglob("*.py")):
        parts = path.relative_to(PACKAGE.parent).with_suffix("").parts
        out[".".join(parts[:-1] if parts[-1] == "__init__" else parts)] = path
    return out


def layer_of(module: str) -> int | None:
    """The index in :data:`LAYERS` of the entry naming ``module`` or its closest package (``csmlab``: only itself)."""
    best, index = -1, None
    for i, (_, names) in enumerate(LAYERS):
        for name in names:
            inside = module == name or (name != "csmlab" and module.startswith(name + "."))
            if inside and len(name) > best:
                best, index = len(name), i
    return index


def imports_of(module: str, path: Path, modules) -> list[tuple[int, str]]:
    """``(line, imported module)`` of every import of a ``csmlab`` module in ``path``, at any depth."""
    package = module if path.name == "__init__.py" else module.rpartition(".")[0]
    found = []
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"), filename=str(path))):
        if isinstance(node, ast.Import):
            found += [(node.lineno, alias.name) for alias in node.names if alias.name.split(".")[0] == "csmlab"]
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                anchor = package.split(".")[:len(package.split(".")) - node.level + 1]
                base = ".".join(anchor + ([base] if base else []))
            if base.split(".")[0] != "csmlab":
                continue
            # `from csmlab.x import y` imports the module csmlab.x.y where there is one.
            found += [(node.lineno, f"{base}.{alias.name}" if f"{base}.{alias.name}" in modules else base)
                      for alias in node.names]
    return found


def test_every_module_has_a_layer():
    missing = [name for name in module_names() if layer_of(name) is None]
    assert not missing, f"modules not in tests/test_imports.py LAYERS (place each in its layer): {missing}"


def test_every_import_points_to_the_same_or_a_lower_layer():
    modules = module_names()
    upward = []
    for module, path in modules.items():
        own = layer_of(module)
        for line, imported in imports_of(module, path, modules):
            target = layer_of(imported)
            if own is not None and target is not None and target > own:
                upward.append(f"{path.relative_to(PACKAGE.parent)}:{line}: {module} ({LAYERS[own][0]}) imports "
                              f"{imported} ({LAYERS[target][0]})")
    assert not upward, "imports that run upward:\n" + "\n".join(upward)


def import_graph(modules: dict[str, Path]) -> dict[str, set[str]]:
    """``{module: the csmlab modules it imports}``, every import at any depth, each import naming the module it
    loads (a package by its ``__init__``)."""
    return {module: {imported for _, imported in imports_of(module, path, modules) if imported in modules}
            for module, path in modules.items()}


def import_circles(graph: dict[str, set[str]]) -> list[list[str]]:
    """The circles of ``graph``: each strongly connected set of two or more modules (or one importing itself),
    sorted (Tarjan's algorithm, iterative)."""
    index, low, on_stack, stack, circles = {}, {}, set(), [], []
    for root in sorted(graph):
        if root in index:
            continue
        work = [(root, iter(sorted(graph[root])))]
        index[root] = low[root] = len(index)
        stack.append(root)
        on_stack.add(root)
        while work:
            node, successors = work[-1]
            for successor in successors:
                if successor not in index:
                    index[successor] = low[successor] = len(index)
                    stack.append(successor)
                    on_stack.add(successor)
                    work.append((successor, iter(sorted(graph[successor]))))
                    break
                if successor in on_stack:
                    low[node] = min(low[node], index[successor])
            else:
                work.pop()
                if work:
                    low[work[-1][0]] = min(low[work[-1][0]], low[node])
                if low[node] == index[node]:
                    component = []
                    while True:
                        member = stack.pop()
                        on_stack.discard(member)
                        component.append(member)
                        if member == node:
                            break
                    if len(component) > 1 or node in graph[node]:
                        circles.append(sorted(component))
    return sorted(circles)


def test_no_module_imports_itself_through_others():
    circles = import_circles(import_graph(module_names()))
    assert not circles, "import circles (each a set of modules that import one another round):\n" + "\n".join(
        " ↔ ".join(circle) for circle in circles)


def test_the_circle_check_finds_a_circle_through_a_function_level_import(tmp_path):
    package = tmp_path / "csmlab"
    (package / "engines").mkdir(parents=True)
    (package / "engines" / "__init__.py").write_text("from csmlab.engines import godot4\n")
    (package / "engines" / "godot4.py").write_text("from csmlab.engine_export import split_boundaries\n")
    (package / "engine_export.py").write_text("def export():\n    from csmlab.engines import godot4\n")
    (package / "settings.py").write_text("from csmlab.registry import check_name\n")
    modules = {"csmlab.engines": package / "engines" / "__init__.py",
               "csmlab.engines.godot4": package / "engines" / "godot4.py",
               "csmlab.engine_export": package / "engine_export.py", "csmlab.settings": package / "settings.py"}
    assert import_circles(import_graph(modules)) == [["csmlab.engine_export", "csmlab.engines.godot4"]]
    assert import_circles({"a": {"b"}, "b": {"c"}, "c": set()}) == []
    assert import_circles({"a": {"a"}}) == [["a"]]


def test_the_layer_check_sees_function_level_and_relative_imports(tmp_path):
    source = tmp_path / "csmlab" / "settings.py"
    source.parent.mkdir()
    source.write_text("def margin():\n    from csmlab.filters import lookup_shadow\n    from . import render\n")
    modules = {"csmlab.filters": None, "csmlab.render": None, "csmlab.settings": None}
    found = imports_of("csmlab.settings", source, modules)
    assert found == [(2, "csmlab.filters"), (3, "csmlab.render")]
    assert all(layer_of(name) > layer_of("csmlab.settings") for _, name in found)


@pytest.mark.parametrize("module", ["csmlab.settings", "csmlab.lookup_choices", "csmlab.fades", "csmlab.config",
                                    "csmlab.cascades", "csmlab.results", "csmlab.regress"])
def test_the_settings_and_the_config_load_without_warp(module):
    code = f"import sys, {module}; print(sorted(m for m in sys.modules if m == 'warp' or m.startswith('warp.')))"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True, timeout=120)
    assert out.stdout.strip() == "[]", f"{module} loads Warp: {out.stdout.strip()}"
