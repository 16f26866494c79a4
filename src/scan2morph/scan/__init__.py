"""Range and stereo scans: repair of range images (spikes, small holes, depth-camera cleanup),
the scanner's view of a range image, stereo reconstruction."""

from scan2morph.lazy import lazy_exports

__getattr__, __dir__, __all__ = lazy_exports(
    __name__,
    {
        "depth_cleanup": ("smooth_depth", "trim_depth_edges"),
        "holes": ("fill_holes",),
        "repair": ("repair_range",),
        "settings": ("DEFAULT_DEPTH_REPAIR", "DEFAULT_REPAIR"),
        "spikes": ("remove_spikes",),
        "stereo": ("DEFAULT_STEREO", "reconstruct_stereo", "stereo_params"),
        "view": ("SCANNER_FRAME", "ScannerView", "scanner_view"),
    },
)
