"""The resolved experiment, and a method preset, written as documented TOML text (``csmlab show``)."""

from __future__ import annotations

import ast
import inspect
import json
import math
import textwrap

from csmlab.config.document import _settings_document, experiment_document
from csmlab.config.records import (_DOCS_TOP, CameraConfig, Experiment, LightConfig, ReportConfig, SceneConfig,
                                   TaaConfig)
from csmlab.settings import APPLIES, ShadowSettings


def field_docs(cls) -> dict[str, str]:
    """The docstring under each field of the dataclass ``cls``, by field name (TOML spelling)."""
    try:
        tree = ast.parse(textwrap.dedent(inspect.getsource(cls)))
    except (OSError, TypeError):
        return {}
    body = tree.body[0].body
    docs = {}
    for node, after in zip(body, body[1:]):
        if (isinstance(node, ast.AnnAssign) and isinstance(node.target, ast.Name) and isinstance(after, ast.Expr)
                and isinstance(after.value, ast.Constant) and isinstance(after.value.value, str)):
            name = "lambda" if node.target.id == "lambda_" else node.target.id
            docs[name] = " ".join(after.value.value.split())
    return docs


def _toml_value(value) -> str:
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, float):
        if math.isfinite(value):
            return repr(value)
        return "nan" if math.isnan(value) else ("inf" if value > 0 else "-inf")
    if isinstance(value, int):
        return str(value)
    if isinstance(value, str):
        return json.dumps(value, ensure_ascii=False)
    if isinstance(value, list):
        return "[" + ", ".join(_toml_value(v) for v in value) + "]"
    if isinstance(value, dict):
        return "{ " + ", ".join(f"{k} = {_toml_value(v)}" for k, v in value.items()) + " }"
    raise TypeError(f"no TOML form for {value!r}")


def _toml_table(table: dict, docs: dict, *, comments: bool) -> list[str]:
    texts = {key: f"{key} = {_toml_value(value)}" for key, value in table.items()}
    width = min(max((len(t) for t in texts.values()), default=0), 40)
    lines = []
    for key, text in texts.items():
        doc = docs.get(key, "").replace("``", "")
        lines.append(f"{text:<{width}}  # {doc}" if comments and doc else text)
    return lines


def experiment_toml(experiment: Experiment, *, comments: bool = True) -> str:
    """The resolved experiment as a TOML file; with ``comments``, each field's documentation beside it."""
    document = experiment_document(experiment)
    sections = {"scene": field_docs(SceneConfig), "camera": field_docs(CameraConfig),
                "light": field_docs(LightConfig), "shadow": field_docs(ShadowSettings),
                "report": field_docs(ReportConfig), "taa": field_docs(TaaConfig)}
    top = {k: v for k, v in document.items() if not isinstance(v, (dict, list))}
    lines = [f"# {experiment.source}", *_toml_table(top, _DOCS_TOP, comments=comments), ""]
    for key in ("scene", "camera", "light", "shadow"):
        lines += [f"[{key}]", *_toml_table(document[key], sections[key], comments=comments), ""]
    for method in document["methods"]:
        lines += ["[[methods]]", *_toml_table(method, sections["shadow"], comments=comments), ""]
    for key in ("sweep", "regress", "report", "taa"):
        if key in document:
            lines += [f"[{key}]", *_toml_table(document[key], sections.get(key, {}), comments=comments), ""]
    return "\n".join(lines)


def method_preset_toml(name: str, settings: ShadowSettings, *, description: str, header: str = "",
                       notes: dict | None = None, default_note: str = "") -> str:
    """A method preset (``configs/methods`` form) holding every field of ``settings`` that applies, each documented.

    ``header`` becomes comment lines at the top; ``extends = ["that_file.toml"]`` then gives a method
    named ``name`` with these settings (a field that does not apply, :data:`~csmlab.settings.APPLIES`,
    is left out: it would change nothing, and the loader refuses it). ``notes`` (``{TOML name: comment}``),
    when given, comment each field in place of its documentation, ``default_note`` the fields it does
    not name (``csmlab import``: where each value came from).
    """
    lines = [f"# {line}" for line in header.splitlines()]
    docs = field_docs(ShadowSettings) if notes is None else {k: notes.get(k, default_note)
                                                                for k in _settings_document(settings)}
    lines += [f"description = {_toml_value(description)}", "", "[[methods]]", f"name = {_toml_value(name)}",
              *_toml_table({k: v for k, v in _settings_document(settings).items()
                            if k not in APPLIES or APPLIES[k].holds(settings)}, docs, comments=True)]
    return "\n".join(lines) + "\n"
