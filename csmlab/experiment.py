"""Runs an experiment: frames × methods × sweep points → the results files.

The unit of work (:class:`Unit`) is a chunk of consecutive frames of one workload (scene, camera
path, light) for a set of its variants (methods × sweep points). Per frame the unit renders the view
(camera visibility and the ray-traced reference) once and shares it by its variants; each of these
then renders its shadow and is measured, the temporal metrics against the same variant's previous
frame. Without TAA a unit is a chunk of frames of every variant; a chunk starts one frame early and
drops that frame's rows. With TAA every frame depends on the history of all before it, so a unit is
every frame of some of the variants (:func:`units_of_work`), and each unit resolves the reference's
history itself. Either way no number depends on where the path was cut, on how many processes ran
it, or on whether the run was interrupted and resumed.

The parent process builds the workload (and so checks every input file) before any work, hands it
to the executor once per worker, stores each finished chunk on disk (for ``--resume``, and so that
its memory does not grow with the path) and, when all chunks are in, reads them back one at a time
to write the results files (:mod:`csmlab.results`) and the report's captures in a fixed order.
"""

from __future__ import annotations

import dataclasses
import os
import pickle
import time
from collections.abc import Callable
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from pathlib import Path
from typing import NamedTuple

import numpy as np

from csmlab import results
from csmlab.camera import CameraPath
from csmlab.cascades.bounds import shadow_end
from csmlab.config import Experiment, Variant, config_hash, experiment_document, experiment_toml, workload_hash
from csmlab.errors import InputError
from csmlab.executor import execute, start_process_server
from csmlab.geometry import normalized
from csmlab.light import LightPath, direction_from_angles
from csmlab.paths.timing import TimingReport
from csmlab.paths.view_check import ViewFindings
from csmlab.scene.core import Scene
from csmlab.shadow_policies import shadow_light_direction

__all__ = ["IMAGE_FRAMES", "ChunkResult", "Job", "RunResult", "Unit", "Workload", "build_workload", "check_device",
           "chunk_ranges", "image_frames", "run_chunk", "run_experiment", "shadow_light", "units_of_work"]


@dataclass(frozen=True)
class Workload:
    """What every method of an experiment sees: the scene, the camera path, the light.

    Attributes
    ----------
    scene : Scene
    path : CameraPath
        One pose per frame.
    light : LightPath
        One direction per frame.
    width, height : int
        Image size in pixels.
    key : str
        The workload hash (:func:`csmlab.config.workload_hash`).
    timing : TimingReport or None
        A recorded path's repeated time stamps and tracking gaps; None for a generated path.
    restarts : frozenset of int
        Frames that follow a cut tracking gap: no temporal metrics (the camera jumped).
    views : ViewFindings or None
        The check of every frame's view (``[camera] view_check``); None when it is off.
    blend : dict or None
        The level's glTF ``alphaMode = "BLEND"`` materials and the rule they were read by
        (``summary.json``'s ``blend_materials``); None without any.
    """

    scene: Scene
    path: CameraPath
    light: LightPath
    width: int
    height: int
    key: str
    timing: TimingReport | None = None
    restarts: frozenset = frozenset()
    views: ViewFindings | None = None
    blend: dict | None = None


@dataclass(frozen=True)
class Job:
    """What a worker needs besides its chunk: sent once per worker process.

    Attributes
    ----------
    workload : Workload
    variants : tuple of Variant
        Every method × sweep point, in results order.
    snapshot_frames : frozenset of int
        Frames whose full-resolution images the report keeps.
    image_frames : frozenset of int
        Frames whose animation frame and per-pixel record the report keeps (:func:`image_frames`).
    device : str
        Warp device, ``cpu`` or ``cuda``.
    held_depths : dict of (method, point) to ndarray, shape (N, 2)
        SDSM with hysteresis: the held view-depth range of every frame (computed once over the whole
        path, so that no chunk depends on where the path was cut).
    held_extents : dict of (method, point) to ndarray, shape (N, C, 2)
        Extent hysteresis: each tight box's held size in every frame (computed once, likewise).
    threads : int
        CPU threads each worker's kernels may use at once (:class:`csmlab.render.DeviceScene`): the
        cores the processes leave over.
    taa : TaaConfig or None
        Temporal anti-aliasing (``[taa]``, :mod:`csmlab.metrics.taa`) when enabled: the frames are
        jittered and every method's S and the reference resolved; None: off.
    """

    workload: Workload
    variants: tuple[Variant, ...]
    snapshot_frames: frozenset
    device: str
    image_frames: frozenset = frozenset()
    held_depths: dict = dataclasses.field(default_factory=dict)
    held_extents: dict = dataclasses.field(default_factory=dict)
    threads: int = 1
    taa: object = None


