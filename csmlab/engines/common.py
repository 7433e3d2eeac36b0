"""What every engine module shares on the way out: the snippet and engine records, and the rules of the lacking lists.

Each engine module (``csmlab/engines/<engine>.py``) turns a :class:`~csmlab.settings.ShadowSettings` into
the settings of its engine — cascade count, per-cascade resolution, shadow distance, split distances,
blending and filter — and names every csmlab knob the engine has no setting for, so that nobody
believes a snippet reproduces more than it does. It declares itself as an :class:`Engine`; the
registries in :mod:`csmlab.engines` are built from those records.

Split distances are exported as the engine spells them: fractions of the shadow distance (Unity URP,
Godot, three.js ``custom`` mode), metres (Bevy ``CascadeShadowConfig``), or — for Unreal, whose only
split control is a distribution exponent — the exponent whose splits come closest, with the error
(csmlab.cascades.splits holds the arithmetic).
"""

from __future__ import annotations

import re
from collections.abc import Callable
from dataclasses import dataclass

from csmlab.cascades.bounds import BOUNDS_METHODS
from csmlab.engines.reading import Imported
from csmlab.errors import InputError
from csmlab.lookup_choices import FILTER_METHODS
from csmlab.settings import APPLIES, GROUP_OF, SETTING_GROUPS, ShadowSettings

__all__ = ["OTHER_TITLE", "Engine", "EngineFiles", "Snippet", "TuneSpace", "blend_lacking", "common_lacking",
           "describe_spec", "fixed_preset", "four_digits", "hard_filter", "in_group_order", "lacking_by_group",
           "largest_resolution", "named_fields", "one_file", "shape_lacking", "storage_lacking", "the_engines_own",
           "vogel_is"]


@dataclass(frozen=True)
class Snippet:
    """One engine's configuration for a setting.

    Attributes
    ----------
    engine : str
        A key of :data:`csmlab.engines.EXPORT_METHODS`.
    title : str
        Where it goes in the engine.
    language : str
        ``ini``, ``csharp``, ``gdscript``, ``rust``, ``javascript``, ``yaml``, ``json`` or ``sdscene`` (Stride's
        asset YAML): csmlab.tune picks the file suffix by it.
    text : str
        The snippet.
    lacking : tuple of str
        csmlab knobs the engine has no setting for, each with the value this setting uses.
    files : tuple of (str, str)
        The engine's own files holding the setting, ``(file name, text)``: what ``csmlab import``
        reads back (:attr:`Engine.files`); empty for an engine without an importer.
    """

    engine: str
    title: str
    language: str
    text: str
    lacking: tuple[str, ...]
    files: tuple[tuple[str, str], ...] = ()


def shape_lacking(settings: ShadowSettings, *, transition: str | None = None, blend_curve: str = "linear",
                  fade: str | None = None) -> list[str]:
    """Where the engine's blend band or far fade has another shape than the setting's (``transition``,
    ``blend_curve``: csmlab.cascades.fit; ``fade``: csmlab.filters); None: the engine has no such knob here."""
    lacking = []
    if transition is not None and settings.blend_band > 0:
        if settings.transition != transition:
            lacking.append(f"transition = {settings.transition!r} (the engine's band is {transition!r})")
        if settings.blend_curve != blend_curve:
            lacking.append(f"blend_curve = {settings.blend_curve!r} (the engine's weight is {blend_curve!r})")
    if fade is not None and settings.fade_out > 0 and settings.fade != fade:
        lacking.append(f"fade = {settings.fade!r} (the engine's fade is {fade!r})")
    return lacking


def blend_lacking(settings: ShadowSettings, why: str) -> list[str]:
    """``blend_band`` named as lacking, with ``why``, where the setting blends cascades and the engine does not
    blend them as csmlab does."""
    return [f"blend_band = {settings.blend_band} ({why})"] if settings.blend_band > 0 else []


def common_lacking(settings: ShadowSettings, *, stable: str, carried=frozenset()) -> list[str]:
    """Knobs no exporter maps: stabilization other than the engine's own, fit, selection, per-cascade
    resolution, splits over the visible depth range, depth format, bias units (of the bias fields the engine's
    files do not carry: ``carried``, its :attr:`EngineFiles.fields`)."""
    lacking = []
    if settings.stabilization != stable:
        lacking.append(f"stabilization = {settings.stabilization!r} (the engine always stabilizes its own way, "
                       f"closest to csmlab's {stable!r})")
    if settings.stabilization == "quantized":
        lacking.append(f"levels = {settings.levels}")
    if settings.fit != "cascade":
        lacking.append(f"fit = {settings.fit!r}")
    if settings.selection != "interval":
        lacking.append(f"selection = {settings.selection!r}")
    if settings.cascade_resolutions:
        # The engines below give every cascade one size; the largest keeps the nearest cascades as sharp.
        lacking.append(f"cascade_resolutions = {list(settings.cascade_resolutions)} (one size for every cascade: "
                       f"{largest_resolution(settings)} written)")
    if BOUNDS_METHODS[settings.bounds].visible:
        lacking.append(f"bounds = {settings.bounds!r} (splits over the visible depth range need the engine's "
                       f"depth readback)")
    if settings.depth_format != "float32":
        lacking.append(f"depth_format = {settings.depth_format!r} (set the shadow map's depth format in the engine)")
    biases = [f"{name} = {getattr(settings, name)}" for name in ("bias_constant", "bias_slope", "normal_offset")
              if name not in carried]
    if biases:
        lacking.append(f"{', '.join(biases)} (engine bias units differ: tune by eye)")
    return lacking


