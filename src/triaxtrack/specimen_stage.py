"""The workflow's stage of :mod:`triaxtrack.triangulate` at the reference frame (rule
trace_specimen): the specimen's targets in the water from the first frame's labels, through the
cell of ``reconstruction/cell.json``, and the first frame's ``quality.json``
(:func:`quality_report`, :func:`with_cell_record`; :func:`quality_cell` reads its cell back for the
later stages); :func:`run_trace_specimen`.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from triaxtrack.eccentricity import mark_radii
from triaxtrack.kit import design_points, load_kit_design, target_table
from triaxtrack.kit_design import KitDesign
from triaxtrack.optics import CellConfig, CellOptics, configured_cell, read_cameras, write_cameras
from triaxtrack.reconstruction_config import TriangulationConfig
from triaxtrack.sfm import REFERENCE_FRAME
from triaxtrack.tables import LABELS, OBSERVATIONS, POINTS, RESIDUALS, read_table, write_table
from triaxtrack.testfolder import read_cell, read_test_fps, write_quality
from triaxtrack.triangulate import SpecimenReconstruction, reconstruct_specimen


def quality_report(rec: SpecimenReconstruction, labels: pd.DataFrame, membrane_ids: np.ndarray) -> dict:
    """``quality.json`` of the first frame: mean reprojection error (all used observations, and
    in air and in water), per camera, counts of targets found and reconstructed, the cell used
    and how the cell frame was fixed."""
    res = rec.residuals
    used = res[res["used"]]
    err = np.hypot(used["du_px"], used["dv_px"])
    per_camera = {
        name: {
            "mean_reprojection_px": float(err[g.index].mean()),
            "observations_used": int(len(g)),
            "observations_dropped": int((~res.loc[res["camera"] == name, "used"]).sum()),
        }
        for name, g in used.groupby("camera")
    }
    counts = []
    for frame, pts in rec.points.groupby("frame"):
        lab = labels[(labels["frame"] == frame) & (labels["id"] > 0)]
        mem = pts[pts["id"].isin(membrane_ids)]
        counts.append({
            "frame": int(frame),
            "time_s": float(pts["time_s"].iloc[0]),
            "targets_labelled": int(lab["id"].nunique()),
            "targets_reconstructed": int(len(pts)),
            "membrane_dots": int(len(membrane_ids)),
            "membrane_dots_reconstructed": int(len(mem)),
            "membrane_dots_3_rays": int((mem["n_rays"] >= 3).sum()),
            "median_sigma_mm": float(mem["sigma_mm"].median()) if len(mem) else float("nan"),
        })  # fmt: skip
    c = rec.cell
    cell: dict[str, Any] = {
        "outer_radius_mm": c.outer_radius,
        "inner_radius_mm": c.inner_radius,
        "wall_thickness_mm": c.outer_radius - c.inner_radius,
        "n_acrylic": c.n_acrylic,
        "n_water": c.n_water,
        "refined": rec.refinement is not None,
    }
    if rec.refinement is not None:
        cell["refinement"] = {
            "rms_before_px": rec.refinement.rms_before_px,
            "rms_after_px": rec.refinement.rms_after_px,
            "points_used": rec.refinement.points_used,
        }
    return {
        "mean_reprojection_px": float(err.mean()),
        "mean_reprojection_air_px": float(err[used["medium"] == "air"].mean()),
        "mean_reprojection_water_px": float(err[used["medium"] == "water"].mean()),
        "sigma0_water_px": rec.sigma0_px,
        "per_camera": per_camera,
        "frames": counts,
        "cell": cell,
        "cell_frame": rec.frame_fix,
    }


def quality_cell(quality: dict) -> CellOptics:
    """The cell of the first frame's quality report (:func:`quality_report`, rule trace_specimen's
    ``quality.json``): radii (mm) and indices, no end caps."""
    c = quality["cell"]
    return CellOptics(
        outer_radius=c["outer_radius_mm"],
        inner_radius=c["inner_radius_mm"],
        n_acrylic=c["n_acrylic"],
        n_water=c["n_water"],
    )


def with_cell_record(quality: dict, cell_doc: dict, cell_config: CellConfig, design: KitDesign) -> dict:
    """The first frame's ``quality`` (:func:`quality_report`) with the record of the cell and
    cameras of ``cell_doc`` (rule reconstruct_cell's ``cell.json``,
    :func:`triaxtrack.sfm.cell_summary`): the cell's axis tilt, cylinder RMS and ``source``, how
    each camera was posed and which were left out; and the wavelength and temperature the
    indices hold for (``cell_config``, the config's ``cell`` section, else the kit's). A new dict,
    the keys in ``quality``'s order and the new ones after them."""
    fitted, kit_cell = cell_doc["cell"], design.cell
    cell = {
        **quality["cell"],
        "wavelength_nm": cell_config.wavelength_nm or kit_cell.wavelength_nm,
        "temperature_c": cell_config.temperature_c or kit_cell.temperature_c,
        "axis_tilt_deg": fitted["axis_tilt_deg"],
        "cylinder_rms_mm": fitted["cylinder_rms_mm"],
        "source": fitted["source"],
    }
    return {
        **quality,
        "cell": cell,
        "cameras_posed": cell_doc["cameras_posed"],
        "cameras_dropped": cell_doc["cameras_dropped"],
    }


