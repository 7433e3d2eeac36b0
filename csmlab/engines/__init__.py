"""Engines: everything csmlab knows of each, one module an engine, and the registries built from them.

Each engine module (``csmlab/engines/<engine>.py``) holds its reader (the engine's own files read as a
csmlab method preset, ``csmlab import``), its writer (those files written back, so that
``import(export(setting))`` can be checked), its exporter (a snippet to paste and the knobs the engine
lacks, ``tune``'s exports), the csmlab fields its files carry and the constants of its filters, and
declares them as one :class:`~csmlab.engines.common.Engine`, ``ENGINE``. :data:`ENGINES` lists those
modules; :data:`EXPORT_METHODS` and :data:`IMPORT_METHODS` are built from it, and :func:`export` and
:func:`import_settings` dispatch on ``engine=``. What every engine shares lives in
csmlab.engines.reading (the engine's defaults, typed values, each field's origin),
csmlab.engines.common (the records and the lacking rules) and csmlab.cascades.splits (split arithmetic);
csmlab.engines.ron and csmlab.engines.unity_yaml read the file formats more than one engine could use.

Every importer starts from the engine's preset in ``configs/engines/`` (the engine's defaults, in one
place) and replaces what the files set, remembering the file and key of each; engine settings csmlab
has no knob for are listed as unmodelled. :func:`preset_toml` writes the result as a method preset for
``extends``.
"""

from __future__ import annotations

import json
import os
from collections.abc import Callable
from dataclasses import replace
from pathlib import Path

from csmlab.engines import bevy, filament, godot4, stride, threejs_csm, ue5, unity_builtin, unity_urp
from csmlab.engines.common import Engine, EngineFiles, Snippet, TuneSpace, in_group_order, the_engines_own
from csmlab.engines.reading import Imported, attribute_name, engine_settings, toml_name
from csmlab.registry import check_name, dispatch
from csmlab.settings import APPLIES, SETTING_GROUPS, ShadowSettings

__all__ = ["ENGINES", "EXPORT_METHODS", "IMPORT_METHODS", "Engine", "EngineFiles", "Imported", "Snippet", "TuneSpace",
           "LEVEL_READERS", "engine_files", "export", "import_settings", "level_instances", "level_toml",
           "preset_toml", "tune_space"]

ENGINES: dict[str, Engine] = {module.ENGINE.name: module.ENGINE for module in (
    ue5, unity_urp, unity_builtin, godot4, bevy, threejs_csm, filament, stride)}
"""Every engine's record by name (its preset's in ``configs/engines``), in the order tune exports them."""

EXPORT_METHODS: dict[str, Callable[..., Snippet]] = {name: engine.export for name, engine in ENGINES.items()}
"""Exporters by engine name."""

IMPORT_METHODS: dict[str, EngineFiles] = {name: engine.files for name, engine in ENGINES.items()
                                          if engine.files is not None}
"""Importers by engine name: the engines whose own files csmlab reads and writes."""


def export(settings: ShadowSettings, *, near: float, far: float, engine: str) -> Snippet:
    """``settings`` as ``engine``'s configuration.

    Parameters
    ----------
    settings : ShadowSettings
    near, far : float
        The camera's near and far planes, metres (splits start at ``near`` and end at
        ``min(shadow_distance, far)``).
    engine : str
        A key of :data:`EXPORT_METHODS`.

    An engine with an importer (:data:`IMPORT_METHODS`) also gets its own files, and every
    knob they cannot hold is added to ``lacking``; a knob at the value of the engine preset the files are
    written against is the engine's own behaviour and is not lacking. The lacking lines come group by group in
    the documented order (:func:`~csmlab.engines.common.in_group_order`).

    Raises
    ------
    ValueError
        For an unknown engine (the known ones listed).
    """
    snippet = dispatch(EXPORT_METHODS, engine, settings, field="engine", near=near, far=far)
    if engine not in IMPORT_METHODS:
        return replace(snippet, lacking=in_group_order(snippet.lacking))
    files, more = engine_files(settings, near=near, far=far, engine=engine)
    named = " ".join(snippet.lacking)
    extra = tuple(item for item in more if f"{item.split(' =', 1)[0]} =" not in named)
    # A knob at the value of the preset the files are written against is the engine's own behaviour: not lacking.
    preset = engine_settings(IMPORT_METHODS[engine].preset(settings))
    lacking = in_group_order(item for item in snippet.lacking + extra if not the_engines_own(item, settings, preset))
    return replace(snippet, lacking=lacking, files=tuple(files.items()))