def named_fields(item: str) -> list[str]:
    """The fields a lacking line names: ``a = 1, b = 2 (why)`` → ``[a, b]``."""
    return re.findall(r"(?:^|, )([a-z_]+) = ", item.split(" (", 1)[0])


OTHER_TITLE = "other"
"""The heading of lacking lines that name no ``[shadow]`` field (:func:`lacking_by_group`)."""


def lacking_by_group(lacking) -> list[tuple[str, tuple[str, ...]]]:
    """``lacking`` (lines) as ``(group title, lines)`` in the documented order
    (:data:`~csmlab.settings.SETTING_GROUPS`): a line goes in the group of the first ``[shadow]`` field it names
    (:func:`named_fields`), and within its group at that field's place (lines naming one field keep their order);
    lines naming no field come last, headed :data:`OTHER_TITLE`. Groups with no line are left out."""
    place = {name: k for k, name in enumerate(name for group in SETTING_GROUPS for name in group.fields)}
    titles = [group.title for group in SETTING_GROUPS] + [OTHER_TITLE]
    lines: dict[str, list[tuple[int, str]]] = {title: [] for title in titles}
    for item in lacking:
        name = next((name for name in named_fields(item) if name in GROUP_OF), None)
        lines[OTHER_TITLE if name is None else GROUP_OF[name].title].append((place.get(name, len(place)), item))
    return [(title, tuple(item for _, item in sorted(lines[title], key=lambda pair: pair[0])))
            for title in titles if lines[title]]


def in_group_order(lacking) -> tuple[str, ...]:
    """``lacking`` (lines) reordered group by group, as :func:`lacking_by_group` heads them."""
    return tuple(item for _, items in lacking_by_group(lacking) for item in items)


def the_engines_own(item: str, settings: ShadowSettings, preset: ShadowSettings) -> bool:
    """Whether every field lacking line ``item`` names holds ``preset``'s value in ``settings``, a value that
    applies to the preset (:data:`~csmlab.settings.APPLIES`): the engine does that itself, so its files reproduce
    it without a setting."""
    names = named_fields(item)
    attributes = ["lambda_" if name == "lambda" else name for name in names]
    return bool(names) and all(
        hasattr(settings, attribute) and getattr(settings, attribute) == getattr(preset, attribute)
        and (name not in APPLIES or APPLIES[name].holds(preset)) for name, attribute in zip(names, attributes))


def storage_lacking(settings: ShadowSettings, *, cascades: int, atlas: str) -> list[str]:
    """``storage`` named as lacking where it is not what an engine whose one cascade takes the whole map, and whose
    ``cascades`` (the count written) otherwise share ``atlas`` (its preset's storage), stores."""
    stored = "array" if cascades == 1 else atlas
    return [] if settings.storage == stored else [
        f"storage = {settings.storage!r} (the engine stores {cascades} cascade(s) as {stored!r})"]


def largest_resolution(settings: ShadowSettings) -> int:
    """Texels per side each engine gets: the largest cascade's (engines give every cascade one size)."""
    return max(settings.cascade_resolutions or (settings.resolution,))


def four_digits(value: float) -> str:
    """``value`` as exporters print a number for a person to paste: four significant digits."""
    return f"{value:.4g}"


def hard_filter(settings: ShadowSettings) -> bool:
    """The filter is one depth test (its record's ``hard``) or one hardware 2×2 comparison (``pcf_bilinear``):
    what engines call no soft shadows (URP's soft shadows off, Godot's Hard, both a linear comparison sampler)."""
    return FILTER_METHODS[settings.filter].hard or settings.filter == "pcf_bilinear"


