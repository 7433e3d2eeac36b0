"""Camera paths: procedural generators and recorded files (TUM, KITTI, EuRoC, csmlab CSV/JSON).

- :mod:`~csmlab.paths.generators`: ``dolly pan orbit walk flyover jitter dueling`` and
  :func:`make_path`;
- :mod:`~csmlab.paths.conventions`: axis conventions (``opengl tum kitti mocap euroc unreal
  unity``) and csmlab's yaw/pitch/roll;
- :mod:`~csmlab.paths.formats`: :func:`read_path` / :func:`write_path` over the formats of
  :mod:`~csmlab.paths.tum`, :mod:`~csmlab.paths.kitti`, :mod:`~csmlab.paths.euroc` and
  :mod:`~csmlab.paths.tabular`, all checked by :mod:`~csmlab.paths.recorded`.
"""

from csmlab.paths.conventions import CONVENTIONS, Convention, orientation_from_yaw_pitch_roll
from csmlab.paths.formats import PATH_FORMATS, PathFormat, guess_format, read_path, write_path
from csmlab.paths.generators import PATH_GENERATORS, make_path

__all__ = [
    "CONVENTIONS",
    "PATH_FORMATS",
    "PATH_GENERATORS",
    "Convention",
    "PathFormat",
    "guess_format",
    "make_path",
    "orientation_from_yaw_pitch_roll",
    "read_path",
    "write_path",
]
