"""The refinement's texture under another exposure: a take darker or brighter than its neutral
shows the same skin at another gain. Oracle: a known displacement of a random skin texture."""

import numpy as np
import pytest
from scipy.ndimage import map_coordinates

from scan2morph.refine.flow import GAIN_BAND, high_pass, measure_flow, texture_gain
from tests.support.plane_take import skin_texture


def _warp(image, dx, dy):
    """``image(x + dx(x), y + dy(x))`` (cubic), the image seen through a displacement."""
    yy, xx = np.mgrid[0 : image.shape[0], 0 : image.shape[1]].astype(np.float64)
    return map_coordinates(image, [yy + dy, xx + dx], order=3, mode="nearest")


def _as_8bit(image):
    """An 8-bit camera's image of ``image`` (grey levels): rounded and clipped to 0..255."""
    return np.clip(np.rint(image), 0, 255).astype(np.uint8).astype(np.float64)


@pytest.mark.parametrize("gain", [0.3, 0.2, 1.6])
def test_a_take_exposed_otherwise_measures_the_displacement_as_well(gain):
    """The take's 8-bit image at another exposure (gain 0.3 or 0.2: its texture spans a third or
    a fifth of the grey levels; 1.6: brighter, below the top): the flow finds the known
    displacement as well as at the neutral's exposure. Measured, median error of the confident
    vectors: 0.046 px at the same exposure; 0.048, 0.049 and 0.046 px (the take's texture scaled
    by its gain, :func:`texture_gain`); 0.110, 0.123 and 0.067 px with the neutral's scale for
    both (before 2026-12-07)."""
    ref = skin_texture((160, 160), 2, contrast=25.0) - 50.0  # grey levels about 100 +- 25
    yy, xx = np.mgrid[0:160, 0:160] / 160.0
    dx = 2.5 * np.sin(np.pi * yy) * np.cos(np.pi * xx)  # up to 2.5 px
    dy = -1.5 * np.sin(np.pi * xx)
    moving = _warp(ref, -dx, -dy)
    inner = np.s_[20:-20, 20:-20]
    median, share = {}, {}
    for g in (1.0, gain):
        flow, conf = measure_flow(_as_8bit(ref), _as_8bit(g * moving))
        good = conf[inner] > 0.3
        err = np.hypot(flow[inner][..., 0] - dx[inner], flow[inner][..., 1] - dy[inner])
        median[g], share[g] = float(np.median(err[good])), float(good.mean())
    assert median[1.0] < 0.06 and share[1.0] > 0.9, (median, share)
    assert median[gain] < 1.2 * median[1.0] and share[gain] > share[1.0] - 0.02, (median, share)


def test_the_texture_gain_is_the_exposure_ratio_and_one_within_its_band():
    """:func:`texture_gain` of a displaced texture at another exposure is that exposure's
    ratio (within 5%); within :data:`GAIN_BAND` of 1 it is 1 exactly (takes of one exposure
    are refined as they were); without texture in the reference it is 1."""
    ref = skin_texture((160, 160), 2, contrast=25.0) - 50.0
    yy, xx = np.mgrid[0:160, 0:160] / 160.0
    moving = _warp(ref, -2.0 * np.sin(np.pi * yy), 1.0 * np.cos(np.pi * xx))
    both = np.ones(ref.shape, bool)
    _, rms_r = high_pass(_as_8bit(ref), 4.0)
    for g in (0.2, 0.3, 0.5, 0.8, 1.3, 1.8):
        _, rms_m = high_pass(_as_8bit(g * moving), 4.0)
        assert texture_gain(rms_r, rms_m, both, 2.0) == pytest.approx(g, rel=0.05), g
    for g in (0.95, 1.0, 1.05):
        _, rms_m = high_pass(_as_8bit(g * moving), 4.0)
        assert texture_gain(rms_r, rms_m, both, 2.0) == 1.0, g
    assert 1 / GAIN_BAND < 0.95 and GAIN_BAND > 1.05
    flat = np.full(ref.shape, 0.5)  # no texture above the noise: no gain to measure
    assert texture_gain(flat, 0.3 * flat, both, 2.0) == 1.0
