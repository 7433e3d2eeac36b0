"""Where the tests find the repository and their fixtures, whatever folder a test module sits in."""

from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
"""The repository's root (README.md, csmlab/, data/, docs/)."""

TEST_DATA = ROOT / "tests" / "data"
"""The tests' own fixtures (tests/data/: engines, gltf, meshes, paths, threejs_csm)."""
