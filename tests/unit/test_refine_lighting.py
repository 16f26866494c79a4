"""The refinement's texture under another exposure: a take darker or brighter than its neutral
shows the same skin at another gain. Oracle: a known displacement of a random skin texture."""

import numpy as np
import pytest
from scipy.ndimage import map_coordinates

from scan2morph.refine import RefineParams, shape_channels, texture_channel
from scan2morph.refine.flow import GAIN_BAND, MIN_GAIN, high_pass, measure_flow, texture_gain
from scan2morph.refine.shape import ShapeParams
from tests.support.plane_take import skin_texture


def _warp(image, dx, dy):
    """``image(x + dx(x), y + dy(x))`` (cubic), the image seen through a displacement."""
    yy, xx = np.mgrid[0 : image.shape[0], 0 : image.shape[1]].astype(np.float64)
    return map_coordinates(image, [yy + dy, xx + dx], order=3, mode="nearest")


def _as_8bit(image):
    """An 8-bit camera's image of ``image`` (grey levels): rounded and clipped to 0..255."""
    return np.clip(np.rint(image), 0, 255).astype(np.uint8).astype(np.float64)


def _scene():
    """A skin texture (grey levels about 100 +- 25) and its known displacement (px)."""
    ref = skin_texture((160, 160), 2, contrast=25.0) - 50.0
    yy, xx = np.mgrid[0:160, 0:160] / 160.0
    dx = 2.5 * np.sin(np.pi * yy) * np.cos(np.pi * xx)  # up to 2.5 px
    dy = -1.5 * np.sin(np.pi * xx)
    return ref, dx, dy, _warp(ref, -dx, -dy)


@pytest.mark.parametrize("gain", [0.3, 0.2, 1.6])
def test_a_take_exposed_otherwise_measures_the_displacement_as_well(gain):
    """The take's 8-bit image at another exposure (gain 0.3 or 0.2: its texture spans a third or
    a fifth of the grey levels; 1.6: brighter, about 1% of it clipped): matched at its gain, the
    flow finds the known displacement as well as at the neutral's exposure. Measured, median
    error of the confident vectors: 0.046 px at the same exposure; 0.049, 0.051 and 0.048 px;
    0.110, 0.123 and 0.067 px with the neutral's scale for both (``match_gain`` off, as before
    2026-12-07)."""
    ref, dx, dy, moving = _scene()
    inner = np.s_[20:-20, 20:-20]
    median, share = {}, {}
    for g, match in ((1.0, True), (gain, True), (gain, False)):
        flow, conf = measure_flow(_as_8bit(ref), _as_8bit(g * moving), match_gain=match)
        good = conf[inner] > 0.3
        err = np.hypot(flow[inner][..., 0] - dx[inner], flow[inner][..., 1] - dy[inner])
        median[g, match], share[g, match] = float(np.median(err[good])), float(good.mean())
    same, matched, unmatched = median[1.0, True], median[gain, True], median[gain, False]
    assert same < 0.06 and share[1.0, True] > 0.9, (median, share)
    assert matched < 1.15 * same and share[gain, True] > share[1.0, True] - 0.02, (median, share)
    assert unmatched > 1.3 * same, median  # the gain is what the matching mends


def test_the_texture_gain_is_the_exposure_ratio_shrunk_towards_one():
    """:func:`texture_gain` of a displaced texture at another exposure is that exposure's
    ratio shrunk towards 1 by :data:`GAIN_BAND` (within 5%), and 1 exactly within the band
    (takes of one exposure are refined as they were); without texture in the reference it is
    1."""
    ref, _, _, moving = _scene()
    both = np.ones(ref.shape, bool)
    _, rms_r = high_pass(_as_8bit(ref), 4.0)
    for g in (0.2, 0.3, 0.5, 0.8, 1.3, 1.8):
        _, rms_m = high_pass(_as_8bit(g * moving), 4.0)
        want = g * GAIN_BAND if g < 1 else g / GAIN_BAND
        assert texture_gain(rms_r, rms_m, both, 2.0) == pytest.approx(want, rel=0.05), g
    for g in (0.95, 1.0, 1.05):
        _, rms_m = high_pass(_as_8bit(g * moving), 4.0)
        assert texture_gain(rms_r, rms_m, both, 2.0) == 1.0, g
    flat = np.full(ref.shape, 0.5)  # no texture above the noise: no gain to measure
    assert texture_gain(flat, 0.3 * flat, both, 2.0) == 1.0


def test_a_take_that_shows_none_of_the_texture_is_not_matched():
    """A take whose face is white (clipped) or flat shows none of the neutral's texture: matched
    at its gain, it would be noise amplified to the flow's grey levels. Below
    :data:`MIN_GAIN` nothing is measured."""
    ref, _, _, moving = _scene()
    for image in (np.full(ref.shape, 255.0), _as_8bit(0.02 * moving + 200.0)):
        flow, conf = measure_flow(_as_8bit(ref), image, match_gain=True)
        assert not conf.any() and not flow.any()
    assert MIN_GAIN <= 0.1


def test_only_the_skins_texture_is_matched_at_its_gain():
    """The texture channel of a refinement matches the take's gain; the curvature image (a
    crease is contrast, not exposure) and a texture gated by the shape (one that did not
    correlate: a projected speckle against the skin) do not."""
    image = np.zeros((8, 8))
    texture = texture_channel(image, image, RefineParams())
    assert texture.match_gain
    xyz = np.dstack([*np.mgrid[0:8, 0:8].astype(float), np.full((8, 8), 500.0)])
    channels = shape_channels(xyz, xyz, np.eye(4), [texture], ShapeParams())
    flows = [c for c in channels if hasattr(c, "match_gain")]
    assert len(flows) >= 2 and not any(c.match_gain for c in flows)


def test_the_texture_gain_needs_enough_textured_pixels():
    """:func:`texture_gain` measures a gain from :data:`MIN_GAIN_PIXELS` pixels where the
    reference has texture (local RMS above twice the noise), and gives 1 from fewer."""
    from scan2morph.refine.flow import MIN_GAIN_PIXELS

    rms_r = np.full((20, 20), 1.0)  # below twice the noise of 2: no texture
    rms_m = 0.3 * np.full((20, 20), 10.0)
    both = np.ones((20, 20), bool)
    textured = rms_r.reshape(-1)
    textured[: MIN_GAIN_PIXELS - 1] = 10.0
    assert texture_gain(rms_r, rms_m, both, 2.0) == 1.0
    textured[MIN_GAIN_PIXELS - 1] = 10.0
    assert texture_gain(rms_r, rms_m, both, 2.0) == pytest.approx(0.3 * GAIN_BAND)
    assert texture_gain(rms_r, rms_m, ~both, 2.0) == 1.0  # no pixel with both images
