"""Figures: headless mesh renders (pyrender) and charts (matplotlib).

The renderer is imported on first use, so that :mod:`scan2morph.render.names` (what the workflow
needs while it is parsed) stays light.
"""

__all__ = ["front_direction", "look_at", "render_mesh"]


def __getattr__(name: str):
    if name in __all__:
        from scan2morph.render import scene

        return getattr(scene, name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
