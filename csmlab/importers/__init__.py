"""Engine settings in: an engine's own files read as a csmlab method preset (``csmlab import``).

Each engine has a module that reads its files and writes them back (the files ``tune`` exports, so
that ``import(export(setting))`` can be checked), registered by engine name in
:data:`IMPORT_METHODS`; :func:`import_settings` dispatches on ``engine=``. Every importer starts from
the engine's preset in ``configs/engines/`` (the engine's defaults, in one place) and replaces what the
files set, remembering the file and key of each; engine settings csmlab has no knob for are listed
as unmodelled. :func:`preset_toml` writes the result as a method preset for ``extends``.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

from csmlab.importers import bevy, filament, godot4, stride, threejs_csm, ue5, unity_builtin, unity_urp
from csmlab.importers.reading import Imported, engine_settings, toml_name
from csmlab.registry import check_name
from csmlab.settings import APPLIES, ShadowSettings

__all__ = ["IMPORT_METHODS", "EngineFiles", "Imported", "engine_files", "import_settings", "preset_toml"]


@dataclass(frozen=True)
class EngineFiles:
    """One engine's files, both ways.

    Attributes
    ----------
    read : callable
        ``read(paths) -> Imported``.
    write : callable
        ``write(settings, *, near, far) -> (files, lacking)``: ``{file name: text}`` that ``read`` takes
        back, and the knobs those files cannot hold.
    fields : frozenset of str
        The :class:`~csmlab.settings.ShadowSettings` attributes the files carry; the rest are the preset's.
    preset : callable
        ``preset(settings) -> str``: the engine preset a setting is written against.
    files : str
        The files to pass, in words (``csmlab list``).
    """

    read: Callable[..., Imported]
    write: Callable[..., tuple]
    fields: frozenset
    preset: Callable[[ShadowSettings], str]
    files: str


def _fixed(name: str) -> Callable[[ShadowSettings], str]:
    return lambda settings: name


IMPORT_METHODS: dict[str, EngineFiles] = {
    "godot4": EngineFiles(godot4.read_godot4, godot4.write_godot4, godot4.FIELDS, _fixed(godot4.PRESET),
                          "project.godot and/or a .tscn with a DirectionalLight3D"),
    "unity_urp": EngineFiles(unity_urp.read_unity_urp, unity_urp.write_unity_urp, unity_urp.FIELDS,
                             _fixed(unity_urp.PRESET), "a UniversalRenderPipelineAsset .asset"),
    "unity_builtin": EngineFiles(unity_builtin.read_unity_builtin, unity_builtin.write_unity_builtin,
                                 unity_builtin.FIELDS, unity_builtin.preset_of, "ProjectSettings/QualitySettings.asset"),
    "ue5": EngineFiles(ue5.read_ue5, ue5.write_ue5, ue5.FIELDS, _fixed(ue5.PRESET),
                       "DefaultEngine.ini, DefaultScalability.ini and/or a DirectionalLight's T3D text"),
    "filament": EngineFiles(filament.read_filament, filament.write_filament, filament.FIELDS,
                            _fixed(filament.PRESET), "the viewer's settings JSON"),
    "threejs_csm": EngineFiles(threejs_csm.read_threejs_csm, threejs_csm.write_threejs_csm, threejs_csm.FIELDS,
                               _fixed(threejs_csm.PRESET), "the CSM options as JSON"),
    "bevy": EngineFiles(bevy.read_bevy, bevy.write_bevy, bevy.FIELDS, _fixed(bevy.PRESET),
                        "a .scn.ron scene with CascadeShadowConfig and the DirectionalLight"),
    "stride": EngineFiles(stride.read_stride, stride.write_stride, stride.FIELDS, _fixed(stride.PRESET),
                          "a .sdscene with a LightComponent of Type !LightDirectional"),
}
"""Importers by engine name (the exporters' names, csmlab.engine_export.EXPORT_METHODS)."""


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


def engine_files(settings: ShadowSettings, *, near: float, far: float, engine: str) -> tuple[dict, list]:
    """``settings`` as ``engine``'s own files ``{name: text}`` and the knobs they cannot hold.

    Beyond what the writer names, every field the files do not carry that applies to ``settings``
    and differs from the engine's preset is lacking: the engine would use its own.
    """
    record = IMPORT_METHODS[check_name(engine, IMPORT_METHODS, field="engine")]
    files, lacking = record.write(settings, near=near, far=far)
    base = engine_settings(record.preset(settings))
    for attribute in ShadowSettings.__dataclass_fields__:
        name = toml_name(attribute)
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
