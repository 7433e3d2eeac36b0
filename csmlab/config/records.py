"""The experiment's records: one frozen dataclass per TOML table, documented field by field.

Each field's docstring is its documentation (``csmlab show`` prints it beside the value); a field's
``metadata`` may carry its range check (:func:`expect`), applied when the table is read
(:mod:`csmlab.config.validate`).
"""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass, field, fields

from csmlab.errors import InputError
from csmlab.settings import ShadowSettings


def _expect(predicate, text: str) -> dict:
    """Field metadata: a range check and the words that say what was expected (:meth:`_Checked.validated`)."""
    return {"expect": (predicate, text)}


def _positive(x) -> bool:
    return x > 0 and math.isfinite(x)


VIEW_CHECK_MODES = ("warn", "refuse", "off")
"""``[camera] view_check`` (:mod:`csmlab.paths.view_check`)."""


class _Checked:
    """A record whose fields declare their range checks in ``metadata`` (:func:`_expect`).

    :meth:`validated` is the same contract as :meth:`csmlab.settings.ShadowSettings.validated`:
    ``ValueError("<field>: expected …, got …")``, which the loader locates in its file.
    """

    def validated(self):
        """Return ``self`` after checking every field that declares a range; raise ``ValueError`` naming the field."""
        for f in fields(self):
            check, value = f.metadata.get("expect"), getattr(self, f.name)
            if check is None or value is None:
                continue
            predicate, text = check
            if not all(predicate(v) for v in (value if isinstance(value, tuple) else (value,))):
                shown = list(value) if isinstance(value, tuple) else value
                raise ValueError(f"{f.name}: expected {text}, got {shown!r}")
        return self


_Row = tuple[float, float, float, float]


@dataclass(frozen=True)
class ScenePart(_Checked):
    """One ``[[scene.parts]]`` entry: a mesh file placed in the level (csmlab.scene.parts)."""

    file: str = ""
    """The part's mesh file (OBJ, PLY, STL, VTK, glTF), relative to the file that names it."""
    translation: tuple[float, float, float] = (0.0, 0.0, 0.0)
    """Metres the part is moved by, last."""
    rotation_deg: tuple[float, float, float] = (0.0, 0.0, 0.0)
    """Turns about the world X, then Y, then Z axes through the part's origin, degrees (after ``scale``)."""
    scale: float = field(default=1.0, metadata=_expect(_positive, "a positive factor"))
    """The part's own uniform scale, after ``[scene] scale`` (metres per file unit) and ``up``."""
    matrix: tuple[_Row, _Row, _Row, _Row] | None = None
    """Instead of translation, rotation_deg and scale: a 4×4 affine transform, row-major, on column vectors
    (``p' = M [p, 1]``, last row 0 0 0 1; shear, non-uniform scale and mirrors allowed), as engines store a node's
    transform (``csmlab import godot4`` writes one per glTF instance)."""

    def validated(self):
        """Return ``self`` after the field checks and, with a ``matrix``, its check
        (:func:`csmlab.scene.parts.matrix_fault`) and that the other form is left at its defaults."""
        super().validated()
        if self.matrix is None:
            return self
        from csmlab.scene.parts import matrix_fault

        fault = matrix_fault(self.matrix)
        if fault:
            raise ValueError(f"matrix: expected {fault}")
        if (self.translation, self.rotation_deg, self.scale) != ((0.0, 0.0, 0.0), (0.0, 0.0, 0.0), 1.0):
            raise ValueError("matrix: expected either matrix or translation, rotation_deg and scale, got both")
        return self


@dataclass(frozen=True)
class SceneConfig(_Checked):
    """``[scene]``: what the camera sees and the light shines on."""

    kind: str = "terrain"
    """A procedural scene (``csmlab list`` names them) or ``mesh`` (a file)."""
    seed: int = 1
    """Random seed of a procedural scene."""
    file: str = ""
    """mesh: the mesh file (OBJ, PLY, STL, VTK, glTF), relative to the file that names it."""
    scale: float = field(default=1.0, metadata=_expect(_positive, "a positive number of metres per mesh unit"))
    """mesh: metres per mesh unit."""
    up: str = "y"
    """mesh: the file's up axis, y or z (a Z-up file is turned to Y-up)."""
    ground: bool = False
    """mesh: add a ground plane under the mesh to receive its shadow."""
    offset: tuple[float, float, float] = (0.0, 0.0, 0.0)
    """Metres the whole world (scene and camera path) is moved by: a world far from the origin (10⁶ m)."""
    blend_casters: str = field(default="opaque", metadata=_expect(lambda x: x in ("opaque", "masked"),
                                                                   "one of ['opaque', 'masked']"))
    """mesh, glTF: alphaMode BLEND materials cast (and are seen) solid (opaque) or alpha-tested at their alphaCutoff
    (masked); docs/engines.md says what each engine does with them."""
    parts: tuple[ScenePart, ...] = ()
    """mesh: further files placed by transforms (``[[scene.parts]]``, :class:`ScenePart`): a level as engines export
    it, several files; with or without ``file`` (placed as it is)."""
    params: dict = field(default_factory=dict)
    """Further keyword parameters of the procedural scene (its generator's signature lists them)."""


