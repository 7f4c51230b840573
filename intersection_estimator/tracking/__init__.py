"""Radar tracking (beyond the paper): radar detections -> tracks for the tracked pipeline.

The paper scores raw radar detections voxel by voxel (§II-A); on real junctions (curved
approaches, turn pockets, offset arms) that straight voxel model loses most arms, while the
tracked pipeline follows such geometry. Every real radar stack tracks its detections, so a
window of radar rows without tracked objects goes through :class:`RadarTracker` first
(``TrackerConfig.enabled``; off = the paper's raw-detection model). Modules: ``kalman``
(constant-velocity filter, RTS smoother), ``gating`` (which rows a track takes, duplicate
tracks), ``tracker`` (scans in, tracked rows out).
"""

from .config import TrackerConfig
from .tracker import RADAR_TRACK_ID0, RadarTracker, is_radar_track, radar_rows_of, track_radar

__all__ = ['TrackerConfig', 'RadarTracker', 'RADAR_TRACK_ID0', 'track_radar', 'radar_rows_of', 'is_radar_track']
