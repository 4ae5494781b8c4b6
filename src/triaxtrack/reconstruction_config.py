"""The config section ``reconstruction`` and the two settings it feeds: :class:`SfmConfig`
(cameras and cell in air, :mod:`triaxtrack.sfm`) and :class:`TriangulationConfig` (targets in the
water, :mod:`triaxtrack.triangulate`). Both share ``max_residual_px`` and ``eccentricity``; each
accepts the other's keys and refuses a key known to neither (:mod:`triaxtrack.config_section`).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

from triaxtrack.config_section import field_names, section_from_dict

SECTION = "reconstruction"


@dataclass(frozen=True)
class SfmConfig:
    """Settings of the cameras-and-cell reconstruction (config ``reconstruction``).

    ``ransac_px``: PnP inlier threshold; ``max_residual_px``: an observation whose residual after
    the bundle adjustment exceeds this is dropped (and the adjustment run again);
    ``min_targets``: a camera with fewer cell-wall targets (after PnP) is posed from the targets
    in the water, and one with fewer targets of any kind is left out, with the reason;
    ``pose_from_water``: pose such cameras through the wall (False: leave them out);
    ``refine_intrinsics``: let the bundle adjustment refine focal lengths, principal
    point and distortion (by default they stay as calibrated); ``eccentricity``: correct the
    cell-wall observations for the eccentricity of the marks' images
    (:mod:`triaxtrack.eccentricity`); ``design_f_max``: hold the cell-wall targets at their
    printed positions when the F statistic of that against adjusting them freely is at most this
    (:func:`triaxtrack.sfm.design_f_statistic`; None: always adjust them).
    """

    ransac_px: float = 2.0
    max_residual_px: float = 1.0
    min_targets: int = 12
    refine_intrinsics: bool = False
    pose_from_water: bool = True
    eccentricity: bool = True
    design_f_max: float | None = 1.5

    @staticmethod
    def from_dict(d: Mapping[str, Any] | None) -> SfmConfig:
        """From the config's ``reconstruction`` section (TriangulationConfig's keys accepted)."""
        return section_from_dict(SfmConfig, d, SECTION, also=field_names(TriangulationConfig))


@dataclass(frozen=True)
class TriangulationConfig:
    """Settings of the ray tracing (config ``reconstruction``).

    ``min_rays``: a point needs this many observations after outlier removal;
    ``max_residual_px``: observations above this residual are dropped, the worst of a point
    first; ``iterations``: Gauss-Newton steps on the reprojection error;
    ``refine_cell``: run :func:`~triaxtrack.triangulate.refine_cell`; ``refine_cell_points``:
    how many points (spread over the IDs) it uses; ``eccentricity``: correct the observations of
    round marks for the eccentricity of their images (:mod:`triaxtrack.eccentricity`).
    """

    min_rays: int = 2
    max_residual_px: float = 1.0
    iterations: int = 3
    refine_cell: bool = False
    refine_cell_points: int = 600
    eccentricity: bool = True

    @staticmethod
    def from_dict(d: Mapping[str, Any] | None) -> TriangulationConfig:
        """From the config's ``reconstruction`` section (SfmConfig's keys accepted)."""
        return section_from_dict(TriangulationConfig, d, SECTION, also=field_names(SfmConfig))
