"""csmlab — a laboratory for cascaded shadow maps.

The pipeline, top to bottom (imports only point downward):

    cli → experiment / executor / results / report / regress
        → render (one frame) and metrics (over Frame records)
        → cascades, scene, paths, camera, light, settings
        → geometry (float64 host math) and kernels (Warp only)
"""

__version__ = "0.1.0"
