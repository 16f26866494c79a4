"""Figures: headless mesh renders (pyrender) and charts (matplotlib)."""

from scan2morph.render.scene import front_direction, look_at, render_mesh

__all__ = ["front_direction", "look_at", "render_mesh"]