class Unit(NamedTuple):
    """A worker's unit of work: frames ``[start, stop)`` of the variants of results ranks ``ranks``.

    Attributes
    ----------
    start, stop : int
    ranks : tuple of int
        Increasing indices into :attr:`Job.variants`. The unit holding rank 0 records the view's
        timings, so that they are recorded once per frame however the variants were split.
    """

    start: int
    stop: int
    ranks: tuple[int, ...]


@dataclass(frozen=True)
class ChunkResult:
    """The results of a :class:`Unit`: frames ``[start, stop)`` of the variants of ``ranks``.

    Attributes
    ----------
    start, stop : int
    rows : list of MetricRow
        One per frame × variant of the unit.
    timings : list of TimingRow
        Wall-clock seconds; the view's stages have empty method and point (only in the unit of rank 0).
    captures : dict of (method, point) to bytes
        The report's per-frame records (:func:`csmlab.report.capture.capture_frame`), in frame order,
        one pickled list per variant: the parent stores each as a part of the chunk's file
        (:func:`csmlab.results.save_chunk`) and reads back one variant's at a time.
    ranks : tuple of int
        The unit's variants, results ranks (:attr:`Unit.ranks`).
    """

    start: int
    stop: int
    rows: list
    timings: list
    captures: dict
    ranks: tuple


@dataclass(frozen=True)
class RunResult:
    """What :func:`run_experiment` did.

    Attributes
    ----------
    out_dir : Path
    frames : int
        Frames in the workload.
    chunks_run, chunks_resumed : int
        Units of work (:class:`Unit`) computed now and units taken from an interrupted run.
    seconds : float
        Wall-clock time of the run.
    summary : dict
        The contents of ``summary.json``.
    """

    out_dir: Path
    frames: int
    chunks_run: int
    chunks_resumed: int
    seconds: float
    summary: dict


def check_device(device: str) -> str:
    """``device`` if Warp can run on it here: ``cpu``, or ``cuda``/``cuda:N`` on a machine with that GPU.

    Raises
    ------
    InputError
        Naming ``--device`` and what was expected.
    """
    if device == "cpu":
        return device
    if device != "cuda" and not (device.startswith("cuda:") and device[5:].isdigit()):
        raise InputError(f"expected cpu, cuda or cuda:N, got {device!r}", field="--device")
    import warp as wp

    from csmlab.kernels import start_warp

    start_warp()
    count = wp.get_cuda_device_count()
    if count == 0 or (device != "cuda" and int(device[5:]) >= count):
        raise InputError(f"expected a CUDA device, but this machine has {count} CUDA device(s) for {device!r}: "
                         "run with --device cpu", field="--device")
    return device


def _located(error: ValueError, *, file, field: str) -> InputError:
    return error if isinstance(error, InputError) else InputError(str(error), file=file, field=field)


def _scene(experiment: Experiment) -> Scene:
    from csmlab.scene import make_scene

    config = experiment.scene
    try:
        if config.kind == "mesh" and config.parts:
            from csmlab.scene.parts import PartPlacement, load_parts

            placements = [PartPlacement(file=p.file, translation=p.translation, rotation_deg=p.rotation_deg,
                                        scale=p.scale, matrix=p.matrix) for p in config.parts]
            scene = load_parts(placements, file=config.file, scale=config.scale, up=config.up, ground=config.ground,
                               blend_casters=config.blend_casters, name=Path(experiment.source).stem)
        elif config.kind == "mesh":
            scene = make_scene("mesh", file=config.file, scale=config.scale, up=config.up, ground=config.ground,
                               blend_casters=config.blend_casters)
        else:
            scene = make_scene(config.kind, seed=config.seed, **config.params)
        return _moved_scene(scene, config.offset)
    except OSError as exc:
        raise InputError(f"expected a readable mesh file, got {exc.strerror or exc}", file=config.file,
                         field="scene.file") from None
    except ValueError as exc:
        file = config.file if config.kind == "mesh" else experiment.source
        raise _located(exc, file=file, field="scene") from None


def _moved_scene(scene: Scene, offset) -> Scene:
    """``scene`` moved by ``offset`` metres (``[scene] offset``); the same scene when it is zero."""
    if not any(offset):
        return scene
    return Scene(scene.vertices + np.asarray(offset, dtype=np.float64), scene.triangles, scene.normals, scene.albedo,
                 name=scene.name, uv=scene.uv, vertex_mask=scene.vertex_mask, alpha=scene.alpha, colour=scene.colour)


def _moved_path(path: CameraPath, offset) -> CameraPath:
    """``path`` moved with the world by ``offset`` metres (``[scene] offset``)."""
    if not any(offset):
        return path
    return dataclasses.replace(path, positions=path.positions + np.asarray(offset, dtype=np.float64))


