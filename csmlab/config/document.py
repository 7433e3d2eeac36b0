"""The resolved experiment as plain data, and the config and workload hashes taken over it."""

from __future__ import annotations

import hashlib
import json
from dataclasses import fields
from pathlib import Path

from csmlab.config.records import Experiment
from csmlab.settings import ShadowSettings


def _settings_document(settings: ShadowSettings) -> dict:
    return {("lambda" if f.name == "lambda_" else f.name): _plain(getattr(settings, f.name)) for f in fields(settings)}


def _plain(value):
    if isinstance(value, tuple):
        return [_plain(v) for v in value]
    if isinstance(value, dict):
        return {k: _plain(v) for k, v in value.items()}
    return value


def _section_document(record) -> dict:
    out = {}
    for f in fields(record):
        value = getattr(record, f.name)
        if f.name == "params":
            out.update(_plain(value))
        elif value is not None:
            out[f.name] = _plain(value)
    return out


def _part_document(part) -> dict:
    """A ``[[scene.parts]]`` entry: with a ``matrix``, without the other form (the loader takes one or the other)."""
    document = _section_document(part)
    if part.matrix is not None:
        for key in ("translation", "rotation_deg", "scale"):
            document.pop(key)
    return document


def experiment_document(experiment: Experiment) -> dict:
    """The resolved experiment as plain data in the TOML file's shape: every field, presets merged.

    ``[shadow]`` holds every base setting; each ``[[methods]]`` entry its name and overrides. File
    fields hold absolute paths. Loading this document as a TOML file gives the same experiment.
    """
    scene = _section_document(experiment.scene)
    if experiment.scene.parts:
        scene["parts"] = [_part_document(part) for part in experiment.scene.parts]
    else:
        # Without parts: an experiment keeps the document (and the hashes) it had.
        scene.pop("parts")
    if experiment.scene.blend_casters == "opaque":
        # The default (as before the field): an experiment that does not set it keeps its hashes.
        scene.pop("blend_casters")
    if experiment.scene.kind == "mesh" and not experiment.scene.file:
        scene.pop("file")
    if experiment.scene.kind != "mesh":
        for key in ("file", "scale", "up", "ground"):
            scene.pop(key)
    if not any(experiment.scene.offset):
        scene.pop("offset")
    camera = _section_document(experiment.camera)
    drop = ("path",) if experiment.camera.file else ("file", "format", "convention", "scale", "offset", "time_offset",
                                                     "times_file", "anchor", "duplicate_times", "max_gap", "gaps",
                                                     "camera")
    for key in drop:
        camera.pop(key, None)
    if not experiment.camera.camera:
        camera.pop("camera", None)
    if experiment.camera.view_check == "warn":
        # The default: an experiment that does not set it keeps the document (and the hashes) it had.
        camera.pop("view_check")
    light = _section_document(experiment.light)
    if not experiment.light.from_scene:
        light.pop("from_scene")
    document = {
        "name": experiment.name,
        "description": experiment.description,
        "chunk_frames": experiment.chunk_frames,
        "scene": scene,
        "camera": camera,
        "light": light,
        "shadow": _settings_document(experiment.shadow),
        "methods": [{"name": m.name, **_plain(m.overrides)} for m in experiment.methods],
    }
    if experiment.sweep:
        document["sweep"] = {k: list(v) for k, v in experiment.sweep}
    if experiment.regress:
        document["regress"] = _plain(experiment.regress)
    report = _section_document(experiment.report)
    if report:
        document["report"] = report
    if experiment.taa.enabled:
        # Only when on: an experiment without TAA keeps the document (and the hashes) it had.
        document["taa"] = _section_document(experiment.taa)
    return document


def _file_digest(path: str) -> str:
    return "sha256:" + hashlib.sha256(Path(path).read_bytes()).hexdigest()


def _hashed(document: dict) -> str:
    return hashlib.sha256(json.dumps(document, sort_keys=True, separators=(",", ":")).encode()).hexdigest()[:16]


def _content_addressed(section: dict) -> dict:
    """A section with its file fields replaced by the files' content digests (hashes don't depend on where)."""
    return {k: (_file_digest(v) if k in ("file", "times_file") and v
                else [_content_addressed(part) for part in v] if k == "parts" else v) for k, v in section.items()}


def config_hash(experiment: Experiment) -> str:
    """16 hex digits of SHA-256 over the resolved document (files by content, name and description left out)."""
    document = experiment_document(experiment)
    for key in ("name", "description", "chunk_frames"):
        document.pop(key)
    for key in ("scene", "camera"):
        document[key] = _content_addressed(document[key])
    return _hashed(document)


def workload_hash(experiment: Experiment, *, frames: int) -> str:
    """16 hex digits of SHA-256 over what the gate compares on: scene, camera, light and frame count.

    Parameters
    ----------
    experiment : Experiment
    frames : int
        Frames actually rendered (a recorded path may hold fewer than ``camera.frames``).
    """
    document = experiment_document(experiment)
    camera = _content_addressed(document["camera"])
    camera.pop("frames")
    return _hashed({"scene": _content_addressed(document["scene"]), "camera": camera, "light": document["light"],
                    "frames": frames})
