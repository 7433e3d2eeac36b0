"""The experiment schema: documented records, TOML loading with presets, validation, sweep expansion.

An experiment file (docs/design.md, "Experiments, CLI, outputs") names a scene, a camera path, a light,
base ``[shadow]`` settings, ``[[methods]]`` (named variations on the base), an optional ``[sweep]``
(cartesian product over shadow fields) and optional ``[regress]`` tolerances.

The package, by job:

- :mod:`~csmlab.config.records` — the records, one per table, each field documented;
- :mod:`~csmlab.config.presets` — finding files, reading TOML, merging ``extends`` presets;
- :mod:`~csmlab.config.locate` — the file and line a merged field came from;
- :mod:`~csmlab.config.validate` — types, ranges and names: :func:`load_experiment`;
- :mod:`~csmlab.config.document` — the resolved document and its config and workload hashes;
- :mod:`~csmlab.config.toml_writer` — the resolved experiment as documented TOML (``csmlab show``).

Import from here: this module's names are the public surface.
"""

from __future__ import annotations

from csmlab.config.document import config_hash, experiment_document, workload_hash
from csmlab.config.presets import (CONFIGS_DIR, EXPERIMENTS_DIR, PROJECT_DIR, find_experiment, list_experiments,
                                   list_presets)
from csmlab.config.records import (CameraConfig, Experiment, LightConfig, Method, ReportConfig, SceneConfig,
                                   TaaConfig, TuneConfig, Variant, sweep_points)
from csmlab.config.toml_writer import experiment_toml, field_docs, method_preset_toml
from csmlab.config.validate import load_experiment, load_tolerances, parse_size, shadow_method_registries

__all__ = [
    "CONFIGS_DIR",
    "EXPERIMENTS_DIR",
    "PROJECT_DIR",
    "CameraConfig",
    "Experiment",
    "LightConfig",
    "Method",
    "ReportConfig",
    "SceneConfig",
    "TaaConfig",
    "TuneConfig",
    "Variant",
    "config_hash",
    "experiment_document",
    "experiment_toml",
    "field_docs",
    "find_experiment",
    "list_experiments",
    "list_presets",
    "load_experiment",
    "load_tolerances",
    "method_preset_toml",
    "parse_size",
    "shadow_method_registries",
    "sweep_points",
    "workload_hash",
]
