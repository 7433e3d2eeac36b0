"""A calibrated video metric: ColorVideoVDP's JOD of each method's rendered sequence against the ray-traced one.

ColorVideoVDP (Mantiuk et al. 2024, the ``cvvdp`` package, module ``pycvvdp``) models how the eye
sees a video on a display — spatial and temporal contrast sensitivity, masking, colour — and
gives one score in JOD (just-objectionable differences): 10 for a sequence that cannot be told
from its reference, one unit less for each step at which 75 % of observers would prefer the
reference. Unlike csmlab's per-frame measures (ΔE, SSIM, ꟻLIP) it sees flicker as the eye
integrates it over time. It is an optional extra (``pip install -e .[video]``: PyTorch and
``cvvdp``, whose model ships inside the package and runs on the CPU); :func:`cvvdp_missing` says
why it cannot run where it is not installed.

The sequences are those of the run's per-pixel records (``pixels/<method>__<point>.npz``, see
:mod:`csmlab.report.pixels`): every frame, at the records' sampled pixels, sRGB uint8, black where
no surface. :data:`SEQUENCES` names each pair of test and reference arrays a record may hold, so
that a stage that changes what the player sees (temporal anti-aliasing) adds its pair beside
``shaded`` and is scored the same way. :func:`write_jod` adds the scores to ``summary.json`` under
``"jod"``; the report shows them.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from csmlab.errors import InputError
from csmlab.files import write_atomic
from csmlab.report.capture import read_npz

__all__ = ["DISPLAY", "INSTALL", "SEQUENCES", "SEQUENCE_LABELS", "cvvdp_missing", "jod_of_sequences", "jod_scores",
           "record_sequences", "write_jod"]

SEQUENCES = {
    "shaded": ("shaded", "reference_shaded"),
    "after_taa": ("shaded_taa", "reference_shaded_taa"),
}
"""Input sequences by name: the record arrays ``(test, reference)``, each ``(N, h, w, 3)`` uint8 sRGB.

``shaded`` is the method's shadow as rendered, against the ray-traced shadow of the same views.
``after_taa`` is the same pair after temporal anti-aliasing, the method's S and the reference R
each through the same TAA (:func:`csmlab.report.pixels.taa_pixels`; only a run with ``[taa]`` on
holds it). :func:`write_jod` scores every pair the records hold.
"""

SEQUENCE_LABELS = {"shaded": "as rendered", "after_taa": "after TAA"}
"""How the report names each of :data:`SEQUENCES` in its JOD table."""

DISPLAY = "standard_fhd"
"""ColorVideoVDP's display model: a 24-inch 1920×1080 sRGB office monitor, 200 cd/m², seen from 60 cm."""
INSTALL = "pip install -e .[video]  (PyTorch's CPU build and cvvdp)"
"""How to install the video metric, as the report and the CLI say it."""


def cvvdp_missing() -> str | None:
    """Why ColorVideoVDP cannot run here (one line), or None when ``pycvvdp`` imports.

    Besides a missing package, PyPI's ``torchvision`` (which ``pycvvdp`` imports) is built against
    PyTorch's CUDA build and fails to import beside the CPU build with a ``RuntimeError``; that
    is reported the same way.
    """
    try:
        import pycvvdp  # noqa: F401
    except ImportError as error:
        return f"ColorVideoVDP is not installed ({error}): {INSTALL}"
    except RuntimeError as error:
        return f"ColorVideoVDP does not import ({error}); torchvision must match the installed torch"
    return None


def jod_of_sequences(test, reference, *, fps: float, display: str = DISPLAY) -> float:
    """ColorVideoVDP's JOD of a test sequence against its reference.

    Parameters
    ----------
    test, reference : array_like, shape (N, h, w, 3), uint8
        sRGB display values, frame by frame.
    fps : float, keyword-only
        Frames per second of both sequences (> 0).
    display : str, keyword-only
        ColorVideoVDP's display model name.

    Returns
    -------
    float
        JOD: 10 for sequences that cannot be told apart, lower for visible differences.

    Raises
    ------
    ValueError
        If the sequences differ in shape or are not ``(N, h, w, 3)`` uint8, or ``fps`` is not positive.
    RuntimeError
        If ColorVideoVDP cannot run here (:func:`cvvdp_missing`).
    """
    test, reference = np.asarray(test), np.asarray(reference)
    if test.shape != reference.shape or test.ndim != 4 or test.shape[3] != 3 or test.dtype != np.uint8 \
            or reference.dtype != np.uint8:
        raise ValueError(f"expected two (N, h, w, 3) uint8 sRGB sequences of one shape, got {test.shape} "
                         f"{test.dtype} and {reference.shape} {reference.dtype}")
    if not (np.isfinite(fps) and fps > 0):
        raise ValueError(f"fps: expected a positive frame rate, got {fps}")
    missing = cvvdp_missing()
    if missing:
        raise RuntimeError(missing)
    import pycvvdp
    import torch

    metric = pycvvdp.cvvdp(display_name=display, quiet=True, device=torch.device("cpu"))
    with torch.no_grad():
        jod, _ = metric.predict(test, reference, dim_order="FHWC", frames_per_second=float(fps))
    return float(jod)