def run_trace_specimen(
    *,
    cell: str | Path,
    cell_points: str | Path,
    air_residuals: str | Path,
    labels: str | Path,
    kit: str | Path,
    test_yaml: str | Path,
    cameras: str | Path,
    points: str | Path,
    observations: str | Path,
    quality: str | Path,
    residuals: str | Path,
    picture: str | Path,
    reconstruction_cfg: dict,
    cell_cfg: dict,
) -> None:
    """Rule trace_specimen: :func:`reconstruct_specimen` at the reference frame from rule
    reconstruct_cell's ``cell`` (``cell.json``: cameras and fitted cell), ``cell_points`` and
    ``air_residuals``, the ``labels``, the kit folder ``kit`` and ``test_yaml``'s fps
    (``reconstruction_cfg``, ``cell_cfg``: the config's ``reconstruction`` and ``cell``
    sections). Writes the ``cameras`` (``cameras.json``, cell frame), all ``points``, the used
    water and air ``observations`` of the reference frame, the :func:`quality_report`
    (:func:`with_cell_record`) to ``quality``, every one of the ``residuals``, and a
    ``picture`` of the reconstruction (PNG); prints the quality but per camera."""
    import cv2

    from triaxtrack.plots import reconstruction_picture

    cell_doc = read_cell(cell)
    design = load_kit_design(kit)
    table = target_table(design)
    design_pts = design_points(design, table)
    cell_config = CellConfig.from_dict(cell_cfg)
    optics = configured_cell(design, cell_config, outer_radius=cell_doc["cell"]["outer_radius_mm"])
    fps = read_test_fps(test_yaml)
    labelled = read_table(labels, LABELS)
    in_water = table.loc[table["surface"] != "cell_outer", "id"].to_numpy()
    bottom = design_pts[(table["surface"] == "pedestal_bottom").to_numpy()]
    rec = reconstruct_specimen(
        read_cameras(cell), read_table(cell_points, POINTS).drop(columns=["frame", "time_s"]),
        read_table(air_residuals, RESIDUALS), labelled, in_water, bottom, optics,
        cell_doc["cell"]["outer_radius_sigma_mm"], TriangulationConfig.from_dict(reconstruction_cfg),
        REFERENCE_FRAME, REFERENCE_FRAME / fps, mark_radii(design, table),
    )  # fmt: skip
    membrane_ids = table.loc[table["surface"] == "membrane", "id"].to_numpy()
    report = with_cell_record(quality_report(rec, labelled, membrane_ids), cell_doc, cell_config, design)
    write_cameras(cameras, dict(sorted(rec.cameras.items())))
    write_table(rec.points, points, POINTS)
    used = rec.residuals[rec.residuals["used"]]
    write_table(used[used["frame"] == REFERENCE_FRAME], observations, OBSERVATIONS)
    write_table(rec.residuals, residuals, RESIDUALS)
    write_quality(quality, report)
    water_used = used[used["medium"] == "water"]
    image = reconstruction_picture(
        rec.cameras, rec.points, rec.cell, water_used, membrane_ids, report["mean_reprojection_px"]
    )
    cv2.imwrite(str(picture), image)
    print(json.dumps({k: v for k, v in report.items() if k != "per_camera"}, indent=2))
