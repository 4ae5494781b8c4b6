"""The workflow's stage of :mod:`triaxtrack.sfm` (rule reconstruct_cell), from the files to
``reconstruction/cell.json`` and the cell-wall points and residuals (:func:`run_reconstruct_cell`).
"""

from __future__ import annotations

import json
from pathlib import Path

from triaxtrack.calibrate.files import calibrated_camera
from triaxtrack.eccentricity import mark_radii
from triaxtrack.kit import design_points, load_kit_design, target_table
from triaxtrack.optics import CellConfig, configured_cell
from triaxtrack.reconstruction_config import SfmConfig
from triaxtrack.sfm import cell_summary, reconstruct_cell
from triaxtrack.tables import LABELS, POINTS, RESIDUALS, read_table, write_table
from triaxtrack.testfolder import read_calibration, write_cell


def run_reconstruct_cell(
    *,
    calibrations: list[str | Path],
    labels: str | Path,
    kit: str | Path,
    cell: str | Path,
    points: str | Path,
    residuals: str | Path,
    reconstruction_cfg: dict,
    cell_cfg: dict,
) -> None:
    """Rule reconstruct_cell: the cameras (intrinsics from ``calibrations``) and the cell wall in
    air from the labelled cell-wall targets of ``labels``, and the cameras that see too little
    of the wall posed through it from the targets in the water (:func:`~triaxtrack.sfm.reconstruct_cell`,
    kit folder ``kit``; ``reconstruction_cfg`` and ``cell_cfg``: the config's ``reconstruction``
    and ``cell`` sections). Writes :func:`~triaxtrack.sfm.cell_summary` to ``cell``, the wall's
    ``points`` (at frame 0) and the air ``residuals``; prints the summary and a warning per camera
    left out."""
    cameras = {}
    for path in calibrations:
        cam = calibrated_camera(read_calibration(path))
        cameras[cam.name] = cam
    design = load_kit_design(kit)
    table = target_table(design)
    design_pts = design_points(design, table)
    wall = (table["surface"] == "cell_outer").to_numpy()
    # targets in the water at their design positions at the reference frame (the specimen
    # undeformed), for the cameras that see too little of the wall
    water = design_pts[~wall].assign(kind=table.loc[~wall, "surface"].to_numpy())
    cfg = SfmConfig.from_dict(reconstruction_cfg)
    optics = configured_cell(design, CellConfig.from_dict(cell_cfg))
    labelled = read_table(labels, LABELS)
    radii = mark_radii(design, table)
    rec = reconstruct_cell(
        cameras, labelled, design_pts[wall], cfg, water=water, cell=optics, mark_radius_mm=radii
    )
    summary = cell_summary(rec)
    write_cell(cell, summary)
    write_table(rec.points.assign(frame=0, time_s=0.0), points, POINTS)
    write_table(rec.residuals, residuals, RESIDUALS)
    print(json.dumps({k: v for k, v in summary.items() if k != "cameras"}, indent=2))
    for name, why in summary["cameras_dropped"].items():
        print(f"WARNING: {name} left out: {why}")
