"""ColorVideoVDP's JOD (csmlab.report.video_quality): the scores' two ends, and what is said where it cannot run.

The tests that score need ``pycvvdp`` (``pip install -e .[video]``) and skip, saying why, where it
does not import; CI does not install it.
"""

import sys

import numpy as np
import pytest

from csmlab.errors import InputError
from csmlab.report import video_quality
from csmlab.report.video_quality import INSTALL, cvvdp_missing, jod_of_sequences, jod_scores

needs_cvvdp = pytest.mark.skipif(cvvdp_missing() is not None, reason=str(cvvdp_missing()))


def _noise_sequence(frames=6, height=48, width=64, seed=1) -> np.ndarray:
    rng = np.random.default_rng(seed)
    still = rng.integers(40, 200, size=(height, width, 3), dtype=np.uint8)
    return np.repeat(still[None], frames, axis=0)


def _flickering(sequence: np.ndarray, amplitude: int) -> np.ndarray:
    """The sequence with its left half brightened by ``amplitude`` on odd frames: a 15 Hz flicker at 30 fps."""
    out = sequence.astype(np.int16)
    out[1::2, :, : sequence.shape[2] // 2] += amplitude
    return np.clip(out, 0, 255).astype(np.uint8)


def test_a_missing_package_is_reported_with_how_to_install_it(monkeypatch):
    monkeypatch.setitem(sys.modules, "pycvvdp", None)
    reason = cvvdp_missing()
    assert reason is not None and INSTALL in reason and "\n" not in reason
    with pytest.raises(RuntimeError, match="pip install"):
        jod_of_sequences(_noise_sequence(), _noise_sequence(), fps=30.0)


def test_an_unknown_sequence_is_refused_naming_the_field(tmp_path):
    with pytest.raises(InputError, match="sequence.*expected one of shaded"):
        jod_scores(tmp_path, sequence="after_everything")


def test_sequences_of_different_shapes_are_refused():
    with pytest.raises(ValueError, match=r"\(N, h, w, 3\) uint8"):
        jod_of_sequences(_noise_sequence(width=64), _noise_sequence(width=32), fps=30.0)


def test_every_sequence_names_a_test_and_a_reference_array():
    assert video_quality.SEQUENCES["shaded"] == ("shaded", "reference_shaded")
    assert all(len(pair) == 2 and pair[0] != pair[1] for pair in video_quality.SEQUENCES.values())


@needs_cvvdp
def test_a_sequence_against_itself_scores_10_jod():
    sequence = _noise_sequence()
    assert jod_of_sequences(sequence, sequence, fps=30.0) == pytest.approx(10.0, abs=1e-3)


@needs_cvvdp
def test_a_stronger_flicker_scores_fewer_jods():
    reference = _noise_sequence()
    weak, strong = (jod_of_sequences(_flickering(reference, a), reference, fps=30.0) for a in (6, 40))
    assert 10.0 - 1e-3 > weak > strong
