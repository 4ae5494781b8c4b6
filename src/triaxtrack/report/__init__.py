"""Figures and a movie for the workflow's HTML report.

Charts are drawn by matplotlib (Agg, never pyplot or a display): every ``*_figure`` function
takes tables (or ``quality.json`` as a dict) and returns a new :class:`matplotlib.figure.Figure`;
:func:`figure_image` draws one as a (H, W, 3) uint8 BGR image and :func:`save_figure` writes it
as PNG. Nothing here
reads or writes files except :func:`save_figure`, :func:`write_movie` and
:func:`write_movie_page`, which write the one file they are given, and the workflow's stages
:func:`run_report_figures` and :func:`run_specimen_movie`, which read a test's files and write
its figures and movie.

* :func:`volume_strain_figure`: volume change (with its uncertainty band) and the specimen
  strains against time, and the share of membrane dots measured.
* :func:`strain_map_figure`, :func:`strain_maps_figure`: local membrane strain on the unrolled
  membrane, with colour bars.
* :func:`reprojection_figure`: mean reprojection error per camera (and per frame if given).
* :func:`tracking_figure`: share of the kit's membrane dots and of the other targets reported
  per frame, losses by reason, per camera.
* :func:`specimen_frames`, :func:`write_movie`, :func:`write_movie_page`: the deforming
  specimen seen from the side, as an H.264 MP4 and as a self-contained HTML player.
* :func:`chosen_frames`: a few frames spread over the test.
* :class:`ReportConfig`: the config section ``report`` (figures, movie, viewer).
* :func:`membrane_layout`: the kit's membrane grid (rows, columns, IDs, design coordinates),
  which every figure and the movie read instead of constants.

Conventions: strains of ``volume`` are compression positive, those of ``strains`` (local
Green-Lagrange) tension positive, as in :mod:`triaxtrack.tables`; both are drawn in per cent.
Colour scales of signed quantities are diverging and symmetric about zero: blue negative, red
positive.
"""

from triaxtrack.report.common import chosen_frames
from triaxtrack.report.config import ReportConfig
from triaxtrack.report.figures import (
    LOSS_REASONS,
    REASON_COLOURS,
    REPORTED,
    draw_bars,
    reprojection_figure,
    run_report_figures,
    tracking_figure,
    volume_strain_figure,
)
from triaxtrack.report.layout import MembraneLayout, membrane_layout
from triaxtrack.report.maps import strain_map_figure, strain_maps_figure
from triaxtrack.report.movie import (
    DIVERGING,
    run_specimen_movie,
    specimen_frames,
    write_movie,
    write_movie_page,
)
from triaxtrack.report.style import DIVERGING_CMAP, PALETTE, figure_image, save_figure

__all__ = [
    "DIVERGING",
    "DIVERGING_CMAP",
    "LOSS_REASONS",
    "PALETTE",
    "REASON_COLOURS",
    "REPORTED",
    "MembraneLayout",
    "ReportConfig",
    "chosen_frames",
    "draw_bars",
    "figure_image",
    "membrane_layout",
    "reprojection_figure",
    "run_report_figures",
    "run_specimen_movie",
    "save_figure",
    "specimen_frames",
    "strain_map_figure",
    "strain_maps_figure",
    "tracking_figure",
    "volume_strain_figure",
    "write_movie",
    "write_movie_page",
]