def tune_space(method: str) -> tuple[str, TuneSpace] | None:
    """The engine whose preset ``method`` is, and its tune space; None for a method of no engine's preset.

    A method is an engine preset's when it bears the name of a preset an engine's files are written against
    (:attr:`EngineFiles.presets`, ``configs/engines/<name>.toml``): ``[[methods]]`` merge by name, so an
    experiment that extends the preset (directly or through another preset) and changes its entry keeps the name.
    (csmlab.config leaves the ``[tune]`` values of such a method to :func:`csmlab.tune.tune`, which settles them.)
    """
    return next(((name, engine.tune) for name, engine in ENGINES.items() if engine.files is not None
                 and engine.tune is not None and method in engine.files.presets), None)


def import_settings(paths, *, engine: str) -> Imported:
    """The settings in ``engine``'s files ``paths``.

    Raises
    ------
    ValueError
        An unknown engine (the known ones listed).
    csmlab.errors.InputError
        A file that is malformed, foreign to the engine, or holds a value out of range: file and key named.
    """
    return IMPORT_METHODS[check_name(engine, IMPORT_METHODS, field="engine")].read([Path(p) for p in paths])


LEVEL_READERS: dict[str, Callable] = {"godot4": godot4.level_instances}
"""Readers of the level an engine's imported files instance, by engine name: ``paths → (instances, not imported)``,
each instance with ``file`` (absolute), ``transform`` (``(4, 4)``) and ``node``."""


def level_instances(paths, *, engine: str) -> tuple[list, list[str]]:
    """The mesh files ``engine``'s files ``paths`` place in their level, and a line for each they instance that csmlab
    cannot place (node, file and why); none for an engine with no level reader (:data:`LEVEL_READERS`).

    Raises
    ------
    csmlab.errors.InputError
        A scene whose structure is broken (file, line and node named).
    """
    reader = LEVEL_READERS.get(engine)
    return reader([Path(p) for p in paths]) if reader is not None else ([], [])


def level_toml(instances, *, out) -> str:
    """``[scene]`` (``kind = "mesh"``, one ``[[scene.parts]]`` per instance: its file relative to ``out``, its
    transform as ``matrix``) and a ``[camera]`` walk fitted to that level, so that the file ``out`` runs; empty for
    no instances. Each matrix entry is written as Python's shortest round-trip repr (the TOML float reads back equal).
    """
    if not instances:
        return ""
    folder = Path(out).resolve().parent
    lines = ["", "# The level the scene instances: one part per glTF instance, placed by its node's world transform.",
             "[scene]", 'kind = "mesh"']
    for instance in instances:
        node = " ".join(str(instance.node).split())
        rows = ", ".join("[" + ", ".join(repr(float(v)) for v in row) + "]" for row in instance.transform)
        lines += ["", f"[[scene.parts]]  # {node}",
                  f"file = {json.dumps(Path(os.path.relpath(instance.file, folder)).as_posix(), ensure_ascii=False)}",
                  f"matrix = [{rows}]"]
    lines += ["", "# A walk placed in the level (fit_level); put your own camera path here.", "[camera]",
              'path = "walk"']
    return "\n".join(lines) + "\n"


def engine_files(settings: ShadowSettings, *, near: float, far: float, engine: str) -> tuple[dict, list]:
    """``settings`` as ``engine``'s own files ``{name: text}`` and the knobs they cannot hold.

    Beyond what the writer names, every field the files do not carry that applies to ``settings``
    and differs from the engine's preset is lacking (the engine would use its own), group by group in the
    documented order (:data:`~csmlab.settings.SETTING_GROUPS`).
    """
    record = IMPORT_METHODS[check_name(engine, IMPORT_METHODS, field="engine")]
    files, lacking = record.write(settings, near=near, far=far)
    base = engine_settings(record.preset(settings))
    for group in SETTING_GROUPS:
        for name in group.fields:
            attribute = attribute_name(name)
            if attribute in record.fields or (name in APPLIES and not APPLIES[name].holds(settings)):
                continue
            mine, theirs = getattr(settings, attribute), getattr(base, attribute)
            if mine != theirs:
                lacking.append(f"{name} = {mine!r} (the engine's is {theirs!r})")
    return files, lacking


def preset_toml(imported: Imported, *, name: str, files) -> str:
    """``imported`` as a method preset: every field that applies, commented with the file and key it came from
    (or the engine preset it defaults to), then the engine settings csmlab cannot model as comment lines."""
    from csmlab.config.toml_writer import method_preset_toml

    notes = {toml_name(a): f"from {origin}" for a, origin in imported.origins.items()}
    default = f"engine default (configs/engines/{imported.preset}.toml)"
    header = (f"csmlab import {imported.engine} {' '.join(Path(f).name for f in files)}\n"
              f"Fields not set by the files are the engine's defaults, configs/engines/{imported.preset}.toml.")
    footer = [f"not modelled: {item}" for item in imported.unmodelled] or ["not modelled: nothing found"]
    return method_preset_toml(name, imported.settings, header=header,
                              description=f"{imported.engine} settings imported from "
                                          f"{', '.join(Path(f).name for f in files)}",
                              notes=notes, default_note=default) + "".join(f"# {line}\n" for line in footer)