def _scene_sun(experiment: Experiment) -> tuple[np.ndarray, np.ndarray]:
    """``[light] from_scene``: the glTF scene's directional light in csmlab's axes (``[scene] up``) and its colour."""
    from csmlab.scene.gltf import read_gltf, sun_of
    from csmlab.scene.mesh import UP_AXES

    try:
        sun = sun_of(read_gltf(experiment.scene.file))
        return UP_AXES[experiment.scene.up] @ sun.direction, sun.colour
    except ValueError as exc:
        raise _located(exc, file=experiment.scene.file, field="light.from_scene") from None


def _first_light_direction(experiment: Experiment):
    light = experiment.light
    if light.from_scene:
        return _scene_sun(experiment)[0]
    if light.direction is not None:
        return normalized(light.direction, name="light.direction")
    return direction_from_angles(elevation_deg=light.elevation_deg, azimuth_deg=light.azimuth_deg)


def fits_level(experiment: Experiment) -> bool:
    """Whether the generated path is placed in the scene's level (``[camera] fit_level``; unset: a mesh scene)."""
    camera = experiment.camera
    if not camera.path:
        return False
    return experiment.scene.kind == "mesh" if camera.fit_level is None else camera.fit_level


def _camera_path(experiment: Experiment, light_direction, level) -> tuple[CameraPath, TimingReport | None, frozenset]:
    """The camera path, a recorded file's timing report (else None) and the frames that restart after a cut.

    ``level`` (:class:`csmlab.scene.level.Level`, the scene moved by ``[scene] offset``) places a
    generated path in it; None leaves it in csmlab's own layout, moved by the offset afterwards.
    """
    from csmlab.paths import make_path
    from csmlab.paths.formats import read_recording

    camera = experiment.camera
    projection = {"fov_y_deg": camera.fov_y_deg, "aspect": camera.aspect, "near": camera.near, "far": camera.far}
    if camera.path:
        try:
            path = make_path(camera.path, frames=camera.frames, fps=camera.fps, seed=camera.seed,
                             light_direction=light_direction, level=level, orbit_height=camera.orbit_height,
                             flight_height=camera.flight_height, **projection, **camera.params)
        except ValueError as exc:
            raise _located(exc, file=experiment.source, field="camera") from None
        return path, None, frozenset()
    try:
        recording = read_recording(
            camera.file, format=camera.format or None, convention=camera.convention or None, scale=camera.scale,
            offset=camera.offset, anchor=camera.anchor, time_offset=camera.time_offset, fps=camera.fps,
            times_file=camera.times_file or None, from_first_pose=True, duplicate_times=camera.duplicate_times,
            max_gap=camera.max_gap, gaps=camera.gaps, camera=camera.camera, **projection)
        path = recording.path
        if camera.start_s is not None or camera.end_s is not None:
            start = path.times[0] if camera.start_s is None else camera.start_s
            end = path.times[-1] if camera.end_s is None else camera.end_s
            path = path.crop(start, end)
        path = path.head(camera.frames)
        restarts = frozenset(int(i) for i in np.flatnonzero(np.isin(path.times, recording.restarts)))
        return path, recording.timing, restarts
    except ValueError as exc:
        raise _located(exc, file=camera.file, field="camera.file") from None


def _light_path(experiment: Experiment, frames: int) -> LightPath:
    light = experiment.light
    if light.from_scene:
        direction, colour = _scene_sun(experiment)
        return dataclasses.replace(LightPath.static(direction, frames), colour=colour)
    if light.direction is not None:
        return LightPath.static(light.direction, frames)
    if light.is_static:
        return LightPath.static(direction_from_angles(elevation_deg=light.elevation_deg,
                                                      azimuth_deg=light.azimuth_deg), frames)
    return LightPath.sun(
        elevation_deg=light.elevation_deg, azimuth_deg=light.azimuth_deg,
        elevation_end_deg=light.elevation_deg if light.elevation_end_deg is None else light.elevation_end_deg,
        azimuth_end_deg=light.azimuth_deg if light.azimuth_end_deg is None else light.azimuth_end_deg,
        frames=frames)


def build_workload(experiment: Experiment) -> Workload:
    """The scene, camera path and light of ``experiment``, every input file read and checked.

    Raises
    ------
    InputError
        From a scene, mesh or camera-path file, naming the file and what was expected.
    """
    from csmlab.paths.view_check import check_views, findings_line
    from csmlab.scene.level import Level

    scene = _scene(experiment)
    check = experiment.camera.view_check
    level = Level.of(scene) if fits_level(experiment) or check != "off" else None
    path, timing, restarts = _camera_path(experiment, _first_light_direction(experiment),
                                          level if fits_level(experiment) else None)
    if not fits_level(experiment):
        path = _moved_path(path, experiment.scene.offset)
    _check_casters(experiment, scene)
    views = None if check == "off" else check_views(level, path)
    if check == "refuse" and not views.clean:
        raise InputError(f"refused: {findings_line(views.as_dict())}; expected every view to fit the scene "
                         f"(view_check = \"warn\" runs it and names the frames)", file=experiment.source,
                         field="camera.view_check")
    return Workload(scene=scene, path=path, light=_light_path(experiment, len(path)),
                    width=_image_width(experiment.camera, path), height=experiment.camera.height,
                    key=workload_hash(experiment, frames=len(path)), timing=timing, restarts=restarts, views=views,
                    blend=_blend_note(experiment))


