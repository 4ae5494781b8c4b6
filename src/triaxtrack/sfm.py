"""Cameras and cell in air: structure from motion on the labelled cell-wall targets.

The paper's section 2.3 (last part) and 3.1. The target IDs are the correspondences, so there is
no feature matching:

1. each camera's pose by PnP (RANSAC, then Levenberg-Marquardt) against the kit's design
   coordinates of the cell-wall targets it labelled (:func:`initial_poses`);
2. one bundle adjustment with pycolmap over every camera and every cell-wall target seen by two
   or more cameras, the intrinsics fixed from calibration unless ``refine_intrinsics``
   (:func:`bundle_adjust`); observations whose residual exceeds ``max_residual_px`` are
   dropped and the adjustment is run again;
3. the scale and the frame from the design: the similarity that best maps the adjusted targets
   onto their design positions (:func:`~triaxtrack.cell_frame.similarity_transform`); unless the
   images cannot tell the printed cell from the adjusted one: the cameras are then adjusted once
   more to the targets held at their printed positions, and where the F statistic of that
   against the free adjustment is at most ``design_f_max`` (:func:`design_f_statistic`: 0.9-1.2
   when the print is exact, 7 for a kit printed 0.05 % too tall, 9 for 0.02 mm of scatter, at
   1080p), those cameras and positions are kept (``wall_targets`` 'design'): the free
   adjustment carries the image noise of a few rays per target into the poses (at 720p it put
   the cell 0.06 % off scale and the membrane 0.13 mm off);
4. the cell's outer cylinder fitted to the 3-D targets
   (:func:`~triaxtrack.cell_frame.fit_cylinder`), and every camera and point moved so that its
   axis is the z axis (:func:`~triaxtrack.cell_frame.axis_frame`): the frame in which
   :mod:`triaxtrack.optics` traces rays through the wall.

A camera that labels too few cell-wall targets is posed from the targets in the water instead
(pedestal CTs, membrane dots at their design positions: the specimen is undeformed at the
reference frame), through the cell wall, by :mod:`triaxtrack.refractive_pose`: against the
fitted cell when two or more cameras were posed in air, otherwise against the nominal cell of
the kit (radii and indices of ``kit.json``, axis on the pedestals' axis, as a lab centres it),
in the design frame. Each camera says how it was posed (``pose_from``: ``cell_wall`` or
``water``); a camera that cannot be posed is left out with the reason; fewer than two posed
cameras is an error naming every camera and what it labelled.

The rotation about the axis and the height of the origin are fixed later, from the bottom
pedestal's coded targets (:func:`triaxtrack.triangulate.pedestal_frame`), as ``target-kit.md``
defines the cell frame. Units: millimetres, pixels in OpenCV convention (the centre of the
top-left pixel is (0, 0)); pycolmap's convention (pixel centres at +0.5) is converted on the
way in and out.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np
import pandas as pd

from triaxtrack.cell_frame import Cylinder, axis_frame, fit_cylinder, similarity_transform, transform_points
from triaxtrack.eccentricity import observation_eccentricity
from triaxtrack.optics import Camera, CellOptics, project_air
from triaxtrack.reconstruction_config import SfmConfig
from triaxtrack.refractive_pose import PoseObservations, pnp_pose, pose_camera

COLMAP_PIXEL_OFFSET = 0.5  # COLMAP puts the centre of the top-left pixel at (0.5, 0.5)
FULL_OPENCV_DIST = 8  # k1 k2 p1 p2 k3 k4 k5 k6: COLMAP's FULL_OPENCV holds both OpenCV models
MAX_BA_ROUNDS = 4  # bundle adjustments, each after dropping the observations above the limit
REFERENCE_FRAME = 0  # the frame whose water targets are at their design positions (undeformed specimen)
# A cell fitted in air is trusted only if it is the printed cell: its scale against the design
# within MAX_SCALE_ERROR and its axis within MAX_AXIS_TILT_DEG of the design's (a sound fit: 1e-4
# and 0.02 deg). Cameras that each see a short arc of one band (a close, low ring) can agree on a
# wrong one (at a 260 mm ring: scale 0.964, tilt 10.9 deg); the cameras are then posed through
# the wall against the kit's cell
MAX_SCALE_ERROR = 0.01
MAX_AXIS_TILT_DEG = 1.0
# The F test of the printed cell against the adjusted one needs the free adjustment to have at
# least this many degrees of freedom (2 per observation less 6 per camera and 3 per target): with
# fewer it cannot tell them apart, and the targets are adjusted freely
MIN_DESIGN_DOF = 100
NOMINAL_RADIUS_SIGMA_MM = 0.5  # standard error of a nominal outer radius (tube tolerance), the
# prior of triaxtrack.triangulate.refine_cell when the radius was not fitted in air


@dataclass(frozen=True)
class CellReconstruction:
    """The cameras and the cell wall in the axis frame (cell axis = z axis, scale and +z from
    the design; rotation about z and height of the origin still those of the printed cell)."""

    cameras: dict[str, Camera]
    points: pd.DataFrame  # id, x_mm, y_mm, z_mm, n_rays, rms_px
    residuals: pd.DataFrame  # camera, frame, id, u_px, v_px, du_px, dv_px, used, reason
    cylinder: Cylinder  # in the axis frame: point (0, 0, 0), direction (0, 0, 1)
    axis_tilt_deg: float  # angle of the fitted axis from the design's z axis
    scale: float  # design scale over the adjusted model's (1 when the design is exact)
    dropped: dict[str, str]  # camera -> why it was left out
    posed_from: dict[str, dict] = field(default_factory=dict)  # camera -> pose_from, targets, rms_px
    nominal: bool = False  # True: no camera saw enough of the wall; the cell is the kit's design
    wall_targets: str = "adjusted"  # 'design': held at the printed positions (the F test), or 'adjusted'
    design_f: float = float("nan")  # the F statistic of the printed positions against the adjusted ones


def earliest_observations(labels: pd.DataFrame, ids: np.ndarray, min_targets: int = 1) -> pd.DataFrame:
    """Per camera, its labelled rows of targets ``ids`` at the earliest frame where it has at
    least ``min_targets`` of them (the cell does not move: any frame gives the camera's pose).
    ``labels``: rows ``camera, frame, id, u_px, v_px`` (id -1, unlabelled, ignored)."""
    lab = labels[labels["id"].isin(ids)]
    counts = lab.groupby(["camera", "frame"]).size()
    counts = counts[counts >= min_targets].reset_index()
    first = counts.groupby("camera")["frame"].min()
    keep = lab["frame"].to_numpy() == lab["camera"].map(first).to_numpy()
    return lab[keep].reset_index(drop=True)


def initial_poses(
    cameras: dict[str, Camera], observations: pd.DataFrame, design: pd.DataFrame, cfg: SfmConfig
) -> tuple[dict[str, Camera], pd.DataFrame, dict[str, str]]:
    """Each camera's pose by PnP against the design positions of the targets it labelled.

    ``cameras``: calibrated intrinsics (pose ignored); ``observations``: rows ``camera, frame,
    id, u_px, v_px``; ``design``: ``id, x_mm, y_mm, z_mm``. Returns the posed cameras, the
    observations with a bool column ``inlier``, and the cameras left out with the reason.
    """
    xyz = design.set_index("id")[["x_mm", "y_mm", "z_mm"]]
    posed, dropped, parts = {}, {}, []
    for name, cam in sorted(cameras.items()):
        obs = observations[observations["camera"] == name]
        if len(obs) < cfg.min_targets:
            dropped[name] = f"{len(obs)} cell-wall targets labelled, fewer than {cfg.min_targets}"
            continue
        X = xyz.loc[obs["id"]].to_numpy(np.float64)
        uv = obs[["u_px", "v_px"]].to_numpy(np.float64)
        pose = pnp_pose(cam, X, uv, cfg.ransac_px)
        inlier = pose[1] if pose is not None else np.zeros(len(obs), bool)
        if pose is None or inlier.sum() < cfg.min_targets:
            dropped[name] = f"PnP found {int(inlier.sum())} consistent cell-wall targets of {len(obs)}"
            continue
        posed[name] = pose[0]
        parts.append(obs.assign(inlier=inlier))
    cols = [*observations.columns, "inlier"]
    out = pd.concat(parts, ignore_index=True) if parts else pd.DataFrame(columns=cols)
    return posed, out, dropped


def _colmap_camera(cam: Camera, camera_id: int):
    import pycolmap

    if len(cam.dist) > FULL_OPENCV_DIST:
        raise ValueError(f"{cam.name}: {len(cam.dist)} distortion coefficients; at most 8 are supported")
    dist = np.zeros(FULL_OPENCV_DIST)
    dist[: len(cam.dist)] = cam.dist
    K = cam.K
    params = [K[0, 0], K[1, 1], K[0, 2] + COLMAP_PIXEL_OFFSET, K[1, 2] + COLMAP_PIXEL_OFFSET, *dist]
    return pycolmap.Camera(
        model="FULL_OPENCV", width=cam.width, height=cam.height, params=params, camera_id=camera_id
    )


def _from_colmap(cam: Camera, colmap_camera, cam_from_world) -> Camera:
    p = np.asarray(colmap_camera.params, float)
    K = np.array([[p[0], 0, p[2] - COLMAP_PIXEL_OFFSET], [0, p[1], p[3] - COLMAP_PIXEL_OFFSET], [0, 0, 1.0]])
    dist = p[4:]
    if not dist[len(cam.dist) :].any():  # the coefficients the calibration had, unless more were refined
        dist = dist[: len(cam.dist)]
    M = np.asarray(cam_from_world.matrix(), float)
    return Camera(cam.name, cam.width, cam.height, K, dist, M[:, :3], M[:, 3])


def bundle_adjust(
    cameras: dict[str, Camera],
    observations: pd.DataFrame,
    points: pd.DataFrame,
    refine_intrinsics: bool,
    hold_points: bool = False,
) -> tuple[dict[str, Camera], pd.DataFrame]:
    """One pycolmap bundle adjustment of camera poses and 3-D points (intrinsics fixed unless
    ``refine_intrinsics``), in the gauge of the starting poses; with ``hold_points`` the points
    stay where they are (constant: the cameras are adjusted to them, in their gauge).

    ``observations``: rows ``camera, id, u_px, v_px`` (distorted pixels, OpenCV convention);
    ``points``: starting ``id, x_mm, y_mm, z_mm`` of every observed id. Returns the adjusted
    cameras and points (same columns). pycolmap's FULL_OPENCV model stands for OpenCV's
    5-coefficient and rational models alike (missing coefficients are zero).
    """
    import pycolmap

    rec = pycolmap.Reconstruction()
    start = points.set_index("id")[["x_mm", "y_mm", "z_mm"]]
    point_ids = {int(i): rec.add_point3D(start.loc[i].to_numpy(float), pycolmap.Track()) for i in start.index}
    image_ids = {}
    for k, (name, cam) in enumerate(sorted(cameras.items()), start=1):
        obs = observations[observations["camera"] == name]
        rec.add_camera_with_trivial_rig(_colmap_camera(cam, k))
        image = pycolmap.Image(
            name=name,
            keypoints=obs[["u_px", "v_px"]].to_numpy(np.float64) + COLMAP_PIXEL_OFFSET,
            camera_id=k,
            image_id=k,
        )
        rec.add_image_with_trivial_frame(image, pycolmap.Rigid3d(pycolmap.Rotation3d(cam.R), cam.t))
        for j, tid in enumerate(obs["id"].to_numpy()):
            rec.add_observation(point_ids[int(tid)], pycolmap.TrackElement(k, j))
            rec.image(k).set_point3D_for_point2D(j, point_ids[int(tid)])
        image_ids[name] = k
    opts = pycolmap.BundleAdjustmentOptions()
    opts.refine_focal_length = refine_intrinsics
    opts.refine_principal_point = refine_intrinsics
    opts.refine_extra_params = refine_intrinsics
    opts.print_summary = False
    if hold_points:
        config = pycolmap.BundleAdjustmentConfig()
        for k in image_ids.values():
            config.add_image(k)
        for pid in point_ids.values():
            config.add_constant_point(pid)
        pycolmap.create_default_bundle_adjuster(opts, config, rec).solve()
    else:
        pycolmap.bundle_adjustment(rec, opts)
    out_cams = {
        name: _from_colmap(cameras[name], rec.camera(k), rec.image(k).cam_from_world())
        for name, k in image_ids.items()
    }
    xyz = np.array([rec.point3D(point_ids[int(i)]).xyz for i in start.index]).reshape(-1, 3)
    out_pts = pd.DataFrame({"id": start.index.to_numpy(np.int64), "x_mm": xyz[:, 0], "y_mm": xyz[:, 1],
                            "z_mm": xyz[:, 2]})  # fmt: skip
    return out_cams, out_pts


def reprojection_residuals(
    cameras: dict[str, Camera], observations: pd.DataFrame, points: pd.DataFrame
) -> pd.DataFrame:
    """``observations`` with ``du_px, dv_px``: reprojection minus observation, seen in air
    (NaN where the camera or the point is unknown)."""
    xyz = points.set_index("id")[["x_mm", "y_mm", "z_mm"]]
    du = np.full(len(observations), np.nan)
    dv = np.full(len(observations), np.nan)
    for name, idx in observations.groupby("camera").indices.items():
        obs = observations.iloc[idx]
        known = obs["id"].isin(xyz.index).to_numpy()
        if name not in cameras or not known.any():
            continue
        sel = idx[known]
        uv = project_air(cameras[name], xyz.loc[obs["id"][known]].to_numpy())
        du[sel] = uv[:, 0] - obs["u_px"].to_numpy()[known]
        dv[sel] = uv[:, 1] - obs["v_px"].to_numpy()[known]
    return observations.assign(du_px=du, dv_px=dv)


def _air_reconstruction(
    posed: dict[str, Camera],
    obs: pd.DataFrame,
    design: pd.DataFrame,
    cfg: SfmConfig,
    mark_radius_mm: pd.Series | None = None,
) -> CellReconstruction | None:
    """Steps 2-4 of the module docstring for the cameras ``posed`` in air (two or more), from
    their PnP observations ``obs`` (with ``inlier``); None when fewer than ``cfg.min_targets``
    cell-wall targets are seen by two of them (cameras close to the cell, each seeing a strip of
    its bands, far apart): no bundle to adjust. With ``mark_radius_mm`` (printed radius by ID)
    and ``cfg.eccentricity``, the observations are corrected for the eccentricity of the marks'
    images at the adjusted points and the bundle adjusted once more (the residuals are then of
    the corrected observations; ``u_px, v_px`` stay as observed)."""
    used = obs["inlier"].to_numpy().copy()
    reason = np.where(used, "", "PnP outlier").astype(object)
    for rounds in range(1, MAX_BA_ROUNDS + 1):
        while True:  # until every target left is seen twice and every camera left sees enough
            counts = obs.loc[used, "id"].value_counts()
            multi = obs["id"].map(counts).fillna(0).to_numpy() >= 2
            reason[used & ~multi] = "seen by one camera"
            used &= multi
            # a camera left with too few targets is not posed by them (it is posed through the
            # wall); the targets it shared with one other camera are then seen by one
            per_cam = obs.loc[used, "camera"].value_counts()
            few = used & (obs["camera"].map(per_cam).fillna(0).to_numpy() < cfg.min_targets)
            if not few.any():
                break
            reason[few] = f"camera left with fewer than {cfg.min_targets} targets"
            used &= ~few
        posed = {n: c for n, c in posed.items() if per_cam.get(n, 0) >= cfg.min_targets}
        sel = obs[used]
        if len(posed) < 2 or sel["id"].nunique() < cfg.min_targets:
            return None
        adj_cams, adj_pts = bundle_adjust(
            posed, sel, design[design["id"].isin(sel["id"])], cfg.refine_intrinsics
        )
        res = reprojection_residuals(adj_cams, obs, adj_pts)
        err = np.hypot(res["du_px"], res["dv_px"]).to_numpy()
        bad = used & ~(err <= cfg.max_residual_px)
        if not bad.any() or rounds == MAX_BA_ROUNDS:
            break  # (after the last round the few left above the limit stay in)
        reason[bad] = f"residual above {cfg.max_residual_px} px"
        used &= ~bad
    observed = obs
    if mark_radius_mm is not None and cfg.eccentricity:
        xyz = adj_pts.set_index("id").reindex(obs["id"])[["x_mm", "y_mm", "z_mm"]].to_numpy()
        cam_of = obs["camera"].to_numpy().astype(str)
        radius = mark_radius_mm.reindex(obs["id"]).to_numpy()
        ecc = observation_eccentricity(adj_cams, cam_of, xyz, radius, None)
        obs = obs.assign(u_px=obs["u_px"] - ecc[:, 0], v_px=obs["v_px"] - ecc[:, 1])
        adj_cams, adj_pts = bundle_adjust(posed, obs[used], adj_pts, cfg.refine_intrinsics)
    printed = design.set_index("id").loc[adj_pts["id"], ["x_mm", "y_mm", "z_mm"]].reset_index()
    f_stat, held_cams = _design_test(posed, obs[used], adj_cams, adj_pts, printed, cfg)
    s, A, b = similarity_transform(
        adj_pts[["x_mm", "y_mm", "z_mm"]].to_numpy(), printed[["x_mm", "y_mm", "z_mm"]].to_numpy()
    )
    pts = transform_points(adj_pts, s, A, b)
    cyl = fit_cylinder(pts[["x_mm", "y_mm", "z_mm"]].to_numpy())
    if held_cams is not None:  # the printed design: the adjusted points' scatter stays the radius's
        adj_cams, s, A, b, pts = held_cams, 1.0, np.eye(3), np.zeros(3), printed
        cyl = replace(fit_cylinder(pts[["x_mm", "y_mm", "z_mm"]].to_numpy()), rms_mm=cyl.rms_mm)
    tilt = float(np.degrees(np.arccos(np.clip(abs(cyl.direction[2]), -1.0, 1.0))))
    A2, b2 = axis_frame(cyl)
    pts = transform_points(pts, 1.0, A2, b2)
    cams = {n: c.transformed(s, A, b).transformed(1.0, A2, b2) for n, c in adj_cams.items()}
    res = reprojection_residuals(cams, obs, pts).assign(
        u_px=observed["u_px"].to_numpy(), v_px=observed["v_px"].to_numpy(), used=used, reason=reason
    )
    err = np.hypot(res["du_px"], res["dv_px"]).to_numpy()
    stats = pd.DataFrame({"id": res["id"], "e2": err**2, "used": used, "camera": res["camera"]})[used]
    per = stats.groupby("id").agg(n_rays=("e2", "size"), ms=("e2", "mean"))
    pts = pts.set_index("id").join(per).reset_index()
    pts = pts.assign(n_rays=pts["n_rays"].astype(np.int64), rms_px=np.sqrt(pts.pop("ms")))
    cylinder = Cylinder(np.zeros(3), np.array([0.0, 0.0, 1.0]), cyl.radius, cyl.rms_mm)
    by_cam = stats.groupby("camera")["e2"]
    posed_from = {
        n: {
            "pose_from": "cell_wall",
            "targets": int(by_cam.size()[n]),
            "rms_px": float(np.sqrt(by_cam.mean()[n])),
        }
        for n in cams
    }
    return CellReconstruction(cams, pts, res.drop(columns="inlier"), cylinder, tilt, s, {}, posed_from,
                              wall_targets="design" if held_cams is not None else "adjusted",
                              design_f=f_stat)  # fmt: skip


def design_f_statistic(free_ss: float, held_ss: float, n_obs: int, n_points: int, n_cameras: int) -> float:
    """The F statistic of holding ``n_points`` targets at their design positions against adjusting
    them freely, from the sums of squared reprojection residuals (px^2) of the two adjustments
    over the same ``n_obs`` observations by ``n_cameras`` posed cameras: the residual variance
    per coordinate the design takes away over the free adjustment's per degree of freedom
    (about 1 when the design holds to within the image noise). NaN when the free adjustment has
    fewer than ``MIN_DESIGN_DOF`` degrees of freedom (too few observations to tell)."""
    dof = _free_dof(n_obs, n_points, n_cameras)
    if dof < MIN_DESIGN_DOF or n_points == 0 or not free_ss > 0:
        return float("nan")
    return float(((held_ss - free_ss) / (3 * n_points)) / (free_ss / dof))


def _free_dof(n_obs: int, n_points: int, n_cameras: int) -> int:
    """Degrees of freedom of a free adjustment: 2 per observation less 6 per camera, 3 per point."""
    return 2 * n_obs - 6 * n_cameras - 3 * n_points


def _design_test(
    posed: dict[str, Camera],
    obs: pd.DataFrame,
    adj_cams: dict[str, Camera],
    adj_pts: pd.DataFrame,
    printed: pd.DataFrame,
    cfg: SfmConfig,
) -> tuple[float, dict[str, Camera] | None]:
    """The cameras adjusted to the targets held at their ``printed`` positions (from the PnP poses
    ``posed``), and the F statistic (:func:`design_f_statistic`) of that against the free
    adjustment (``adj_cams``, ``adj_pts``) over the observations ``obs``. The held cameras are
    returned (else None) when the statistic is at most ``cfg.design_f_max``: the observations do
    not tell the printed cell from the adjusted one, and the design's positions are exact where
    the adjusted ones carry the image noise."""
    if cfg.design_f_max is None or _free_dof(len(obs), len(adj_pts), len(adj_cams)) < MIN_DESIGN_DOF:
        return float("nan"), None  # (too few observations: no adjustment to hold them in)
    held_cams, _ = bundle_adjust(posed, obs, printed, cfg.refine_intrinsics, hold_points=True)
    ss = [
        float(np.nansum(reprojection_residuals(c, obs, p)[["du_px", "dv_px"]].to_numpy() ** 2))
        for c, p in ((adj_cams, adj_pts), (held_cams, printed))
    ]
    f_stat = design_f_statistic(ss[0], ss[1], len(obs), len(adj_pts), len(adj_cams))
    return f_stat, held_cams if f_stat <= cfg.design_f_max else None


def is_printed_cell(rec: CellReconstruction) -> bool:
    """Is the cell fitted in air the printed one: scale within ``MAX_SCALE_ERROR`` of the
    design's, axis within ``MAX_AXIS_TILT_DEG`` of its z axis?"""
    return abs(rec.scale - 1.0) <= MAX_SCALE_ERROR and rec.axis_tilt_deg <= MAX_AXIS_TILT_DEG


def _nominal_reconstruction(cell: CellOptics, labels: pd.DataFrame) -> CellReconstruction:
    """No camera posed in air: no wall points or residuals (columns those of ``labels`` and the
    residuals'), the kit's cell (axis = z axis of the design)."""
    points = pd.DataFrame({"id": np.zeros(0, np.int64), **{c: np.zeros(0) for c in ("x_mm", "y_mm", "z_mm")},
                           "n_rays": np.zeros(0, np.int64), "rms_px": np.zeros(0)})  # fmt: skip
    residuals = labels.iloc[:0].assign(du_px=np.zeros(0), dv_px=np.zeros(0), used=np.zeros(0, bool),
                                       reason=np.zeros(0, object))  # fmt: skip
    cylinder = Cylinder(np.zeros(3), np.array([0.0, 0.0, 1.0]), cell.outer_radius, float("nan"))
    return CellReconstruction({}, points, residuals, cylinder, float("nan"), 1.0, {}, {}, nominal=True)


def _label_counts(labels: pd.DataFrame, kinds: pd.Series) -> dict[str, str]:
    """Per camera, its labelled targets by kind (``kinds``: id -> kind) at its best frame, as text."""
    lab = labels[labels["id"].isin(kinds.index)]
    per = lab.assign(kind=lab["id"].map(kinds)).groupby(["camera", "frame", "kind"]).size()
    best = per.groupby(["camera", "kind"]).max()
    out = {}
    for name in labels["camera"].unique():
        counts = best.get(name, pd.Series(dtype=int))
        out[str(name)] = ", ".join(f"{int(counts.get(k, 0))} {k}" for k in sorted(set(kinds)))
    return out


def _pose_through_wall(
    intrinsics: Camera,
    labels: pd.DataFrame,
    known: pd.DataFrame,
    cell: CellOptics,
    cfg: SfmConfig,
    mark_radius_mm: pd.Series | None = None,
) -> tuple[Camera, dict, pd.DataFrame] | str:
    """One camera posed from its labels at ``REFERENCE_FRAME`` of the targets ``known`` (``id,
    x_mm, y_mm, z_mm, in_water``) through ``cell`` (:func:`triaxtrack.refractive_pose.pose_camera`).
    With ``mark_radius_mm`` and ``cfg.eccentricity`` it is posed again from the observations
    corrected for the eccentricity of the marks' images at the first pose. Returns the camera,
    its ``posed_from`` entry and the residual rows of its cell-wall observations, or why it
    could not be posed."""
    lab = labels[(labels["camera"] == intrinsics.name) & (labels["frame"] == REFERENCE_FRAME)]
    lab = lab.merge(known, on="id").drop_duplicates("id").reset_index(drop=True)
    if len(lab) < cfg.min_targets:
        return (f"{len(lab)} targets of known position labelled at frame {REFERENCE_FRAME}, "
                f"fewer than {cfg.min_targets}")  # fmt: skip
    water = lab["in_water"].to_numpy(bool)
    obs = PoseObservations(lab["id"].to_numpy(), lab[["x_mm", "y_mm", "z_mm"]].to_numpy(float),
                           lab[["u_px", "v_px"]].to_numpy(float), water)  # fmt: skip
    pose = pose_camera(intrinsics, obs, cell, cfg.min_targets, cfg.ransac_px)
    if isinstance(pose, str):
        return pose
    if mark_radius_mm is not None and cfg.eccentricity:
        radius = mark_radius_mm.reindex(obs.ids).to_numpy()
        ecc = np.zeros_like(obs.uv)
        for in_water, medium in ((True, cell), (False, None)):
            sel = water == in_water
            ecc[sel] = observation_eccentricity({intrinsics.name: pose.camera}, lab["camera"].to_numpy()[sel],
                                                obs.xyz[sel], radius[sel], medium)  # fmt: skip
        again = pose_camera(intrinsics, replace(obs, uv=obs.uv - ecc), cell, cfg.min_targets, cfg.ransac_px)
        pose = pose if isinstance(again, str) else again
    info = {
        "pose_from": "water" if water[pose.used].any() else "cell_wall",
        "targets": int(pose.used.sum()),
        "targets_in_water": int((pose.used & water).sum()),
        "rms_px": pose.rms_px,
    }
    air = lab[~water]
    rows = air[["camera", "frame", "id", "u_px", "v_px"]].assign(
        du_px=pose.residuals[~water, 0], dv_px=pose.residuals[~water, 1], used=pose.used[~water],
        reason=np.where(pose.used[~water], "", f"residual above {cfg.ransac_px} px"),
    )  # fmt: skip
    return pose.camera, info, rows


def reconstruct_cell(
    cameras: dict[str, Camera],
    labels: pd.DataFrame,
    design: pd.DataFrame,
    cfg: SfmConfig,
    water: pd.DataFrame | None = None,
    cell: CellOptics | None = None,
    mark_radius_mm: pd.Series | None = None,
) -> CellReconstruction:
    """Cameras and cell wall from the labelled targets (module docstring).

    ``cameras``: calibrated intrinsics per camera; ``labels``: rows ``camera, frame, id, u_px,
    v_px`` (every labelled frame; per camera its earliest frame with enough cell-wall targets
    is used, and ``REFERENCE_FRAME`` for a pose through the wall); ``design``: ``id, x_mm, y_mm,
    z_mm`` of the cell-wall targets (design positions); ``water``: the same of the targets in the
    water whose design position holds at ``REFERENCE_FRAME`` (pedestal CTs, membrane dots; an
    optional ``kind`` column names them in messages); ``cell``: the kit's cell (radii,
    indices); ``mark_radius_mm``: the printed radius of each cell-wall ID's round mark, for the
    eccentricity of its image (:func:`triaxtrack.eccentricity.mark_radii`; None: no
    correction). Without ``water`` and ``cell`` only cameras that see the wall are posed. Raises
    ValueError, naming every camera and what it labelled, when fewer than two can be posed.
    """
    obs = earliest_observations(labels, design["id"].to_numpy(), cfg.min_targets)
    posed, obs, dropped = initial_poses(cameras, obs, design, cfg)
    through_water = water is not None and cell is not None and cfg.pose_from_water
    for name in sorted(set(cameras) - set(posed) - set(dropped)):
        dropped[name] = "no frame with enough labelled cell-wall targets"
    rec = _air_reconstruction(posed, obs, design, cfg, mark_radius_mm) if len(posed) >= 2 else None
    for name in sorted(set(posed) - set(rec.cameras if rec is not None else posed)):
        dropped[name] = f"fewer than {cfg.min_targets} cell-wall targets left by the bundle adjustment"
    unlike = rec is not None and not is_printed_cell(rec)
    if unlike and through_water:
        rec = None
    if rec is None and through_water and cell is not None:  # (through_water implies a cell)
        why = (
            "no cell frame from the wall"
            if len(posed) < 2
            else "the wall's targets give a cell unlike the printed one (scale or axis)"
            if unlike
            else "the wall's targets too few in common"
        )
        rec = _nominal_reconstruction(cell, labels)
        dropped = {n: dropped.get(n, f"{why}: posed through it") for n in cameras}
    if rec is not None and through_water and cell is not None and dropped:
        rec = _add_water_cameras(rec, cameras, labels, design, water, cell, cfg, dropped, mark_radius_mm)
        dropped = rec.dropped
    if rec is None or len(rec.cameras) < 2:
        kinds = pd.Series("cell-wall", index=design["id"].to_numpy())
        if water is not None:
            wk = water["kind"].to_numpy() if "kind" in water.columns else "in-water"
            kinds = pd.concat([kinds, pd.Series(wk, index=water["id"].to_numpy())])
        counts = _label_counts(labels, kinds)
        why = "; ".join(
            f"{n}: {counts.get(n, 'nothing')} labelled: {dropped.get(n, 'posed')}" for n in sorted(cameras)
        )
        alone = rec is None and len(posed) > 1
        n = len(rec.cameras) if rec is not None else 0 if alone else len(posed)
        shared = f" ({len(posed)} posed alone share too few cell-wall targets)" if alone else ""
        raise ValueError(f"cameras and cell: only {n} camera(s) could be posed{shared}; {why}")
    return replace(rec, dropped=dict(sorted(dropped.items())))


def _add_water_cameras(
    rec: CellReconstruction,
    cameras: dict[str, Camera],
    labels: pd.DataFrame,
    design: pd.DataFrame,
    water: pd.DataFrame,
    cell: CellOptics,
    cfg: SfmConfig,
    dropped: dict[str, str],
    mark_radius_mm: pd.Series | None = None,
) -> CellReconstruction:
    """``rec`` with the cameras of ``dropped`` posed through the wall where they can be: against
    the fitted cell (its radius, the kit's wall thickness and indices) in the axis frame, or the
    kit's cell when ``rec.nominal``. Cell-wall targets are at their adjusted positions where the
    air reconstruction has them, else at their design positions."""
    wall = design.set_index("id")[["x_mm", "y_mm", "z_mm"]]
    if len(rec.points):
        wall.update(rec.points.set_index("id")[["x_mm", "y_mm", "z_mm"]])
    in_water = water[["id", "x_mm", "y_mm", "z_mm"]].assign(in_water=True)
    known = pd.concat([wall.reset_index().assign(in_water=False), in_water], ignore_index=True)
    thickness = cell.outer_radius - cell.inner_radius
    optics = replace(cell, outer_radius=rec.cylinder.radius, inner_radius=rec.cylinder.radius - thickness)
    cams, posed_from, left, rows = dict(rec.cameras), dict(rec.posed_from), {}, [rec.residuals]
    for name in sorted(dropped):
        out = _pose_through_wall(cameras[name], labels, known, optics, cfg, mark_radius_mm)
        if isinstance(out, str):
            left[name] = f"{dropped[name]}; through the wall: {out}"
            continue
        cams[name], posed_from[name], air_rows = out
        rows.append(air_rows)
    rows = [r for r in rows if len(r)]
    residuals = pd.concat(rows, ignore_index=True) if rows else rec.residuals
    return replace(rec, cameras=cams, posed_from=posed_from, dropped=left, residuals=residuals)


def cell_summary(rec: CellReconstruction) -> dict:
    """The reconstruction as JSON: ``cameras`` (as ``cameras.json``, in the axis frame), how each
    was posed (``cameras_posed``: ``pose_from``, targets used, RMS residual px), the ``cell``
    (fitted in air, or the kit's nominal cell: ``source``) and what was left out
    (``cameras_dropped``). Values that were not measured are null."""
    used = rec.residuals[rec.residuals["used"].astype(bool)]
    err = np.hypot(used["du_px"].astype(float), used["dv_px"].astype(float))
    n = len(rec.points)
    if rec.nominal:
        frame = (
            "design frame: the kit's nominal cell on the pedestals' axis (no camera saw enough of the wall)"
        )
        sigma, rms, tilt = NOMINAL_RADIUS_SIGMA_MM, None, None
    else:
        frame = "axis frame: cell axis = z axis; rotation about it and origin height from the printed cell"
        sigma, rms, tilt = rec.cylinder.rms_mm / np.sqrt(max(n, 1)), rec.cylinder.rms_mm, rec.axis_tilt_deg
    return {
        "frame": frame,
        "cameras": {name: cam.to_json() for name, cam in sorted(rec.cameras.items())},
        "cameras_posed": dict(sorted(rec.posed_from.items())),
        "cell": {
            "source": "nominal" if rec.nominal else "cell_wall",
            "outer_radius_mm": rec.cylinder.radius,
            "outer_radius_sigma_mm": sigma,
            "cylinder_rms_mm": rms,
            "axis_tilt_deg": tilt,
            "targets": n,
            "wall_targets": None if rec.nominal else rec.wall_targets,
            "design_f": None if rec.nominal or not np.isfinite(rec.design_f) else rec.design_f,
        },
        "design_scale": rec.scale,
        "mean_reprojection_px": float(err.mean()) if len(err) else None,
        "observations_used": int(len(used)),
        "observations_dropped": int((~rec.residuals["used"].astype(bool)).sum()),
        "cameras_dropped": dict(sorted(rec.dropped.items())),
    }
