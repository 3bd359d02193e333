"""Robot poses in the map frame: odometry corrected by scan matching (correlative search, then PLICP)."""

from doorbatch.config import ScanMatchConfig
from doorbatch.pipeline.poses.scanmatch import ScanMatchResult, scan_match_trajectory

__all__ = ["ScanMatchConfig", "ScanMatchResult", "scan_match_trajectory"]