def _check_casters(experiment: Experiment, scene: Scene) -> None:
    """InputError naming the method when its ``[shadow] blend_casters = "none"`` would leave the level no caster (every
    triangle blended): before any frame runs, not from a worker mid-run."""
    if not scene.blended or np.any(scene.vertex_blend[scene.triangles[:, 0]] < 0):
        return
    for method in experiment.methods:
        if method.settings.blend_casters == "none":
            raise InputError(f"expected a rule that leaves the level a caster; every triangle of {scene.name} is "
                             f"blended (alphaMode BLEND) and \"none\" drops them all from method {method.name}'s "
                             f"depth pass", file=experiment.source, field=f"{method.name}.shadow.blend_casters")


def _blend_note(experiment: Experiment) -> dict | None:
    """``{"rule": …, "materials": ["file: name", …]}``: the glTF files' ``BLEND`` materials (a run warns about them,
    :func:`csmlab.scene.gltf_materials.blend_line`), with ``"methods": {name: rule}`` for the methods whose
    ``[shadow] blend_casters`` casts them otherwise; None for a procedural scene or a level without any."""
    from csmlab.scene.gltf import read_gltf
    from csmlab.scene.gltf_materials import blend_materials

    scene = experiment.scene
    if scene.kind != "mesh":
        return None
    files = dict.fromkeys(f for f in (scene.file, *(p.file for p in scene.parts)) if f)
    names = [f"{Path(file).name}: {name}" for file in files if Path(file).suffix.lower() in (".gltf", ".glb")
             for name in blend_materials(read_gltf(file).document)]
    if not names:
        return None
    own = {m.name: m.settings.blend_casters for m in experiment.methods if m.settings.blend_casters != "scene"}
    return {"rule": scene.blend_casters, "materials": names, **({"methods": own} if own else {})}


def _image_width(camera, path: CameraPath) -> int:
    """``[camera] width``, unless the camera file states another aspect: then ``height × aspect``, rounded.

    Pixels stay square: a glTF camera's ``aspectRatio`` or a nerfstudio path's render size sets the
    image's shape, ``[camera] height`` its size.
    """
    if abs(path.aspect - camera.aspect) <= 1e-9 * camera.aspect:
        return camera.width
    return max(8, int(round(camera.height * path.aspect)))


def chunk_ranges(frames: int, chunk_frames: int) -> list[tuple[int, int]]:
    """``[start, stop)`` ranges of at most ``chunk_frames`` frames covering ``range(frames)``."""
    return [(start, min(start + chunk_frames, frames)) for start in range(0, frames, chunk_frames)]


def units_of_work(frames: int, variants: int, *, chunk_frames: int, taa: bool, split: bool,
                  kept=()) -> tuple[list[Unit], list[Unit]]:
    """The units a run needs, ``(done, todo)``: those ``kept`` from an interrupted run it reuses, and the rest.

    Parameters
    ----------
    frames, variants : int
        Frames in the workload; variants (methods × sweep points) in results order.
    chunk_frames : int
        Frames per unit without TAA.
    taa : bool
        ``[taa] enabled``: a frame's history depends on every frame before it, so a unit covers
        every frame, of some of the variants.
    split : bool
        With TAA, one unit per variant (for several processes: a process that is free takes over
        variants another has not started, which balances variants of very different cost — in
        ``experiments/taa.toml`` godot4 took 5–7× exact's time — with no cost model; the price is the
        view each unit renders again, 0.1 s a frame there against 1.2 s of a variant's, so ~8 % more
        work in all); otherwise one unit of them all (one process: the view once).
    kept : iterable of Unit
        Units found on disk (:func:`csmlab.results.kept_chunks`); without TAA those of this run's
        chunks are reused, with TAA any of every frame whose variants no unit taken before holds
        (a run resumed with another ``--jobs`` reuses what the first finished).

    Returns
    -------
    done, todo : list of Unit
    """
    everyone = tuple(range(variants))
    if not taa:
        planned = [Unit(start, stop, everyone) for start, stop in chunk_ranges(frames, chunk_frames)]
        kept = set(kept)
        return [u for u in planned if u in kept], [u for u in planned if u not in kept]
    done, covered = [], set()
    for unit in sorted(kept):
        if (unit.start, unit.stop) == (0, frames) and unit.ranks and covered.isdisjoint(unit.ranks):
            done.append(unit)
            covered.update(unit.ranks)
    left = tuple(rank for rank in everyone if rank not in covered)
    if split:
        return done, [Unit(0, frames, (rank,)) for rank in left]
    return done, [Unit(0, frames, left)] if left else []