@dataclass(frozen=True)
class CameraConfig(_Checked):
    """``[camera]``: the camera path (a generator or a recorded file) and the image."""

    path: str = ""
    """A path generator (``csmlab list`` names them); leave empty when ``file`` is set."""
    file: str = ""
    """A recorded camera path, relative to the file that names it; leave empty when ``path`` is set."""
    format: str = ""
    """file: its format (``csmlab list`` names them); empty guesses it from the file."""
    camera: str = ""
    """file, glTF: the animated camera's node (or camera) name; empty when the file has one camera."""
    convention: str = ""
    """file: its camera axis convention; empty takes the format's own."""
    scale: float = field(default=1.0, metadata=_expect(_positive, "a positive number of metres per file unit"))
    """file: metres per file unit."""
    offset: tuple[float, float, float] = (0.0, 0.0, 0.0)
    """file: world position in metres the path is moved by after scaling."""
    time_offset: float = 0.0
    """file: the run's clock at the file's first pose, seconds (the clock starts there, not at the file's time
    stamps)."""
    start_s: float | None = None
    """file: first time kept, seconds on the run's clock (see ``time_offset``); unset keeps from the start."""
    end_s: float | None = None
    """file: last time kept, seconds on the run's clock (see ``time_offset``); unset keeps to the end."""
    times_file: str = ""
    """file: a separate time-stamp file (KITTI), relative to the file that names it."""
    anchor: str = ""
    """file: "first" puts the first pose at ``offset`` (georeferenced/UTM paths); empty keeps the file's positions."""
    duplicate_times: str = "first"
    """file: poses under a repeated time stamp: first (default, as pandas/NumPy keep), last, mean or error."""
    max_gap: float | None = field(default=None, metadata=_expect(_positive, "a positive number of seconds"))
    """file: a step between poses longer than this (seconds) is a tracking gap; unset: 10 × the median step."""
    gaps: str = "interpolate"
    """file: tracking gaps are bridged (interpolate), cut (no frame inside, temporal metrics restart) or an error."""
    seed: int = 1
    """Random seed of a generated path."""
    frames: int = field(default=120, metadata=_expect(lambda x: x >= 1, "at least 1 frame"))
    """Frames to render: a generated path's length, a recorded path's cap."""
    fps: float = field(default=30.0, metadata=_expect(_positive, "a positive frame rate in Hz"))
    """Frames per second (a recorded path is resampled to it)."""
    width: int = field(default=640, metadata=_expect(lambda x: 8 <= x <= 16384, "an image width in 8..16384 pixels"))
    """Image width in pixels."""
    height: int = field(default=360, metadata=_expect(lambda x: 8 <= x <= 16384, "an image height in 8..16384 pixels"))
    """Image height in pixels."""
    fov_y_deg: float = field(default=60.0, metadata=_expect(lambda x: 0 < x < 180, "an angle in (0, 180) degrees"))
    """Vertical field of view, degrees."""
    near: float = field(default=0.1, metadata=_expect(lambda x: x >= 1e-6, "a distance of at least 1e-6 metres"))
    """Near clip distance, metres."""
    far: float = field(default=400.0, metadata=_expect(_positive, "a positive distance in metres"))
    """Far clip distance, metres."""
    fit_level: bool | None = None
    """path: place the generated path in the scene's level — x, z from its bounds' centre, heights above its ground
    found by ray casts (csmlab.paths.generators.fitted_path); unset: on for kind = "mesh", off for procedural scenes."""
    orbit_height: float | None = None
    """path = "orbit": the camera's height, metres: world y (default 3), or above the ground in a fitted level
    (default half the radius). ``height`` is the image's."""
    flight_height: float | None = None
    """path = "flyover": the flight's height, metres: world y (default 40), or above the highest ground under the
    track in a fitted level (default half the level's longer half-extent)."""
    view_check: str = field(default="warn", metadata=_expect(lambda x: x in VIEW_CHECK_MODES,
                                                              f"one of {list(VIEW_CHECK_MODES)}"))
    """Check every frame's view against the scene (camera inside geometry, below the ground, near plane clipping most
    of the view): warn (a line naming the frames, kept in summary.json and the report), refuse (exit 2, for CI), off."""
    params: dict = field(default_factory=dict)
    """Further keyword parameters of the path generator (its signature lists them)."""

    @property
    def aspect(self) -> float:
        """Width / height of the image."""
        return self.width / self.height


