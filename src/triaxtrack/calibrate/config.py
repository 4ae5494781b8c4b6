"""Calibration settings (config ``calibration``), the lens models, and the error a camera that
cannot be calibrated raises."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import cv2

from triaxtrack.config_section import section_from_dict

#: calibration models: name -> (cv2.calibrateCamera flags, number of distortion coefficients)
MODELS: dict[str, tuple[int, int]] = {
    "standard": (0, 5),
    "rational": (cv2.CALIB_RATIONAL_MODEL, 8),
}


class CalibrationError(ValueError):
    """A camera cannot be calibrated from its board images (the message names camera and files)."""


@dataclass(frozen=True)
class CalibrationConfig:
    """Settings of config ``calibration`` (config/README.md)."""

    model: str = "standard"  # standard (5 coefficients) | rational (8)
    min_images: int = 8  # fewer usable board images: error
    outlier_floor_px: float = 0.25  # an image is never rejected at or below this RMS
    outlier_mad_k: float = 5.0  # rejected above median + k * MAD (scaled) of the per-image RMS
    passes: int = 2  # corner refinements: 1, or 2 (again in undistorted coordinates, then refit)

    def __post_init__(self) -> None:
        if self.model not in MODELS:
            raise ValueError(f"calibration model must be one of {sorted(MODELS)}, not {self.model!r}")
        if self.min_images < 3:
            raise ValueError(f"calibration min_images must be at least 3, not {self.min_images}")
        if self.outlier_floor_px <= 0 or self.outlier_mad_k <= 0:
            raise ValueError("calibration outlier_floor_px and outlier_mad_k must be positive")
        if self.passes not in (1, 2):
            raise ValueError(f"calibration passes must be 1 or 2, not {self.passes}")

    @staticmethod
    def from_dict(d: Mapping[str, Any] | None) -> CalibrationConfig:
        """From the config's ``calibration`` section (ValueError naming an unknown key or a
        value out of range)."""
        return section_from_dict(CalibrationConfig, d, "calibration")
