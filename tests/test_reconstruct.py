"""Cameras and cell by SfM (triaxtrack.sfm), specimen by refractive ray tracing
(triaxtrack.triangulate), against a synthetic scene: the default ring of 13 cameras, the kit's
targets projected exactly (air for the cell wall, Snell's law through both walls for the rest)
plus Gaussian pixel noise. No rendering: these test the geometry, not the detection.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pandas as pd
import pytest

from triaxtrack.cell_frame import axis_frame, fit_cylinder, similarity_transform, transform_points
from triaxtrack.influence import CODEC_SHIFT_COLUMNS
from triaxtrack.kit import design_points
from triaxtrack.optics import Camera, cell_optics, project_air, project_water
from triaxtrack.refractive_pose import PoseObservations, image_spread_px, min_spread_px, pose_camera
from triaxtrack.score_cameras import rotation_angle_deg
from triaxtrack.sfm import SfmConfig, bundle_adjust, cell_summary, design_f_statistic, reconstruct_cell
from triaxtrack.simulate import SimulationConfig, make_cameras
from triaxtrack.triangulate import (
    TriangulationConfig,
    intersect_rays,
    pedestal_frame,
    reconstruct_specimen,
    refine_cell,
    triangulate_refracted,
    water_rays,
)

NOISE_PX = 0.05  # about the centroid error of the identification stage
MIN_VIEW_COS = 0.3  # a target is seen when its normal is within ~73 degrees of the view


def _observations(cameras, points: pd.DataFrame, table: pd.DataFrame, cell, rng) -> pd.DataFrame:
    """Noisy labels ``camera, frame, id, u_px, v_px`` of every target facing each camera (the
    direction to the camera in air, or of the refracted ray in water) and inside its image."""
    xyz = points[["x_mm", "y_mm", "z_mm"]].to_numpy()
    normal = np.c_[xyz[:, :2], np.zeros(len(xyz))]
    normal /= np.linalg.norm(normal, axis=1)[:, None]
    air = (table["surface"] == "cell_outer").to_numpy()
    rows = []
    for cam in cameras:
        uv = np.full((len(xyz), 2), np.nan)
        view = np.full((len(xyz), 3), np.nan)
        uv[air] = project_air(cam, xyz[air])
        view[air] = cam.center - xyz[air]
        uv[~air], d, _ = project_water(cam, xyz[~air], cell)
        view[~air] = -d
        cos = (normal * view).sum(axis=1) / np.linalg.norm(view, axis=1)
        inside = (uv[:, 0] > 5) & (uv[:, 0] < cam.width - 6) & (uv[:, 1] > 5) & (uv[:, 1] < cam.height - 6)
        seen = (cos > MIN_VIEW_COS) & inside
        noisy = uv[seen] + rng.normal(0, NOISE_PX, (seen.sum(), 2))
        rows.append(pd.DataFrame({"camera": cam.name, "frame": 0, "id": points["id"][seen].to_numpy(),
                                  "u_px": noisy[:, 0], "v_px": noisy[:, 1]}))  # fmt: skip
    return pd.concat(rows, ignore_index=True)


@pytest.fixture(scope="module")
def scene(design, table):
    """Cameras, design points (the truth: nothing deformed), the cell and noisy labels."""
    cameras = make_cameras(SimulationConfig())
    points = design_points(design, table)
    cell = cell_optics(design)
    labels = _observations(cameras, points, table, cell, np.random.default_rng(7))
    intrinsics = {
        c.name: Camera(c.name, c.width, c.height, c.K, c.dist, np.eye(3), np.zeros(3)) for c in cameras
    }
    return {"cameras": {c.name: c for c in cameras}, "intrinsics": intrinsics, "points": points,
            "cell": cell, "labels": labels, "table": table}  # fmt: skip


@pytest.fixture(scope="module")
def cell_rec(scene):
    table = scene["table"]
    wall = scene["points"][(table["surface"] == "cell_outer").to_numpy()]
    return reconstruct_cell(scene["intrinsics"], scene["labels"], wall, SfmConfig())


def _rms(points: pd.DataFrame, truth: pd.DataFrame, ids) -> float:
    got = points.set_index("id").loc[ids, ["x_mm", "y_mm", "z_mm"]].to_numpy()
    want = truth.set_index("id").loc[ids, ["x_mm", "y_mm", "z_mm"]].to_numpy()
    return float(np.sqrt(((got - want) ** 2).sum(axis=1).mean()))


# ---------------------------------------------------------------- geometry helpers


def test_camera_transformed_keeps_every_image(scene):
    cam = scene["cameras"]["cam01"]
    pts = scene["points"][["x_mm", "y_mm", "z_mm"]].to_numpy()[:400:7] * [1, 1, 1]
    A = np.linalg.qr(np.random.default_rng(1).normal(size=(3, 3)))[0]
    A *= np.linalg.det(A)
    s, b = 1.7, np.array([3.0, -2.0, 40.0])
    moved = cam.transformed(s, A, b)
    np.testing.assert_allclose(project_air(moved, s * pts @ A.T + b), project_air(cam, pts), atol=1e-8)


def test_similarity_transform_recovers_scale_rotation_shift():
    rng = np.random.default_rng(2)
    src = rng.normal(size=(50, 3)) * 40
    A = np.linalg.qr(rng.normal(size=(3, 3)))[0]
    A *= np.linalg.det(A)
    s, A2, b = similarity_transform(src, 0.98 * src @ A.T + [1.0, 2.0, 3.0])
    assert s == pytest.approx(0.98, abs=1e-12)
    np.testing.assert_allclose(A2, A, atol=1e-12)
    np.testing.assert_allclose(b, [1.0, 2.0, 3.0], atol=1e-10)


def test_fit_cylinder_and_axis_frame_recover_a_tilted_offset_cylinder():
    rng = np.random.default_rng(3)
    th, z = rng.uniform(0, 2 * np.pi, 400), rng.uniform(-40, 190, 400)
    pts = np.c_[77 * np.cos(th), 77 * np.sin(th), z] + rng.normal(0, 0.01, (400, 3))
    tilt = np.deg2rad(0.4)
    R = np.array([[1, 0, 0], [0, np.cos(tilt), -np.sin(tilt)], [0, np.sin(tilt), np.cos(tilt)]])
    moved = pts @ R.T + [0.8, -0.5, 2.0]
    cyl = fit_cylinder(moved)
    assert cyl.radius == pytest.approx(77.0, abs=0.005)
    assert np.degrees(np.arccos(abs(cyl.direction[2]))) == pytest.approx(0.4, abs=0.005)
    A, b = axis_frame(cyl)
    back = moved @ A.T + b
    np.testing.assert_allclose(np.hypot(back[:, 0], back[:, 1]), 77.0, atol=0.05)


def test_intersect_rays_is_exact_for_rays_through_points():
    rng = np.random.default_rng(4)
    pts = rng.normal(size=(20, 3)) * 30
    group = np.repeat(np.arange(20), 4)
    dirs = rng.normal(size=(80, 3))
    dirs /= np.linalg.norm(dirs, axis=1)[:, None]
    origins = pts[group] - rng.uniform(10, 100, (80, 1)) * dirs
    np.testing.assert_allclose(intersect_rays(origins, dirs, group, 20), pts, atol=1e-9)


# ---------------------------------------------------------------- cameras and cell


def test_bundle_adjustment_recovers_perturbed_poses(scene):
    """pycolmap's adjustment from poses off by ~1 degree and ~5 mm, points held at the design by
    many observations, comes back to the true poses (up to the gauge, fixed here by the
    similarity to the design)."""
    table, labels = scene["table"], scene["labels"]
    wall = scene["points"][(table["surface"] == "cell_outer").to_numpy()]
    obs = labels[labels["id"].isin(wall["id"])]
    rng = np.random.default_rng(5)
    start = {}
    for name, cam in scene["cameras"].items():
        rot = np.linalg.qr(np.eye(3) + rng.normal(0, 0.015, (3, 3)))[0]
        rot *= np.sign(np.diag(rot))[None, :]
        start[name] = Camera(
            name, cam.width, cam.height, cam.K, cam.dist, rot @ cam.R, cam.t + rng.normal(0, 5, 3)
        )
    cams, pts = bundle_adjust(start, obs, wall[wall["id"].isin(obs["id"])], refine_intrinsics=False)
    s, A, b = similarity_transform(
        pts[["x_mm", "y_mm", "z_mm"]].to_numpy(), wall.set_index("id").loc[pts["id"]].to_numpy()
    )
    for name, cam in cams.items():
        moved = cam.transformed(s, A, b)
        assert np.linalg.norm(moved.center - scene["cameras"][name].center) < 0.3
        assert rotation_angle_deg(moved.R, scene["cameras"][name].R) < 0.03


def test_cameras_within_half_a_millimetre_and_005_degrees(scene, cell_rec):
    assert not cell_rec.dropped
    assert cell_rec.cylinder.radius == pytest.approx(scene["cell"].outer_radius, abs=0.01)
    used = cell_rec.residuals[cell_rec.residuals["used"]]
    assert np.hypot(used["du_px"], used["dv_px"]).mean() < 2 * NOISE_PX
    for name, cam in cell_rec.cameras.items():
        truth = scene["cameras"][name]
        assert np.linalg.norm(cam.center - truth.center) < 0.5, name
        assert rotation_angle_deg(cam.R, truth.R) < 0.05, name


def test_the_printed_cell_is_held_when_the_images_cannot_tell_it_from_the_adjusted_one(scene, cell_rec):
    """Exact design, 0.05 px of noise: the F statistic is near 1, the wall targets stay at their
    printed positions and the cameras come closer to the truth than with the targets adjusted
    freely (which carry the image noise into the poses)."""
    table = scene["table"]
    wall = scene["points"][(table["surface"] == "cell_outer").to_numpy()]
    assert cell_rec.wall_targets == "design" and 0.8 < cell_rec.design_f < 1.25
    assert cell_summary(cell_rec)["cell"]["wall_targets"] == "design"
    got = cell_rec.points.set_index("id").loc[:, ["x_mm", "y_mm", "z_mm"]]
    np.testing.assert_allclose(np.hypot(got["x_mm"], got["y_mm"]), scene["cell"].outer_radius, atol=1e-6)
    free = reconstruct_cell(scene["intrinsics"], scene["labels"], wall, SfmConfig(design_f_max=None))
    assert free.wall_targets == "adjusted" and np.isnan(free.design_f)

    def centre_error(rec):
        return np.mean(
            [np.linalg.norm(c.center - scene["cameras"][n].center) for n, c in rec.cameras.items()]
        )

    assert centre_error(cell_rec) < 0.8 * centre_error(free)


@pytest.mark.parametrize("misprint", ["height", "scatter"])
def test_a_misprinted_cell_is_adjusted_freely(scene, misprint):
    """A kit printed 0.1 % too tall, or with 0.03 mm of scatter, is not the cell the images see:
    the F statistic is large and the targets are adjusted; the cameras stay within tolerance."""
    table = scene["table"]
    wall = scene["points"][(table["surface"] == "cell_outer").to_numpy()].copy()
    z = wall["z_mm"].to_numpy()
    if misprint == "height":
        wall["z_mm"] = z.mean() + (z - z.mean()) * 1.001
    else:
        rng = np.random.default_rng(11)
        wall["z_mm"] = z + rng.normal(0, 0.03, len(z))
    rec = reconstruct_cell(scene["intrinsics"], scene["labels"], wall, SfmConfig())
    assert rec.wall_targets == "adjusted" and rec.design_f > 3
    for name, cam in rec.cameras.items():
        assert np.linalg.norm(cam.center - scene["cameras"][name].center) < 0.5, name


def test_design_f_statistic():
    # 989 observations, 13 cameras, 300 points: 1978 - 78 - 900 = 1000 degrees of freedom left to the free fit
    assert design_f_statistic(1000.0, 1900.0, 989, 300, 13) == pytest.approx(1.0)
    assert design_f_statistic(1000.0, 3700.0, 989, 300, 13) == pytest.approx(3.0)
    assert np.isnan(design_f_statistic(1000.0, 1900.0, 200, 100, 10))  # dof 40 - 300 < 0: cannot tell
    assert np.isnan(design_f_statistic(0.0, 1.0, 1000, 300, 13))


def test_a_wrong_label_is_dropped_with_its_reason(scene):
    table, labels = scene["table"], scene["labels"]
    wall = scene["points"][(table["surface"] == "cell_outer").to_numpy()]
    bad = labels.copy()
    row = bad.index[(bad["camera"] == "cam03") & bad["id"].isin(wall["id"])][10]
    bad.loc[row, "u_px"] += 6.0
    rec = reconstruct_cell(scene["intrinsics"], bad, wall, SfmConfig())
    res = rec.residuals.set_index(["camera", "id"])
    flagged = res.loc[(bad.loc[row, "camera"], bad.loc[row, "id"])]
    assert not flagged["used"] and flagged["reason"] != ""
    assert res["used"].sum() >= len(res) - 3


def test_too_few_cameras_is_an_error_naming_them(scene):
    table = scene["table"]
    wall = scene["points"][(table["surface"] == "cell_outer").to_numpy()]
    one = scene["labels"][scene["labels"]["camera"] == "cam01"]
    with pytest.raises(ValueError, match="only 1 camera"):
        reconstruct_cell(scene["intrinsics"], one, wall, SfmConfig())


# ---------------------------------------------------------------- specimen


def _water(scene):
    table = scene["table"]
    in_water = table.loc[table["surface"] != "cell_outer", "id"].to_numpy()
    return scene["labels"][scene["labels"]["id"].isin(in_water)]


def test_membrane_within_005_mm_and_90_percent_from_3_rays(scene, cell_rec):
    table = scene["table"]
    bottom = scene["points"][(table["surface"] == "pedestal_bottom").to_numpy()]
    in_water = table.loc[table["surface"] != "cell_outer", "id"].to_numpy()
    rec = reconstruct_specimen(
        cell_rec.cameras, cell_rec.points, cell_rec.residuals, scene["labels"], in_water, bottom,
        replace(scene["cell"], outer_radius=cell_rec.cylinder.radius,
                inner_radius=cell_rec.cylinder.radius - 12.0),
        1e-3, TriangulationConfig(), 0, 0.0,
    )  # fmt: skip
    membrane = table.loc[table["surface"] == "membrane", "id"].to_numpy()
    got = rec.points[rec.points["id"].isin(membrane)]
    assert (got["n_rays"] >= 3).sum() >= 0.9 * len(membrane)
    assert _rms(rec.points, scene["points"], got["id"]) < 0.05
    assert abs(rec.frame_fix["rotation_deg"]) < 0.01 and rec.frame_fix["pedestal_cts"] == 16
    used = rec.residuals[rec.residuals["used"]]
    assert np.hypot(used["du_px"], used["dv_px"]).mean() < 0.1
    # the reported uncertainty is of the size of the actual error
    assert 0.3 < got["sigma_mm"].median() / _rms(rec.points, scene["points"], got["id"]) < 3


def test_without_refraction_the_points_are_millimetres_off(scene):
    """The same rays taken straight (every index 1) put the membrane millimetres away."""
    obs = _water(scene)
    straight = replace(scene["cell"], n_acrylic=1.0, n_water=1.0)
    cams = scene["cameras"]
    refracted = triangulate_refracted(cams, obs, scene["cell"], TriangulationConfig())
    naive = triangulate_refracted(cams, obs, straight, TriangulationConfig(max_residual_px=1e9))
    ids = np.intersect1d(refracted.points["id"], naive.points["id"])
    ids = ids[ids > 1000]
    assert _rms(refracted.points, scene["points"], ids) < 0.05
    assert _rms(naive.points, scene["points"], ids) > 2.0


def test_pedestal_frame_recovers_a_rotated_and_lifted_cell(scene):
    table = scene["table"]
    bottom = scene["points"][(table["surface"] == "pedestal_bottom").to_numpy()]
    c, s = np.cos(np.deg2rad(3.0)), np.sin(np.deg2rad(3.0))
    turned = transform_points(bottom, 1.0, np.array([[c, -s, 0], [s, c, 0], [0, 0, 1.0]]), [0, 0, 1.5])
    A, b, n = pedestal_frame(turned, bottom)
    back = transform_points(turned, 1.0, A, b)
    assert n == 16
    np.testing.assert_allclose(back[["x_mm", "y_mm", "z_mm"]], bottom[["x_mm", "y_mm", "z_mm"]], atol=1e-9)


def test_refining_the_cell_recovers_from_a_wrong_water_index(scene):
    """Triangulated with n_water 1.340 and a 12.3 mm wall, the membrane is off by ~0.1 mm; the
    refractive bundle adjustment lowers the reprojection error and the 3-D error."""
    obs = _water(scene)
    cams = scene["cameras"]
    wrong = replace(scene["cell"], inner_radius=scene["cell"].outer_radius - 12.3, n_water=1.340)
    cfg = TriangulationConfig(refine_cell_points=200)
    before = triangulate_refracted(cams, obs, wrong, cfg)
    fit = refine_cell(cams, before.residuals, wrong, cfg, outer_radius_sigma_mm=1e-3)
    after = triangulate_refracted(cams, obs, fit.cell, cfg)
    ids = np.intersect1d(before.points["id"], after.points["id"])
    ids = ids[ids > 1000]
    assert fit.rms_after_px < fit.rms_before_px
    assert _rms(after.points, scene["points"], ids) < 0.5 * _rms(before.points, scene["points"], ids)


def test_water_rays_of_a_missing_pixel_are_nan(scene):
    cam = scene["cameras"]["cam01"]
    origins, dirs = water_rays(cam, np.array([[5.0, 5.0], [cam.K[0, 2], cam.K[1, 2]]]), scene["cell"])
    assert np.isnan(dirs[0]).all() and np.isfinite(dirs[1]).all()


def test_a_wrong_water_label_is_dropped_and_only_its_point_moves(scene):
    obs = _water(scene).reset_index(drop=True)
    cams, cfg = scene["cameras"], TriangulationConfig()
    clean = triangulate_refracted(cams, obs, scene["cell"], cfg).points.set_index("id")
    bad = obs.copy()
    row = bad.index[bad["id"] == 2000][0]
    bad.loc[row, "v_px"] += 4.0
    got = triangulate_refracted(cams, bad, scene["cell"], cfg)
    res = got.residuals
    assert not res.loc[row, "used"] and res.loc[row, "reason"].startswith("residual above")
    assert res["used"].sum() == len(res) - 1
    pts = got.points.set_index("id")
    assert (
        np.linalg.norm(pts.loc[2000, ["x_mm", "y_mm", "z_mm"]] - scene["points"].set_index("id").loc[2000])
        < 0.1
    )
    others = pts.index[pts.index != 2000]
    np.testing.assert_allclose(
        pts.loc[others, ["x_mm", "y_mm", "z_mm"]], clean.loc[others, ["x_mm", "y_mm", "z_mm"]]
    )


def test_the_codec_shifts_are_the_points_moves_when_every_camera_errs_alike(scene):
    """An error of every observation alike (the codec correction's, ``codec_u_px, codec_v_px``)
    moves each point by the sum of its rays' pulls: the points' ``codec_*_mm`` match triangulating
    again with every observation moved by it (to 2 % of the shift, the projection being nearly
    linear over 0.05 px); without the columns the points have none."""
    obs = _water(scene).reset_index(drop=True)
    cams, cfg = scene["cameras"], TriangulationConfig()
    rng = np.random.default_rng(5)
    codec = rng.uniform(0.02, 0.05, (len(obs), 2)) * (obs["id"].to_numpy() < 1000)[:, None]
    given = obs.assign(codec_u_px=codec[:, 0], codec_v_px=codec[:, 1])
    got = triangulate_refracted(cams, given, scene["cell"], cfg)
    assert "codec_u_px" not in got.residuals.columns
    pts = got.points.set_index("id")
    for axis, cols in (("u_px", CODEC_SHIFT_COLUMNS[:3]), ("v_px", CODEC_SHIFT_COLUMNS[3:])):
        moved = obs.assign(**{axis: obs[axis] + codec[:, 0 if axis == "u_px" else 1]})
        again = triangulate_refracted(cams, moved, scene["cell"], cfg).points.set_index("id")
        ids = pts.index[pts.index < 1000]  # the pedestals' targets
        xyz = ["x_mm", "y_mm", "z_mm"]
        shift = again.loc[ids, xyz].to_numpy() - pts.loc[ids, xyz].to_numpy()
        predicted = pts.loc[ids, list(cols)].to_numpy()
        assert np.abs(shift).max() > 1e-3  # a shift to see
        np.testing.assert_allclose(predicted, shift, atol=0.02 * np.abs(shift).max())
        assert (pts.loc[pts.index >= 1000, list(cols)].to_numpy() == 0).all()  # no error given there
    plain = triangulate_refracted(cams, obs, scene["cell"], cfg).points
    assert not set(CODEC_SHIFT_COLUMNS) & set(plain.columns)


# ---------------------------------------------------------------- cameras posed through the wall


def _wall_and_water(scene):
    """The design of the cell-wall targets and of the targets in the water (with their kind)."""
    table, points = scene["table"], scene["points"]
    wall = (table["surface"] == "cell_outer").to_numpy()
    return points[wall], points[~wall].assign(kind=table.loc[~wall, "surface"].to_numpy())


def _check_poses(rec, truth: dict) -> None:
    for name, cam in rec.cameras.items():
        assert np.linalg.norm(cam.center - truth[name].center) < 0.5, name
        assert rotation_angle_deg(cam.R, truth[name].R) < 0.05, name


def test_a_camera_without_wall_targets_is_posed_through_the_wall(scene):
    wall, water = _wall_and_water(scene)
    labels = scene["labels"]
    labels = labels[~((labels["camera"] == "cam05") & labels["id"].isin(wall["id"]))]
    rec = reconstruct_cell(scene["intrinsics"], labels, wall, SfmConfig(), water=water, cell=scene["cell"])
    assert not rec.dropped and not rec.nominal and len(rec.cameras) == len(scene["cameras"])
    assert rec.posed_from["cam05"]["pose_from"] == "water"
    assert rec.posed_from["cam05"]["rms_px"] < 2 * NOISE_PX
    assert rec.posed_from["cam04"]["pose_from"] == "cell_wall"
    _check_poses(rec, scene["cameras"])


def test_a_wall_fit_unlike_the_printed_cell_poses_every_camera_through_it(scene, cell_rec, monkeypatch):
    """The cameras posed in air agree on a cell unlike the printed one (as at a close, low ring
    where each sees a short arc of one band: scale 0.964, axis tilted 10.9 degrees): it is not
    trusted, and every camera is posed through the wall against the kit's cell."""
    import triaxtrack.sfm as sfm

    assert sfm.is_printed_cell(cell_rec)
    broken = replace(cell_rec, scale=0.964, axis_tilt_deg=10.9)
    assert not sfm.is_printed_cell(broken)
    monkeypatch.setattr(sfm, "_air_reconstruction", lambda *args: broken)
    wall, water = _wall_and_water(scene)
    cell = scene["cell"]
    rec = reconstruct_cell(scene["intrinsics"], scene["labels"], wall, SfmConfig(), water=water, cell=cell)
    assert rec.nominal and {v["pose_from"] for v in rec.posed_from.values()} == {"water"}
    _check_poses(rec, scene["cameras"])


def test_a_camera_the_bundle_adjustment_leaves_with_too_few_targets_is_posed_through_the_wall(
    scene, cell_rec, monkeypatch
):
    """The bundle adjustment drops so many of a camera's wall observations that fewer than
    min_targets are left: the camera is not lost but posed through the wall."""
    import triaxtrack.sfm as sfm

    short = replace(cell_rec, cameras={n: c for n, c in cell_rec.cameras.items() if n != "cam05"})
    monkeypatch.setattr(sfm, "_air_reconstruction", lambda *args: short)
    wall, water = _wall_and_water(scene)
    cell = scene["cell"]
    rec = reconstruct_cell(scene["intrinsics"], scene["labels"], wall, SfmConfig(), water=water, cell=cell)
    assert not rec.dropped and len(rec.cameras) == len(scene["cameras"])
    assert rec.posed_from["cam05"]["pose_from"] == "water"
    _check_poses(rec, scene["cameras"])


def test_a_camera_left_with_too_few_targets_takes_no_orphan_into_the_bundle(scene):
    """cam05 labels exactly min_targets wall targets: one of them no other camera sees, and one
    only cam04 also sees. The first is dropped (seen by one camera), which leaves cam05 too few;
    the second is then seen by cam04 alone and is dropped too, rather than entering the bundle
    adjustment with one observation (pycolmap: 'Check failed: point3D.track.Length() > 1')."""
    wall, water = _wall_and_water(scene)
    labels, cfg = scene["labels"], SfmConfig()
    on_wall = labels["id"].isin(wall["id"])
    seen = labels.loc[on_wall].groupby("id")["camera"].agg(set)
    ids = seen[seen.map(lambda c: {"cam04", "cam05"} <= c)].index[: cfg.min_targets].to_numpy()
    lone, pair = ids[0], ids[1]
    keep = ~on_wall | (labels["camera"] != "cam05") | labels["id"].isin(ids)
    keep &= ~(labels["id"].eq(lone) & labels["camera"].ne("cam05"))
    keep &= ~(labels["id"].eq(pair) & ~labels["camera"].isin(["cam04", "cam05"]))
    cell = scene["cell"]
    rec = reconstruct_cell(scene["intrinsics"], labels[keep], wall, SfmConfig(), water=water, cell=cell)
    assert rec.posed_from["cam05"]["pose_from"] == "water" and not rec.dropped
    res = rec.residuals.set_index(["camera", "id"])
    assert not res.loc[("cam04", pair), "used"] and res.loc[("cam04", pair), "reason"] == "seen by one camera"
    _check_poses(rec, scene["cameras"])


def test_cameras_that_share_too_few_wall_targets_are_posed_through_it(scene):
    """Two cameras each pose from their own strip of the wall, with no target in common (close
    cameras far apart): no bundle to adjust, so every camera is posed through the wall against
    the nominal cell (it raised LinAlgError from an empty similarity transform)."""
    wall, water = _wall_and_water(scene)
    labels = scene["labels"]
    on_wall = labels["id"].isin(wall["id"])
    first = labels.loc[on_wall & (labels["camera"] == "cam01"), "id"]
    second = (labels["camera"] == "cam02") & ~labels["id"].isin(first)
    keep = ~on_wall | (labels["camera"] == "cam01") | second
    cell = scene["cell"]
    rec = reconstruct_cell(scene["intrinsics"], labels[keep], wall, SfmConfig(), water=water, cell=cell)
    assert rec.nominal and not rec.dropped and len(rec.cameras) == len(scene["cameras"])
    assert {v["pose_from"] for v in rec.posed_from.values()} == {"water"}
    _check_poses(rec, scene["cameras"])


@pytest.fixture(scope="module")
def close_ring(design, table):
    """Three cameras of a closer ring (radius 300 mm) that label no cell-wall target at all."""
    cfg = SimulationConfig(
        cameras=13, camera_radius_mm=300.0, focal_factor=0.677, camera_height_mm=71.0, seed=5
    )
    cameras = make_cameras(cfg)[:3]
    points = design_points(design, table)
    cell = cell_optics(design)
    labels = _observations(cameras, points, table, cell, np.random.default_rng(11))
    wall = table.loc[table["surface"] == "cell_outer", "id"]
    intrinsics = {
        c.name: Camera(c.name, c.width, c.height, c.K, c.dist, np.eye(3), np.zeros(3)) for c in cameras
    }
    return {"cameras": {c.name: c for c in cameras}, "intrinsics": intrinsics, "points": points, "cell": cell,
            "labels": labels[~labels["id"].isin(wall)], "table": table}  # fmt: skip


def test_no_camera_sees_the_wall_the_nominal_cell_poses_them(close_ring):
    wall, water = _wall_and_water(close_ring)
    rec = reconstruct_cell(
        close_ring["intrinsics"],
        close_ring["labels"],
        wall,
        SfmConfig(),
        water=water,
        cell=close_ring["cell"],
    )
    assert rec.nominal and not rec.dropped and len(rec.cameras) == 3
    assert {v["pose_from"] for v in rec.posed_from.values()} == {"water"}
    assert rec.cylinder.radius == close_ring["cell"].outer_radius
    _check_poses(rec, close_ring["cameras"])
    summary = cell_summary(rec)
    assert summary["cell"]["source"] == "nominal" and summary["cameras_posed"]["cam01"]["targets"] >= 12


def test_a_camera_that_cannot_be_posed_is_left_out_with_the_reason(close_ring):
    wall, water = _wall_and_water(close_ring)
    labels = close_ring["labels"]
    few = labels[(labels["camera"] != "cam03") | labels["id"].isin(labels["id"].unique()[:5])]
    rec = reconstruct_cell(
        close_ring["intrinsics"], few, wall, SfmConfig(), water=water, cell=close_ring["cell"]
    )
    assert sorted(rec.cameras) == ["cam01", "cam02"]
    assert "fewer than 12" in rec.dropped["cam03"]
    _check_poses(rec, close_ring["cameras"])


def test_fewer_than_two_posed_is_an_error_naming_each_camera_and_its_labels(close_ring):
    wall, water = _wall_and_water(close_ring)
    labels = close_ring["labels"]
    bottom = water.loc[water["kind"] == "pedestal_bottom", "id"]
    some = labels[(labels["camera"] == "cam01") | ((labels["camera"] == "cam02") & labels["id"].isin(bottom))]
    with pytest.raises(ValueError, match="only 1 camera") as err:
        reconstruct_cell(
            close_ring["intrinsics"], some, wall, SfmConfig(), water=water, cell=close_ring["cell"]
        )
    message = str(err.value)
    assert "cam02: 0 cell-wall" in message and "pedestal_bottom" in message and "cam03: nothing" in message


def test_clumped_targets_do_not_pose_a_camera(close_ring):
    cam = close_ring["cameras"]["cam01"]
    assert image_spread_px(np.c_[np.linspace(0, 600, 20), np.full(20, 300.0)]) < min_spread_px(cam)
    labels = close_ring["labels"]
    obs = labels[labels["camera"] == "cam01"]
    uv = obs[["u_px", "v_px"]].to_numpy()
    # a clump of ~46 targets 80 px across: enough of them, too little spread (40 px radius)
    near = obs[np.hypot(*(uv - uv.mean(axis=0)).T) < 40]
    xyz = close_ring["points"].set_index("id").loc[near["id"], ["x_mm", "y_mm", "z_mm"]].to_numpy()
    seen = PoseObservations(
        near["id"].to_numpy(), xyz, near[["u_px", "v_px"]].to_numpy(), np.ones(len(near), bool)
    )
    assert len(near) >= 12
    out = pose_camera(close_ring["intrinsics"]["cam01"], seen, close_ring["cell"], 12, 2.0)
    assert isinstance(out, str) and "not well spread" in out, out