_PREPARED: dict = {}


def _prepared_scene(job: Job):
    """The scene on the job's device, built once per process and kept for the next chunks."""
    from csmlab.kernels import start_warp
    from csmlab.render import prepare_scene

    key = (job.workload.key, job.device, job.threads)
    if key not in _PREPARED:
        start_warp()
        _PREPARED.clear()
        _PREPARED[key] = prepare_scene(job.workload.scene, device=job.device, threads=job.threads)
    return _PREPARED[key]


_UNIT_END: dict = {}
"""The last unit this process ran without TAA, under ``"last"``: ``(job, stop, ranks, frames)``, its
variants' frames ``stop − 1`` by ``(method, point)``. The next unit of the same job and variants that
starts at ``stop`` takes them as its previous frames instead of rendering frame ``stop − 1`` again
(:func:`csmlab.executor.run_pool` hands a process consecutive units). They are the frames a fresh
start renders, bit for bit: scrolled depth maps are the maps rasterized whole (:mod:`csmlab.scrolling`),
and the temporal metrics read of a previous frame its maps, camera and settings only."""


def run_chunk(job: Job, chunk: Unit) -> ChunkResult:
    """Render and measure frames ``[start, stop)`` of the unit's variants (a worker's unit of work).

    Frame ``start - 1`` is rendered too, as the previous frame of ``start``, and gives no rows —
    unless the unit this process ran last ended there (:data:`_UNIT_END`).
    """
    from threadpoolctl import threadpool_limits

    import csmlab.metrics  # noqa: F401  (loads ꟻLIP's OpenMP library, so that the limit below reaches it)

    # One thread per process for every library's pool (ꟻLIP's OpenMP, OpenBLAS): the executor
    # runs one process per core, and a second pool per process only oversubscribes the cores —
    # ꟻLIP's busy-waiting OpenMP threads made each call 3× slower and stalled OpenBLAS (issue 14).
    with threadpool_limits(limits=1):
        return _run_chunk(job, chunk)


def _shadow_reach(settings, *, camera_far: float) -> float:
    """Metres from the camera the shadows of ``settings`` may reach in any frame: ``shadow_distance``, or for a
    distance that follows the camera (``shadow_distance_from``) its end at the camera's far plane, the farthest
    a visible point can lie."""
    if settings.shadow_distance_from == "fixed":
        return settings.shadow_distance
    return shadow_end(method=settings.shadow_distance_from, shadow_distance=settings.shadow_distance,
                      max_shadow_distance=settings.max_shadow_distance, camera_far=camera_far)


def _run_chunk(job: Job, chunk: Unit) -> ChunkResult:
    from csmlab.metrics import measure_frame
    from csmlab.metrics.taa import halton_jitter, resolve_view
    from csmlab.render import render_shadow, render_view
    from csmlab.report.capture import capture_frame
    from csmlab.report.pixels import world_grid

    start, stop, ranks = chunk
    variants = [job.variants[rank] for rank in ranks]
    # Every unit renders the view; the one of rank 0 times it, once per frame for the whole run.
    times_view = 0 in ranks
    workload = job.workload
    scene = _prepared_scene(job)
    grid = world_grid(workload.path.positions, reach=max(_shadow_reach(v.settings, camera_far=workload.path.far)
                                                         for v in job.variants))
    rows, timings, captures, previous = [], [], {}, {}
    taa = job.taa
    # TAA's histories: each variant's resolve of S and the reference's, with the view they follow.
    history, reference_history, previous_view = {}, None, None
    first = max(start - 1, 0)
    last = _UNIT_END.pop("last", None)
    if taa is None and start > 0 and last is not None and last[0] is job and last[1:3] == (start, tuple(ranks)):
        previous, first = last[3], start
    for index in range(first, stop):
        pose = workload.path.pose(index)
        counted = index >= start
        # Frame start − 1 is only the previous frame of frame start: of it the temporal metrics
        # read the cascades and depth maps, not its reference or shadow.
        view = render_view(scene, pose, workload.light.direction(index), width=workload.width,
                           height=workload.height, index=index, reference=counted,
                           previous_light_direction=workload.light.direction(index - 1) if index else None,
                           jitter=None if taa is None else halton_jitter(index, phases=taa.phases),
                           light_colour=workload.light.colour)
        if index in workload.restarts:
            previous = {}
            history, reference_history, previous_view = {}, None, None
        if counted and times_view:
            timings += [results.TimingRow(index, "", "", stage, seconds) for stage, seconds in view.timings.items()]
        if taa is not None and counted:
            began = time.perf_counter()
            reference_history = resolve_view(view.reference, view, previous_view, reference_history, taa=taa,
                                             device=job.device)
            if times_view:
                timings.append(results.TimingRow(index, "", "", "taa_reference", time.perf_counter() - began))
        for variant in variants:
            key = (variant.method, variant.point)
            held = job.held_depths.get(key)
            extents = job.held_extents.get(key)
            frame = render_shadow(scene, view, variant.settings,
                                  visible_depth=None if held is None else tuple(held[index]),
                                  held_extents=None if extents is None else extents[index], lookup=counted,
                                  scroll_from=previous[key].maps if key in previous else None,
                                  light_direction=shadow_light(workload, variant.settings, index))
            if counted:
                resolved = None
                if taa is not None:
                    began = time.perf_counter()
                    history[key] = resolve_view(frame.shadow.lit, view, previous_view, history.get(key), taa=taa,
                                                device=job.device)
                    timings.append(results.TimingRow(index, *key, "taa", time.perf_counter() - began))
                    resolved = (history[key], reference_history)
                began = time.perf_counter()
                measures = measure_frame(frame, previous.get(key), device=job.device, taa=resolved)
                measured = time.perf_counter() - began
                rows.append(results.MetricRow(index, float(pose.time_s), variant.method, variant.point,
                                              measures.values))
                timings += [results.TimingRow(index, *key, stage, seconds) for stage, seconds in frame.timings.items()]
                timings.append(results.TimingRow(index, *key, "metrics", measured))
                captures.setdefault(key, []).append(
                    capture_frame(frame, measures, snapshot=index in job.snapshot_frames, grid=grid,
                                  images=index in job.image_frames, taa=resolved))
            previous[key] = frame
        previous_view = view
    if taa is None:
        _UNIT_END["last"] = (job, stop, tuple(ranks), previous)
    packed = {key: pickle.dumps(kept, protocol=pickle.HIGHEST_PROTOCOL) for key, kept in captures.items()}
    return ChunkResult(start=start, stop=stop, rows=rows, timings=timings, captures=packed, ranks=tuple(ranks))


