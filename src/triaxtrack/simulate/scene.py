"""The scene of a simulated test (:class:`Scene`, read back by :func:`load_scene`): the kit on its
surfaces, the cameras and the deforming specimen, and where a surface's points are at any
loading progress."""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pandas as pd

from triaxtrack.deformation import Deformation
from triaxtrack.kit import ShapeSet, load_kit_design, printed_shapes, surface_by_name, target_table
from triaxtrack.kit_design import KitDesign
from triaxtrack.layout import TEST_FOLDER
from triaxtrack.optics import Camera, CellOptics, cell_optics, read_cameras
from triaxtrack.simulate.config import SimulationConfig, loading_progress

OCCLUDER_NEWTON_STEPS = 3  # fixed-point steps from the soil-surface height to the printed surface's


def deformation_for(cfg: SimulationConfig, design: KitDesign) -> Deformation:
    s = design.specimen
    return Deformation(
        radius=s.diameter / 2,
        height=s.height,
        membrane_thickness=s.membrane_thickness,
        axial_strain=cfg.axial_strain,
        bulge_mm=cfg.bulge_mm,
        shear_mm=cfg.shear_mm,
        axial_nonuniformity=cfg.axial_nonuniformity,
    )


def progress(frame: int, frames: int) -> float:
    """Share of the test's duration at a frame: 0 at the first, 1 at the last (the loading
    progress of a constant strain rate; :func:`frame_progress` follows ``loading_history``)."""
    return frame / (frames - 1)


def frame_progress(frame: int, cfg: SimulationConfig) -> float:
    """Loading progress p of a frame (the deformation's): ``progress`` through the config's
    ``loading_history`` (:func:`~triaxtrack.simulate.config.loading_progress`)."""
    return float(loading_progress(cfg, frame / cfg.fps))


FOLLOWABLE_ROWS = 0.5  # a dot row's share a membrane dot may move between frames and be followed


def largest_step_rows(cfg: SimulationConfig, design: KitDesign) -> float:
    """The largest move of a membrane dot between two consecutive frames, in dot rows (the
    membrane's row pitch, ``height / rows``). Past ``FOLLOWABLE_ROWS`` a frame, a grid seen from
    a chunk's first frame (no velocity yet) looks the same one row over, and is followed there:
    14 cameras at 4K, 2 % strain with ``axial_nonuniformity`` 0.3 over 8 frames move mid-height
    0.72 rows a frame, and the tracker read 600 dots per camera one row over. A real test moves
    a few thousandths of a row a frame."""
    deformation = deformation_for(cfg, design)
    table = target_table(design)
    mem = table[table["surface"] == "membrane"]
    theta, z = mem["theta_rad"].to_numpy(float), mem["z_mm"].to_numpy(float)
    prev, step = None, 0.0
    for k in range(cfg.frames):
        now = deformation.outer_surface(theta, z, frame_progress(k, cfg))[0]
        if prev is not None:
            step = max(step, float(np.linalg.norm(now - prev, axis=1).max()))
        prev = now
    return step / (design.specimen.height / design.membrane.rows)


@dataclass
class Scene:
    """Everything needed to render any frame of a simulated test."""

    name: str
    cfg: SimulationConfig
    design: KitDesign
    table: pd.DataFrame
    shapes: list[ShapeSet]
    cameras: dict[str, Camera]
    deformation: Deformation
    cell: CellOptics


def load_scene(test_dir: str | Path) -> Scene:
    test_dir = Path(test_dir)
    scene = json.loads((test_dir / TEST_FOLDER.truth.scene).read_text())
    cfg = SimulationConfig.from_dict(scene["simulation"])
    design = load_kit_design(test_dir / TEST_FOLDER.kit)
    table = target_table(design)
    return Scene(
        name=scene["name"],
        cfg=cfg,
        design=design,
        table=table,
        shapes=printed_shapes(design, table),
        cameras=read_cameras(test_dir / TEST_FOLDER.truth.cameras),
        deformation=Deformation(**scene["deformation"]),
        cell=cell_optics(design),
    )


def _surface_points(scene: Scene, surface: str, theta_z: np.ndarray, p: float):
    """3-D points and outward normals of (theta, z) surface coordinates at progress p."""
    th, z = theta_z[:, 0], theta_z[:, 1]
    if surface == "membrane":
        return scene.deformation.outer_surface(th, z, p)
    rad = surface_by_name(scene.design)[surface]["radius"]
    pts = np.c_[rad * np.cos(th), rad * np.sin(th), z]
    nrm = np.c_[np.cos(th), np.sin(th), np.zeros_like(th)]
    if surface == "pedestal_top":
        pts = pts + scene.deformation.top_displacement(p)
    return pts, nrm


def material_height(deformation: Deformation, z: np.ndarray, theta: np.ndarray, p: float) -> np.ndarray:
    """Material height Z (mm) of the printed membrane surface's points at cell-frame height
    ``z`` (mm) and azimuth ``theta`` (rad), progress p.

    The soil surface's height ``z = H g(Z / H0)``, ``g(zeta) = zeta - k zeta (1 - zeta)``, is
    inverted exactly; ``OCCLUDER_NEWTON_STEPS`` fixed-point steps then move to the printed
    surface (offset along the normal by the membrane thickness: under 0.02 mm in z).
    """
    s = deformation
    k = s.axial_nonuniformity * p
    hc = s.current_height(p)
    z = np.asarray(z, float)
    theta = np.asarray(theta, float)

    def soil_inverse(zz: np.ndarray) -> np.ndarray:
        u = np.clip(zz / hc, 0.0, 1.0)
        return s.height * 2 * u / ((1 - k) + np.sqrt((1 - k) ** 2 + 4 * k * u))  # stable root

    Z = soil_inverse(z)
    for _ in range(OCCLUDER_NEWTON_STEPS):
        dz = s.outer_surface(theta, Z, p)[0][:, 2] - s.inner_surface(theta, Z, p)[:, 2]
        Z = soil_inverse(z - dz)
    return Z
