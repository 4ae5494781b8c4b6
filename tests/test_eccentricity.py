"""Eccentricity of round marks seen through the cell (triaxtrack.eccentricity), against the
area centroid of a densely projected disc, and its correction in the triangulation: exact
centroids of the dots' images give the dots' centres back only when it is applied."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from triaxtrack.eccentricity import disc_outline, eccentricity_px, mark_radii
from triaxtrack.kit import design_points, membrane_radius
from triaxtrack.optics import Camera, cell_optics, project_air, project_water
from triaxtrack.sfm import SfmConfig, reconstruct_cell
from triaxtrack.simulate import SimulationConfig, make_cameras
from triaxtrack.triangulate import TriangulationConfig, triangulate_refracted

RINGS, SECTORS = 24, 96  # the dense disc: a polar mesh of triangles


def _mesh() -> np.ndarray:
    """Triangles (T, 3) of a polar mesh of a disc: vertex 0 the centre, then RINGS rings of
    SECTORS vertices."""
    tris = [(0, 1 + j, 1 + (j + 1) % SECTORS) for j in range(SECTORS)]  # the fan round the centre
    for i in range(RINGS - 1):  # quads between rings
        a, b = 1 + i * SECTORS, 1 + (i + 1) * SECTORS
        for j in range(SECTORS):
            k = (j + 1) % SECTORS
            tris += [(a + j, b + j, b + k), (a + j, b + k, a + k)]
    return np.array(tris)


def _dense_centroids(camera, centres: np.ndarray, radii: np.ndarray, cell) -> np.ndarray:
    """(M, 2) area centroids of the images of discs (in the water through ``cell``, or in air
    with ``cell`` None), from a fine mesh of projected triangles each."""
    centres = np.atleast_2d(centres)
    rings = [disc_outline(centres, np.asarray(radii) * f, SECTORS) for f in np.arange(1, RINGS + 1) / RINGS]
    pts = np.concatenate([centres[:, None], *rings], axis=1)  # (M, 1 + RINGS * SECTORS, 3)
    flat = pts.reshape(-1, 3)
    uv = (project_air(camera, flat) if cell is None else project_water(camera, flat, cell)[0]).reshape(
        len(centres), -1, 2
    )
    t = uv[:, _mesh()]  # (M, T, 3, 2)
    a, b = t[:, :, 1] - t[:, :, 0], t[:, :, 2] - t[:, :, 0]
    area = 0.5 * np.abs(a[..., 0] * b[..., 1] - a[..., 1] * b[..., 0])
    return (area[..., None] * t.mean(axis=2)).sum(axis=1) / area.sum(axis=1)[:, None]


def _dense_centroid(camera, centre: np.ndarray, radius: float, cell) -> np.ndarray:
    return _dense_centroids(camera, centre[None], np.array([radius]), cell)[0]


@pytest.fixture(scope="module")
def ring(design):
    return {c.name: c for c in make_cameras(SimulationConfig())}, cell_optics(design)


def test_eccentricity_is_the_image_centroid_minus_the_image_of_the_centre(design, ring):
    """A membrane dot (radius 1 mm) seen nearly face on (a small eccentricity) and 50 degrees
    round and 50 mm down (a large one, over 0.01 px): the module's eccentricity equals a dense
    mesh's within 2 % and 1e-4 px."""
    cameras, cell = ring
    cam = cameras["cam01"]
    r = membrane_radius(design)
    facing = np.arctan2(*(cam.center[[1, 0]]))
    for dtheta, z, least in ((0.0, 60.0, 0.0), (np.deg2rad(50), 20.0, 0.01)):
        centre = np.array([r * np.cos(facing + dtheta), r * np.sin(facing + dtheta), z])
        want = _dense_centroid(cam, centre, 1.0, cell) - project_water(cam, centre[None], cell)[0][0]
        got = eccentricity_px(cam, centre[None], np.array([1.0]), cell)[0]
        assert np.linalg.norm(want) > least
        assert np.linalg.norm(got - want) < 0.02 * np.linalg.norm(want) + 1e-4


