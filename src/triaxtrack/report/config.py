"""The config section ``report``: :class:`ReportConfig`, the settings of the report's figures
(:func:`~triaxtrack.report.figures.run_report_figures`), movie
(:func:`~triaxtrack.report.movie.run_specimen_movie`) and 3-D viewer
(:func:`~triaxtrack.report.viewer.run_specimen_viewer`)."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

from triaxtrack.config_section import section_from_dict


@dataclass(frozen=True)
class ReportConfig:
    """Settings of config section ``report`` (config/README.md)."""

    strain_map_frames: int = 4  # times shown in the strain maps
    movie_fps: float = 10  # frames per second of the movie
    movie_max_frames: int = 300  # at most this many processed frames, spread over the test
    movie_colour_by: str = "radial"  # radial (displacement) | e_zz | e_tt | e_tz
    movie_magnify: float = 1.0  # displacement magnification of the drawn geometry
    movie_height_px: int = 720  # movie height, pixels
    viewer_colour_by: str = "e_zz"  # the 3-D viewer's colour: e_zz | e_tt | e_tz
    viewer_max_frames: int = 60  # at most this many processed frames on the viewer's time slider

    @staticmethod
    def from_dict(d: Mapping[str, Any] | None) -> ReportConfig:
        """From the config's ``report`` section (ValueError naming an unknown key)."""
        return section_from_dict(ReportConfig, d, "report")