@dataclass(frozen=True)
class LightConfig(_Checked):
    """``[light]``: the directional light, as a vector or as a sun's elevation and azimuth."""

    direction: tuple[float, float, float] | None = None
    """From the light toward the scene, any non-zero length; or set elevation/azimuth instead."""
    from_scene: bool = False
    """The glTF scene's directional light (KHR_lights_punctual) instead of direction or angles."""
    elevation_deg: float | None = field(default=None, metadata=_expect(lambda x: -90 <= x <= 90,
                                                                       "an angle in [-90, 90] degrees"))
    """Sun elevation above the horizon, degrees (90: straight down). Default 40."""
    azimuth_deg: float | None = None
    """Sun azimuth from +Z toward +X about +Y, degrees. Default 30."""
    elevation_end_deg: float | None = field(default=None, metadata=_expect(lambda x: -90 <= x <= 90,
                                                                           "an angle in [-90, 90] degrees"))
    """Animated sun: elevation at the last frame, degrees (linear in between)."""
    azimuth_end_deg: float | None = None
    """Animated sun: azimuth at the last frame, degrees (linear in between)."""

    @property
    def is_static(self) -> bool:
        """The light direction is the same in every frame."""
        return self.direction is not None or self.from_scene or (
            self.elevation_end_deg in (None, self.elevation_deg) and self.azimuth_end_deg in (None, self.azimuth_deg))


@dataclass(frozen=True)
class ReportConfig(_Checked):
    """``[report]``: what the HTML report keeps."""

    snapshot_frames: tuple[int, ...] | None = field(default=None, metadata=_expect(lambda x: x >= 0,
                                                                                   "frame numbers >= 0"))
    """Frames kept at full resolution (frames past the end are skipped); unset: three spread over the run."""


TAA_CLAMPS = ("ycocg_minmax", "variance", "none")
"""The ``[taa]`` neighbourhood clamps (:mod:`csmlab.kernels.taa`)."""


@dataclass(frozen=True)
class TaaConfig(_Checked):
    """``[taa]``: temporal anti-aliasing over every method's shadow and the reference (:mod:`csmlab.metrics.taa`).

    Off by default; on, every frame is rendered with a sub-pixel camera jitter, each method's S and
    the ray-traced R go through the same resolve, and the ``*_taa`` columns are filled. The
    history runs over the whole path, so the run is split by variant, not by frame
    (``chunk_frames`` is not used; :func:`csmlab.experiment.units_of_work`): every variant's frames
    run in order in one process.
    """

    enabled: bool = False
    """Resolve every frame with TAA (the ``*_taa`` columns); false leaves them empty and the frames unjittered."""
    phases: int = field(default=8, metadata=_expect(lambda x: isinstance(x, int) and 1 <= x <= 256,
                                                    "an integer in 1..256"))
    """Jitter phases: the camera's sub-pixel offset of frame t is Halton (2, 3) point ``1 + t mod phases``, less ½."""
    alpha: float = field(default=0.1, metadata=_expect(lambda x: 0.0 < x <= 1.0, "a blend weight in (0, 1]"))
    """Weight of the current frame in the exponential blend ``h + α (c − h)`` (1: no history)."""
    clamp: str = field(default="ycocg_minmax", metadata=_expect(lambda x: x in TAA_CLAMPS,
                                                                 f"one of {list(TAA_CLAMPS)}"))
    """Neighbourhood clamp of the history: ycocg_minmax (the 3×3 box of the current frame: for csmlab's grey
    signals the luma's min and max) | variance (μ ± γσ of the 3×3, Salvi's variance clipping) | none."""
    gamma: float = field(default=1.0, metadata=_expect(lambda x: 0.0 < x <= 10.0, "a number in (0, 10]"))
    """variance: half-width of the clip box in standard deviations."""
    depth_tolerance: float = field(default=0.05, metadata=_expect(lambda x: 0.0 < x < 1.0, "a fraction in (0, 1)"))
    """Disocclusion: a history tap counts where frame t−1's depth there is within this fraction of the point's depth."""


@dataclass(frozen=True)
class TuneConfig(_Checked):
    """``[tune]``: what ``csmlab tune`` searches and under which budgets (command-line options win).

    Every other key of ``[tune]`` is a ``[shadow]`` field to search: a list of choices
    (``resolution = [512, 1024, 2048]``) or a range (``lambda = { min = 0.3, max = 0.95 }``, with
    ``log = true`` for a log scale and ``step`` for a grid).
    """

    space: tuple = ()
    """``(field, ("choice", values) | ("range", lo, hi, log, step))`` pairs, in file order."""
    method: str = ""
    """The method to tune; empty: the experiment's first."""
    objectives: tuple[str, ...] = ()
    """metrics.csv columns to improve (means over frames); empty: ``rho_p05``."""
    trials: int | None = field(default=None, metadata=_expect(lambda x: x >= 1, "at least 1 trial"))
    """Candidates to evaluate; unset: 20."""
    seed: int | None = None
    """Sampler seed; unset: 0."""
    memory_budget: int | None = None
    """Shadow-map memory in bytes no recommended setting may exceed (TOML: ``"64MiB"``, ``"16MB"`` or bytes)."""
    max_flicker: float | str | None = None
    """Largest ``flicker_metric`` a recommended setting may have: a number, or ``"best-preset"`` (the
    lowest of the engine presets within the memory budget)."""
    flicker_metric: str = "flicker"
    """The flicker column the budget applies to (flicker, flicker_same, flip_rate, …)."""


