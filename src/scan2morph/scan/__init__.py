"""Range and stereo scans: repair of range images (spikes, small holes), stereo reconstruction."""

from scan2morph.scan.repair import DEFAULT_REPAIR, fill_holes, remove_spikes, repair_range
from scan2morph.scan.stereo import DEFAULT_STEREO, reconstruct_stereo, stereo_params

__all__ = [
    "DEFAULT_REPAIR",
    "DEFAULT_STEREO",
    "fill_holes",
    "reconstruct_stereo",
    "remove_spikes",
    "repair_range",
    "stereo_params",
]