def shadow_light(workload: Workload, settings, index: int) -> np.ndarray:
    """The unit light direction ``(3,)`` frame ``index``'s shadow maps are built with under ``settings.sun_policy``.

    Taken from the whole sun path (:func:`csmlab.shadow_policies.shadow_light_direction`), so that no
    chunk depends on where the path was cut, and normalized as :func:`csmlab.render.render_view`
    normalizes the view's light: with ``every_frame`` it is the view's light bit for bit.
    """
    return normalized(shadow_light_direction(workload.light.directions, index, policy=settings.sun_policy,
                                             update_frames=settings.sun_update_frames,
                                             step_deg=settings.sun_step_deg), name="light direction")


def _held_depths(workload: Workload, variants, *, device: str) -> dict:
    """Per SDSM variant with hysteresis, its held view-depth range ``(N, 2)`` over the whole path.

    The visible range of every frame is read from a G-buffer of the run's size once, here, before
    the chunks run: hysteresis depends on every earlier frame, which a chunk does not render.
    """
    from csmlab.cascades.bounds import BOUNDS_METHODS, HOLD_METHODS

    wanted = [v for v in variants if BOUNDS_METHODS[v.settings.bounds].visible
              and HOLD_METHODS[v.settings.hold].active(v.settings.hysteresis)]
    if not wanted:
        return {}
    from csmlab.render import visible_depth

    scene = _prepared_scene(Job(workload=workload, variants=(), snapshot_frames=frozenset(), device=device))
    ranges = np.array([visible_depth(scene, workload.path.pose(i), width=workload.width, height=workload.height)
                       or (np.nan, np.nan) for i in range(len(workload.path))], dtype=np.float64)
    return {(v.method, v.point): HOLD_METHODS[v.settings.hold].held(ranges, hysteresis=v.settings.hysteresis,
                                                                      near=workload.path.near) for v in wanted}


def _held_extents(workload: Workload, variants, held_depths: dict, *, device: str) -> dict:
    """Per variant with extent hysteresis, its tight boxes' held sizes ``(N, C, 2)`` over the whole path.

    Like :func:`_held_depths`, computed before the chunks run from every frame's tight extents (host
    math; an SDSM variant's split range read from its held range or the frame's G-buffer).
    """
    wanted = [v for v in variants if v.settings.extent_hysteresis > 0.0]
    if not wanted:
        return {}
    from csmlab.cascades import tight_extents
    from csmlab.cascades.bounds import BOUNDS_METHODS
    from csmlab.cascades.stabilize import held_extents
    from csmlab.render import visible_depth

    ranges = None
    out = {}
    for v in wanted:
        depths = held_depths.get((v.method, v.point))
        if BOUNDS_METHODS[v.settings.bounds].visible and depths is None:
            if ranges is None:
                scene = _prepared_scene(Job(workload=workload, variants=(), snapshot_frames=frozenset(), device=device))
                ranges = [visible_depth(scene, workload.path.pose(i), width=workload.width, height=workload.height)
                          for i in range(len(workload.path))]
            depths = ranges
        extents = [tight_extents(pose=workload.path.pose(i), light_direction=shadow_light(workload, v.settings, i),
                                 settings=v.settings, visible_depth=None if depths is None else depths[i])
                   for i in range(len(workload.path))]
        out[(v.method, v.point)] = held_extents(extents, hysteresis=v.settings.extent_hysteresis)
    return out