@dataclass(frozen=True)
class Method:
    """One ``[[methods]]`` entry: a name and the ``[shadow]`` fields it changes.

    Attributes
    ----------
    name : str
        As it appears in ``metrics.csv`` and the report.
    overrides : dict
        The shadow fields the entry sets (TOML names).
    settings : ShadowSettings
        The base ``[shadow]`` with ``overrides`` applied.
    """

    name: str
    overrides: dict
    settings: ShadowSettings


@dataclass(frozen=True)
class Variant:
    """One method at one sweep point: the unit that gets its own rows in ``metrics.csv``."""

    method: str
    point: str
    settings: ShadowSettings


@dataclass(frozen=True)
class Experiment:
    """A validated experiment.

    Attributes
    ----------
    name : str
        Names the results (``reports/<name>/``); defaults to the file's stem.
    description : str
    source : str
        The experiment file, absolute.
    extends : tuple of str
        The presets it extends, as written.
    scene : SceneConfig
    camera : CameraConfig
        File fields hold absolute paths.
    light : LightConfig
    shadow : ShadowSettings
        The base settings.
    methods : tuple of Method
        In file order (presets first).
    sweep : tuple of (str, tuple)
        Shadow field and its values, in file order.
    regress : dict
        Metric name to ``{"abs": float, "rel": float}`` tolerances.
    report : ReportConfig
    chunk_frames : int
        Frames per unit of work.
    tune : TuneConfig
        What ``csmlab tune`` searches (the ``[tune]`` table).
    taa : TaaConfig
        Temporal anti-aliasing (the ``[taa]`` table).
    """

    name: str
    description: str
    source: str
    extends: tuple[str, ...]
    scene: SceneConfig
    camera: CameraConfig
    light: LightConfig
    shadow: ShadowSettings
    methods: tuple[Method, ...]
    sweep: tuple[tuple[str, tuple], ...]
    regress: dict
    report: ReportConfig
    chunk_frames: int
    tune: TuneConfig = TuneConfig()
    taa: TaaConfig = TaaConfig()

    def points(self) -> list[tuple[str, dict]]:
        """Sweep points ``(label, {field: value})`` (:func:`sweep_points`)."""
        return sweep_points(self.sweep)

    def variants(self) -> list[Variant]:
        """Every method at every sweep point, methods outermost; the sweep's fields win over the method's."""
        return [Variant(method=m.name, point=label, settings=m.settings.replace(**point))
                for m in self.methods for label, point in self.points()]

    def with_frames(self, frames: int) -> Experiment:
        """The same experiment with the camera's frame cap set to ``frames``."""
        if not isinstance(frames, int) or frames < 1:
            raise InputError(f"expected at least 1 frame, got {frames!r}", field="--frames")
        camera = CameraConfig(**{**_record_fields(self.camera), "frames": frames})
        return Experiment(**{**_record_fields(self), "camera": camera})


_TOP_FIELDS = ("name", "description", "extends", "chunk_frames", "scene", "camera", "light", "shadow", "methods",
               "sweep", "regress", "report", "tune", "taa")
_DOCS_TOP = {
    "name": "Names the results folder reports/<name>/; defaults to the file's stem.",
    "description": "One line on what the experiment shows.",
    "chunk_frames": "Frames per unit of work (parallelism, resume); results do not depend on it.",
}


def sweep_points(sweep) -> list[tuple[str, dict]]:
    """The points of a sweep, ``(label, {field: value})``, in order, the last field fastest.

    ``sweep`` is a sequence of ``(field, values)`` pairs or a dict of them; labels read
    ``resolution=512/levels=16``. Without a sweep the one point is ``("base", {})``.
    """
    pairs = list(sweep.items()) if isinstance(sweep, dict) else list(sweep)
    if not pairs:
        return [("base", {})]
    names = [name for name, _ in pairs]
    return [("/".join(f"{n}={repr(v) if isinstance(v, float) else v}" for n, v in zip(names, values)),
             dict(zip(names, values)))
            for values in itertools.product(*(values for _, values in pairs))]


def _record_fields(record) -> dict:
    return {f.name: getattr(record, f.name) for f in fields(record)}
