"""Range and stereo scans: repair of range images (spikes, small holes, depth-camera cleanup),
the scanner's view of a range image, stereo reconstruction."""

from scan2morph.scan.depth_cleanup import smooth_depth, trim_depth_edges
from scan2morph.scan.holes import fill_holes
from scan2morph.scan.repair import repair_range
from scan2morph.scan.settings import DEFAULT_DEPTH_REPAIR, DEFAULT_REPAIR
from scan2morph.scan.spikes import remove_spikes
from scan2morph.scan.stereo import DEFAULT_STEREO, reconstruct_stereo, stereo_params
from scan2morph.scan.view import SCANNER_FRAME, ScannerView, scanner_view

__all__ = [
    "DEFAULT_DEPTH_REPAIR",
    "DEFAULT_REPAIR",
    "DEFAULT_STEREO",
    "SCANNER_FRAME",
    "ScannerView",
    "fill_holes",
    "reconstruct_stereo",
    "remove_spikes",
    "repair_range",
    "scanner_view",
    "smooth_depth",
    "stereo_params",
    "trim_depth_edges",
]
