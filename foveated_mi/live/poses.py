"""Per-frame poses, the CSV files the live view records and ``foveated-mi sequence`` replays.

They live in :mod:`foveated_mi.poses` (a sequence config reads them without the live view);
this module gives the same names for code that imports them from here.
"""
from __future__ import annotations

from ..poses import CAMERA_COLUMNS, COLUMNS, GAZE_BOUND, INFO_COLUMNS, REQUIRED, Pose, PoseTrack

__all__ = ["Pose", "PoseTrack", "COLUMNS", "CAMERA_COLUMNS", "GAZE_BOUND", "INFO_COLUMNS",
           "REQUIRED"]