def vogel_is(settings: ShadowSettings, **fields) -> bool:
    """``settings`` run ``pcf_vogel`` rotated per pixel with ``fields`` (an engine's disk)."""
    return settings.filter == "pcf_vogel" and settings.poisson_rotation in ("pixel", "pixel_taa") and all(
        getattr(settings, name) == value for name, value in fields.items())


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
    presets : tuple of str
        Every engine preset ``preset`` can return (``configs/engines/<preset>.toml``).
    """

    read: Callable[..., Imported]
    write: Callable[..., tuple]
    fields: frozenset
    preset: Callable[[ShadowSettings], str]
    files: str
    presets: tuple[str, ...]


def _as_is(settings: ShadowSettings) -> ShadowSettings:
    return settings


@dataclass(frozen=True)
class TuneSpace:
    """The settings an engine can express, as ``csmlab tune`` searches them: a tune of the engine's preset
    offers these values only, and its exporter writes every one of them to the engine's own files.

    Attributes
    ----------
    fields : dict
        TOML field name → ``("choice", values)`` or ``("range", lo, hi, log, step)`` (the form of
        :attr:`csmlab.config.TuneConfig.space`): the engine's legal values (a range: its slider's).
    settle : callable
        ``settle(settings) -> settings``: the fields the engine derives from the tuned ones, set as the engine
        sets them (Godot's split fractions for its cascade count; identity where none are derived).
    """

    fields: dict
    settle: Callable[[ShadowSettings], ShadowSettings] = _as_is

    def restricted(self, space: dict, *, engine: str, method: str) -> dict:
        """``space`` (field → spec) cut to what the engine can express; the engine's whole space when empty.

        A range is clipped to the engine's (a range over the engine's choices keeps the choices inside it); a
        choice keeps the engine's values.

        Raises
        ------
        InputError
            For a field the engine has no setting for, or a spec with no value the engine can take:
            the method, the field and the engine's values named.
        """
        if not space:
            return dict(self.fields)
        out = {}
        for field, spec in space.items():
            legal = self.fields.get(field)
            if legal is None:
                raise InputError(f"method {method} extends the {engine} preset, whose tune space is the engine's "
                                 f"own: {engine} has no setting for {field!r} (its tunable fields: "
                                 f"{', '.join(self.fields)})", field=f"tune.{field}")
            kept = _within(spec, legal)
            if kept is None:
                raise InputError(f"method {method} extends the {engine} preset: expected {field} values {engine} can "
                                 f"take ({describe_spec(legal)}), got {describe_spec(spec)}", field=f"tune.{field}")
            out[field] = kept
        return out


def _within(spec: tuple, legal: tuple) -> tuple | None:
    """The part of ``spec`` inside ``legal`` (both ``("choice", …)`` or ``("range", …)``), None when empty."""
    if legal[0] == "choice":
        if spec[0] == "choice":
            values = tuple(v for v in spec[1] if v in legal[1])
        else:
            values = tuple(v for v in legal[1] if spec[1] <= v <= spec[2])
        return ("choice", values) if values else None
    lo, hi = legal[1], legal[2]
    if spec[0] == "choice":
        values = tuple(v for v in spec[1] if isinstance(v, (int, float)) and lo <= v <= hi)
        return ("choice", values) if values else None
    low, high = max(spec[1], lo), min(spec[2], hi)
    # The engine's step (Unreal's exponent to the 0.01 its snippet prints) holds unless the user's is set.
    return ("range", low, high, spec[3], spec[4] if spec[4] is not None else legal[4]) if low < high else None


def describe_spec(spec: tuple) -> str:
    """A search-space spec as a person reads it: ``1, 2, 4`` or ``0.0 to 10.0``."""
    return ", ".join(map(str, spec[1])) if spec[0] == "choice" else f"{spec[1]} to {spec[2]}"


@dataclass(frozen=True)
class Engine:
    """Everything the registries of :mod:`csmlab.engines` take from one engine module.

    Attributes
    ----------
    name : str
        The engine's name: its preset's in ``configs/engines`` (or the stem of its presets').
    export : callable
        ``export(settings, *, near, far) -> Snippet``.
    files : EngineFiles or None
        Its own files, read and written (``csmlab import``); None for an engine without an importer.
    tune : TuneSpace or None
        What a tune of its preset may try: the engine's own settings (:func:`csmlab.engines.tune_space`).
    """

    name: str
    export: Callable[..., Snippet]
    files: EngineFiles | None = None
    tune: TuneSpace | None = None


def one_file(write: Callable[..., tuple], settings: ShadowSettings, *, near: float, far: float) -> tuple[str, list]:
    """The text of the one file ``write`` writes for ``settings`` (an engine whose snippet is its own file), and
    the knobs it names as lacking."""
    files, lacking = write(settings, near=near, far=far)
    (text,) = files.values()
    return text, lacking


def fixed_preset(name: str) -> Callable[[ShadowSettings], str]:
    """``preset(settings)`` of an engine with one preset, ``name``, whatever the settings."""
    return lambda settings: name