IMAGE_FRAMES = 240
"""Most frames a run keeps images of for the report (the animation and the interactive page's
per-pixel records, ~0.7 MB per frame and variant): a longer path keeps an even sample of this many,
so that the memory and the report of a 10,000-frame path stay those of a short one. The metrics,
``cascades.csv`` and the snapshots keep every frame they name."""


def image_frames(frames: int) -> frozenset:
    """The frames of a ``frames``-frame run that keep images: all of them, or :data:`IMAGE_FRAMES` evenly spread."""
    if frames <= IMAGE_FRAMES:
        return frozenset(range(frames))
    return frozenset(int(f) for f in np.round(np.linspace(0, frames - 1, IMAGE_FRAMES)))


def _snapshot_frames(experiment: Experiment, frames: int) -> frozenset:
    from csmlab.report.capture import default_snapshot_frames

    chosen = experiment.report.snapshot_frames
    if chosen is None:
        return frozenset(default_snapshot_frames(frames))
    return frozenset(f for f in chosen if f < frames)


def run_experiment(experiment: Experiment, *, out_dir, jobs: int = 1, executor: str = "inprocess",
                   address: str | None = None, device: str = "cpu", resume: bool = False,
                   progress: Callable[[int, int], None] | None = None,
                   workload: Workload | None = None, images: bool = True) -> RunResult:
    """Run every frame × method × sweep point of ``experiment`` and write its results files.

    Parameters
    ----------
    experiment : Experiment
    out_dir : str or Path
        The results directory (created).
    jobs : int
        Worker processes of the pool or local Dask cluster.
    executor : str
        Where the chunks run: a key of :data:`csmlab.executor.EXECUTORS`.
    address : str, optional
        Dask scheduler: ``"local"`` or ``tcp://HOST:PORT``.
    device : str
        ``cpu`` or ``cuda``.
    resume : bool
        Keep the units of work an interrupted run of the same config left in ``out_dir``.
    progress : callable, optional
        ``progress(frames_done, frames_total)``, called before the first unit and after each;
        ``frames_done`` is the frames' worth of work done (frames × variants done ÷ variants, whole).
    workload : Workload, optional
        :func:`build_workload` of ``experiment``, built already: the runs of a tune, which differ in
        their methods alone, share one (its scene generated, its level's BVH built and its views
        checked once, not once a run). None builds it here.
    images : bool
        Keep the report's images: the animations and the interactive page's per-pixel records
        (:func:`image_frames`). False keeps the metrics, the timings, the cascade rows and the
        snapshots asked for: a tune's runs, whose summaries alone are read, record nothing else.

    Returns
    -------
    RunResult

    Raises
    ------
    InputError
        On a bad device or input file, before any work is done.
    """
    began = time.perf_counter()
    check_device(device)
    if executor == "pool" and jobs > 1:
        # Unless the command line started it already: its imports overlap the workload's building.
        start_process_server()
    if workload is None:
        workload = build_workload(experiment)
    frames = len(workload.path)
    hash_ = config_hash(experiment)
    # Chunks of another device differ in float rounding: they must not be mixed into this run.
    chunk_key = f"{hash_}-{device}"
    out = results.prepare_output(out_dir, resolved_toml=experiment_toml(experiment), run_key=chunk_key,
                                 resume=resume)
    variants = tuple(experiment.variants())
    # TAA's history runs from the first frame: a unit is every frame of some variants, so that no
    # number depends on a cut. Finished units live on disk, not here: the parent's memory does not
    # grow with the path.
    kept = [Unit(*unit) for unit in results.kept_chunks(out, run_key=chunk_key)] if resume else []
    done, todo = units_of_work(frames, len(variants), chunk_frames=experiment.chunk_frames,
                               taa=experiment.taa.enabled, split=jobs > 1, kept=kept)
    units = sorted(done + todo)
    resumed = len(done)

    def report_progress() -> None:
        if progress is not None:
            progress(sum((u.stop - u.start) * len(u.ranks) for u in done) // len(variants), frames)

    report_progress()
    held_depths = _held_depths(workload, variants, device=device)
    # Processes share out the cores first (a Dask worker has one thread); a core no process has is a thread's.
    processes = jobs if executor == "dask" else max(1, min(jobs, len(todo)))
    threads = 1 if executor == "dask" else max(1, (os.cpu_count() or 1) // processes)
    job = Job(workload=workload, variants=variants, snapshot_frames=_snapshot_frames(experiment, frames),
              device=device, image_frames=image_frames(frames) if images else frozenset(), held_depths=held_depths,
              held_extents=_held_extents(workload, variants, held_depths, device=device), threads=threads,
              taa=experiment.taa if experiment.taa.enabled else None)
    order = [(v.method, v.point) for v in variants]
    for chunk, result in execute(run_chunk, todo, shared=job, executor=executor, jobs=jobs, address=address):
        parts = {_captures_part(rank): result.captures[key] for rank, key in enumerate(order)
                 if key in result.captures}
        results.save_chunk(out, dataclasses.replace(result, captures={}), run_key=chunk_key, parts=parts)
        done.append(chunk)
        report_progress()
    summary = _write_results(out, experiment, job, units, run_key=chunk_key, config_hash=hash_)
    results.clear_chunks(out)
    return RunResult(out_dir=out, frames=frames, chunks_run=len(todo), chunks_resumed=resumed,
                     seconds=time.perf_counter() - began, summary=summary)


def _captures_part(rank: int) -> str:
    """Name of the chunk part holding the captures of the variant of results rank ``rank``."""
    return f"captures{rank}"


def _write_results(out: Path, experiment: Experiment, job: Job, units: list[Unit], *, run_key: str,
                   config_hash: str) -> dict:
    from csmlab.invariants import summary_invariants
    from csmlab.metric_registry import metric_columns
    from csmlab.report.capture import write_captures, write_casters

    columns = metric_columns(max(v.settings.map_count for v in job.variants))
    order = {(v.method, v.point): rank for rank, v in enumerate(job.variants)}

    def chunks(rank: int):
        """The units holding variant ``rank``, in frame order."""
        for unit in units:
            if rank in unit.ranks:
                yield results.load_chunk(out, *unit, run_key=run_key)

    # One variant at a time, read back from the units on disk unit by unit: its rows (written,
    # then kept as arrays for the summary) and its captures, so that nothing of a long path is
    # whole in memory.
    arrays = {}

    def variant_rows():
        for rank, variant in enumerate(job.variants):
            key = (variant.method, variant.point)
            parts = []
            for chunk in chunks(rank):
                rows = [row for row in chunk.rows if (row.method, row.point) == key]
                parts.append(results.metric_arrays(rows, columns=columns))
                yield rows
            arrays[key] = {name: np.concatenate([part[name] for part in parts]) for name in parts[0]}

    def frame_timings():
        """The timings of each frame range, every unit of it together (write_timings sorts a block)."""
        for start, stop in sorted({(unit.start, unit.stop) for unit in units}):
            yield [row for unit in units if (unit.start, unit.stop) == (start, stop)
                   for row in results.load_chunk(out, *unit, run_key=run_key).timings]

    results.write_metrics(out / "metrics.csv", variant_rows(), columns=columns)
    results.write_timings(out / "timings.csv", frame_timings(), order=order)

    def write_variant(rank: int) -> None:
        variant = job.variants[rank]
        captures = []
        for unit in units:
            packed = results.load_chunk_part(out, *unit, _captures_part(rank)) if rank in unit.ranks else None
            captures += [] if packed is None else pickle.loads(packed)
        write_captures(out, method=variant.method, point=variant.point, captures=captures)

    # A variant more than the cores at a time: their files' compression (zlib) releases the GIL, the
    # workers have finished, and while a file waits on the disk (write_atomic's fsync) another
    # variant's compression takes its core (the default run's three on 2 cores: 1.46 → 1.27 s from
    # the last unit's arrival to the summary, against two at a time).
    with ThreadPoolExecutor(max_workers=(os.cpu_count() or 1) + 1) as pool:
        list(pool.map(write_variant, range(len(job.variants))))
    write_casters(out, job.workload.scene.vertices, job.workload.scene.triangles)
    methods, points = results.summarize(arrays, columns=columns, methods=[m.name for m in experiment.methods],
                                        points=[label for label, _ in experiment.points()])
    summary = dict(name=experiment.name, config_hash=config_hash, workload_hash=job.workload.key, device=job.device,
                   frames=len(job.workload.path), config=experiment_document(experiment),
                   light_moves=not experiment.light.is_static, point_fields=dict(experiment.points()),
                   stabilization={m.name: {v.point: v.settings.stabilization for v in job.variants
                                           if v.method == m.name}
                                  for m in experiment.methods},
                   invariants=summary_invariants(job.variants, light_static=experiment.light.is_static,
                                                 fov_y_deg=job.workload.path.fov_y_deg),
                   methods=methods, points=points)
    if job.workload.timing is not None:
        summary["recording"] = job.workload.timing.as_dict()
    if job.workload.views is not None:
        summary["view_check"] = job.workload.views.as_dict()
    if job.workload.blend is not None:
        summary["blend_materials"] = job.workload.blend
    if np.any(job.workload.light.colour != 1.0):
        summary["light_colour"] = [float(c) for c in job.workload.light.colour]
    results.write_summary(out / "summary.json", **summary)
    return results.read_summary(out)
