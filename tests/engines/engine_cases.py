"""What the engine tests share: the fixture folder, the round trip through an engine's own files, a snippet's numbers.

Every test module of tests/engines/ imports it (pytest puts this folder on the path, as tests/ for
tests/features/gl_pipeline.py).
"""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np

from csmlab.cascades.splits import split_boundaries
from csmlab.config import load_experiment
from csmlab.engines import export, import_settings
from csmlab.engines.reading import toml_name
from csmlab.settings import APPLIES, ShadowSettings

ROOT = Path(__file__).resolve().parents[2]
DATA = ROOT / "tests" / "data" / "engines"
VENDOR = DATA / "vendor"
NEAR, FAR = 0.1, 400.0
SPLIT_FIELDS = {"split", "splits", "lambda_", "distribution_exponent", "first_cascade_far"}


def round_trip(settings: ShadowSettings, engine: str, folder: Path) -> tuple[ShadowSettings, str]:
    """``import(export(settings))`` through the engine's own files, and the knobs the export names as lacking."""
    snippet = export(settings, near=NEAR, far=FAR, engine=engine)
    paths = []
    for name, text in snippet.files:
        paths.append(folder / name)
        paths[-1].write_text(text, encoding="utf-8")
    return import_settings(paths, engine=engine).settings, " ".join(snippet.lacking)


def differences(settings: ShadowSettings, back: ShadowSettings, lacking: str) -> list[str]:
    """Fields of ``settings`` (those that apply to it) that came back different and are not named as lacking;
    a split field counts as back when the cascade boundaries are (to 1 cm: Unreal's exponent grid)."""
    wrong = []
    for attribute in ShadowSettings.__dataclass_fields__:
        name = toml_name(attribute)
        if name in APPLIES and not APPLIES[name].holds(settings):
            continue
        mine, theirs = getattr(settings, attribute), getattr(back, attribute)
        if isinstance(mine, (float, tuple)) and np.shape(mine) == np.shape(theirs):
            same = np.allclose(mine, theirs, rtol=1e-9, atol=1e-12)
        else:
            same = mine == theirs
        if same or f"{name} =" in lacking:
            continue
        if attribute in SPLIT_FIELDS and (settings.cascades != back.cascades and "cascades =" in lacking or np.allclose(
                split_boundaries(settings, near=NEAR, far=FAR), split_boundaries(back, near=NEAR, far=FAR), atol=0.01)):
            continue
        wrong.append(f"{name}: {mine!r} → {theirs!r}")
    return wrong


def numbers(text: str, after: str) -> list[float]:
    """The numbers on the first line of ``text`` holding ``after``, after it (a call's arguments, not its name)."""
    rest = next(line for line in text.splitlines() if after in line).split(after, 1)[1]
    rest = rest.split("(", 1)[1] if "(" in rest else rest  # new Vector3(…): the arguments, not the 3
    return [float(v) for v in re.findall(r"-?\d+\.?\d*(?:e-?\d+)?", rest)]


def engine_preset(name: str, folder) -> ShadowSettings:
    """The settings of ``configs/engines/<name>.toml`` as an experiment that extends it resolves them."""
    path = folder / "uses_engine.toml"
    path.write_text(f'extends = ["engines/{name}"]\n[camera]\npath = "walk"\n')
    return load_experiment(path).methods[0].settings
