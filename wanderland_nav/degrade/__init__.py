"""Degraded (video-3DGS-like) environments built from a grounded scene, and how far they are from it.

`build_degraded_scene(src, out, preset("splat_mesh"))` writes a scene folder the whole pipeline
consumes unchanged; `degradation_report(grounded, degraded)` measures it (`report.py`).
"""

from .build import CORRECTION, build_degraded_scene
from .poses import PoseCorrection, pose_correction
from .report import degradation_report
from .spec import PRESETS, DegradeSpec, preset

__all__ = ["CORRECTION", "PRESETS", "DegradeSpec", "PoseCorrection", "build_degraded_scene",
           "degradation_report", "pose_correction", "preset"]