def jod_scores(out_dir, *, sequence: str = "shaded", display: str = DISPLAY) -> dict[str, float]:
    """JOD of every recorded variant's ``sequence`` (:data:`SEQUENCES`) in a results directory.

    Parameters
    ----------
    out_dir : str or Path
        A results directory with per-pixel records (``pixels/*.npz``).
    sequence : str, keyword-only
        A name in :data:`SEQUENCES`.
    display : str, keyword-only
        ColorVideoVDP's display model.

    Returns
    -------
    dict
        Record stem (``<method>__<point>``) → JOD, for each record holding both arrays, in file-name order.

    Raises
    ------
    InputError
        If ``sequence`` is not a name of :data:`SEQUENCES` or a record is unreadable.
    RuntimeError
        If ColorVideoVDP cannot run here.
    """
    return {stem: jod_of_sequences(test, reference, fps=fps, display=display)
            for stem, (test, reference, fps) in record_sequences(out_dir, sequence=sequence).items()}


def record_sequences(out_dir, *, sequence: str = "shaded") -> dict[str, tuple[np.ndarray, np.ndarray, float]]:
    """What :func:`jod_scores` feeds ColorVideoVDP: each record's ``sequence`` pair and its frame rate.

    Parameters
    ----------
    out_dir : str or Path
        A results directory with per-pixel records (``pixels/*.npz``).
    sequence : str, keyword-only
        A name in :data:`SEQUENCES`.

    Returns
    -------
    dict
        Record stem (``<method>__<point>``) → ``(test, reference, fps)``: the two ``(N, h, w, 3)`` uint8
        sRGB arrays and frames per second (the median step of the record's ``time_s``), for each record
        holding both arrays, in file-name order.

    Raises
    ------
    InputError
        If ``sequence`` is not a name of :data:`SEQUENCES` or a record is unreadable.
    """
    if sequence not in SEQUENCES:
        raise InputError(f"expected one of {', '.join(SEQUENCES)}, got {sequence!r}", field="sequence")
    test_name, reference_name = SEQUENCES[sequence]
    pairs = {}
    for path in sorted(Path(out_dir, "pixels").glob("*.npz")):
        try:
            record = read_npz(path)
        except (OSError, ValueError, EOFError) as error:
            raise InputError(f"expected a csmlab pixel record (.npz), got an unreadable file: {error}",
                             file=path) from None
        if test_name in record and reference_name in record:
            pairs[path.stem] = (record[test_name], record[reference_name], _frame_rate(record["time_s"]))
    return pairs


def write_jod(out_dir, *, display: str = DISPLAY) -> dict:
    """Score every sequence of :data:`SEQUENCES` the records hold and add them to ``summary.json``.

    Returns
    -------
    dict
        What ``summary.json`` now holds under ``"jod"``: ``display`` (the model), ``metric``
        (``"ColorVideoVDP <version>"``) and ``sequences``: name → {record stem → JOD}, only the
        sequences some record holds.

    Raises
    ------
    InputError
        If ``summary.json`` or a record is missing or unreadable.
    RuntimeError
        If ColorVideoVDP cannot run here.
    """
    from importlib.metadata import version

    from csmlab.results import json_text, read_summary

    out = Path(out_dir)
    summary = read_summary(out)
    sequences = {}
    for name in SEQUENCES:
        scores = jod_scores(out, sequence=name, display=display)
        if scores:
            sequences[name] = {stem: round(jod, 4) for stem, jod in scores.items()}
    summary["jod"] = {"display": display, "metric": f"ColorVideoVDP {version('cvvdp')}", "sequences": sequences}
    write_atomic(out / "summary.json", json_text(summary))
    return summary["jod"]


def _frame_rate(times) -> float:
    steps = np.diff(np.asarray(times, dtype=np.float64))
    steps = steps[np.isfinite(steps) & (steps > 0)]
    return float(1.0 / np.median(steps)) if steps.size else 30.0