def test_exact_dot_centroids_give_the_centres_back_only_when_corrected(design, table, ring):
    """Observations at the exact image centroids of 60 membrane dots in every camera that sees
    them: without the correction the points are biased towards the axis by micrometres; with it
    they are the centres within 0.3 micrometres."""
    cameras, cell = ring
    pts = design_points(design, table)
    mem = pts[(table["surface"] == "membrane").to_numpy()].iloc[::64]
    radii = mark_radii(design, table)
    rows = []
    for cam in cameras.values():
        for p in mem.itertuples():
            centre = np.array([p.x_mm, p.y_mm, p.z_mm])
            to_cam = cam.center[:2] - centre[:2]
            if np.dot(to_cam, centre[:2]) < 0.5 * np.linalg.norm(to_cam) * np.linalg.norm(centre[:2]):
                continue  # seen more obliquely than 60 degrees (or from behind)
            uv = _dense_centroid(cam, centre, radii[p.id], cell)
            if np.isfinite(uv).all() and 0 < uv[0] < cam.width and 0 < uv[1] < cam.height:
                rows.append((cam.name, 0, p.id, uv[0], uv[1]))
    obs = pd.DataFrame(rows, columns=["camera", "frame", "id", "u_px", "v_px"])
    truth = mem.set_index("id")[["x_mm", "y_mm", "z_mm"]]

    def radial_errors(points: pd.DataFrame) -> np.ndarray:
        got = points.set_index("id").loc[truth.index, ["x_mm", "y_mm", "z_mm"]].to_numpy()
        err = got - truth.to_numpy()
        return np.hypot(got[:, 0], got[:, 1]) - np.hypot(truth["x_mm"], truth["y_mm"]).to_numpy(), err

    cfg = TriangulationConfig()
    plain = triangulate_refracted(cameras, obs, cell, cfg)
    fixed = triangulate_refracted(cameras, obs, cell, cfg, radii)
    dr_plain, _ = radial_errors(plain.points)
    dr_fixed, err = radial_errors(fixed.points)
    assert len(fixed.points) == len(mem)
    assert dr_plain.mean() < -0.002  # towards the axis
    assert np.abs(dr_fixed).max() < 3e-4
    assert np.linalg.norm(err, axis=1).max() < 3e-4


def test_the_cell_fitted_in_air_from_exact_centroids_has_its_printed_radius(design, table, ring):
    """Cell-wall observations at the exact image centroids of their marks (no noise): the bundle
    adjustment's cylinder has the printed radius within 0.5 micrometres with the correction;
    without it, it is 6 micrometres small."""
    cameras, _ = ring
    pts = design_points(design, table)
    wall = pts[(table["surface"] == "cell_outer").to_numpy()]
    radii = mark_radii(design, table)
    rows = []
    for cam in cameras.values():
        xyz = wall[["x_mm", "y_mm", "z_mm"]].to_numpy()
        to_cam = cam.center[None, :2] - xyz[:, :2]
        cos = (to_cam * xyz[:, :2]).sum(axis=1) / np.linalg.norm(to_cam, axis=1) / np.hypot(*xyz[:, :2].T)
        seen = wall[cos > 0.5]
        uv = _dense_centroids(cam, xyz[cos > 0.5], radii[seen["id"]].to_numpy(), None)
        inside = (uv[:, 0] > 5) & (uv[:, 0] < cam.width - 6) & (uv[:, 1] > 5) & (uv[:, 1] < cam.height - 6)
        rows += [(cam.name, 0, i, u, v) for i, (u, v) in zip(seen["id"][inside], uv[inside], strict=True)]
    labels = pd.DataFrame(rows, columns=["camera", "frame", "id", "u_px", "v_px"])
    intrinsics = {n: Camera(n, c.width, c.height, c.K, c.dist, np.eye(3), np.zeros(3))
                  for n, c in cameras.items()}  # fmt: skip
    printed = design.cell.outer_radius
    plain = reconstruct_cell(intrinsics, labels, wall, SfmConfig(), mark_radius_mm=None)
    fixed = reconstruct_cell(intrinsics, labels, wall, SfmConfig(), mark_radius_mm=radii)
    assert plain.cylinder.radius - printed < -0.004  # -6 micrometres, as on the demo
    assert abs(fixed.cylinder.radius - printed) < 0.0005


def test_eccentricity_between_computed_frames_is_interpolated_in_time():
    """Computed at frames 0 and 10: at frame 4, 0.6 of frame 0's plus 0.4 of frame 10's; an
    observation known at one end only takes that value; one known at neither, 0."""
    from triaxtrack.timesteps import _interpolated_eccentricity

    at = {
        0: pd.DataFrame({"camera": ["c1", "c1"], "id": [1, 2], "eu": [0.01, 0.02], "ev": [-0.01, 0.0]}),
        10: pd.DataFrame({"camera": ["c1", "c2"], "id": [1, 1], "eu": [0.03, 0.05], "ev": [0.01, 0.0]}),
    }
    obs = pd.DataFrame({"camera": ["c1", "c1", "c2", "c2"], "id": [1, 2, 1, 3]})
    got = _interpolated_eccentricity(at, 4, obs)
    np.testing.assert_allclose(got, [[0.018, -0.002], [0.02, 0.0], [0.05, 0.0], [0.0, 0.0]], atol=1e-12)
    np.testing.assert_allclose(_interpolated_eccentricity(at, 12, obs)[0], [0.03, 0.01])
