"""Range and stereo scans: repair of range images (spikes, small holes)."""

from scan2morph.scan.repair import DEFAULT_REPAIR, fill_holes, remove_spikes, repair_range

__all__ = ["DEFAULT_REPAIR", "fill_holes", "remove_spikes", "repair_range"]
