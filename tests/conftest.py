"""Fixtures every test module shares.

``device`` follows Warp's own test pattern (``warp/tests/unittest_utils.get_test_devices``): a
kernel test that takes it runs once per available Warp device — the CPU everywhere, and the first
CUDA device where one is present — so a run on a GPU machine covers the whole kernel suite.
"""

import pytest
import warp as wp

# An array on one device handed to a launch on another is an error, not a kernel writing through a
# foreign pointer (Warp's default, RELAXED, checks nothing: a CPU launch given a CUDA array segfaults).
wp.config.launch_array_access_mode = wp.config.LaunchArrayAccessMode.STRICT

DEVICES = ["cpu"] + ([pytest.param("cuda:0", marks=pytest.mark.cuda)] if wp.get_cuda_device_count() > 0 else [])
"""The Warp devices this machine offers, in the order tests run on them (the CUDA one marked ``cuda``)."""


@pytest.fixture(params=DEVICES)
def device(request) -> str:
    """Each available Warp device in turn (``"cpu"``, then ``"cuda:0"`` where present)."""
    return request.param


@pytest.hookimpl(tryfirst=True)
def pytest_collection_modifyitems(items):
    """Mark ``browser`` every test that takes a ``browser`` fixture (headless chromium under Selenium).

    Marked by the fixture rather than by hand so that a new browser test cannot miss it; ``tryfirst``
    so that ``-m`` selects on the mark.
    """
    for item in items:
        if "browser" in getattr(item, "fixturenames", ()):
            item.add_marker(pytest.mark.browser)
