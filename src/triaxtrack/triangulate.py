"""Targets in the water, by ray tracing through the cell wall (the paper's section 3.2).

Each observation of a pedestal or membrane target is a ray: undistorted with the camera's
calibration, traced from the camera centre, refracted by Snell's law at the outer wall (air to
acrylic) and the inner wall (acrylic to water) (:func:`water_rays`). A point's first estimate
is the least-squares intersection of its rays in the water (:func:`intersect_rays`); it is then
refined by Gauss-Newton on the reprojection error through the full refractive path
(:func:`refine_points`, exact projection by :func:`triaxtrack.optics.project_water`), which
weighs every ray by its image precision rather than by its length in the water. An observation
whose residual exceeds ``max_residual_px`` is dropped, the worst first, and its point solved
again. Each point reports ``n_rays``, ``rms_px`` and ``sigma_mm``: the standard error of its
position, from the geometry of its rays and the larger of the a-posteriori image noise of all
points and of its own residuals.

:func:`refine_cell` goes beyond the seed: one refractive bundle adjustment of the outer radius,
the wall thickness and the water's refractive index over all targets (the cameras held), by
variable projection (the points re-triangulated for every trial of the three parameters).

:func:`pedestal_frame` fixes what the cell wall cannot: the rotation about the axis and the
height of the origin, from the bottom pedestal's coded targets, so that the results are in the
cell frame of ``target-kit.md`` (origin on the bottom pedestal face, +x towards CT 17).
Millimetres in the (axis-aligned) cell frame; pixels in OpenCV convention.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np
import pandas as pd
from scipy.optimize import least_squares

from triaxtrack.cell_frame import transform_points
from triaxtrack.codec_lag.correct import CODEC_COLUMNS
from triaxtrack.eccentricity import observation_eccentricity
from triaxtrack.influence import (
    CODEC_SHIFT_COLUMNS,
    INFLUENCE_COLUMNS,
    observation_influence,
    observation_shift,
)
from triaxtrack.optics import (
    Camera,
    CellOptics,
    pixels_to_normalized,
    project_water,
    trace_into_water,
)
from triaxtrack.reconstruction_config import TriangulationConfig

FD_STEP_MM = 1e-4  # finite-difference step of the point Jacobians (the projection is exact to ~1e-8 px)
REFINE_CELL_STEPS = (0.01, 0.01, 1e-4)  # finite-difference steps: outer radius mm, wall mm, n_water
UNPROJECTED_PX = 10.0  # residual counted for an observation whose point no longer projects


def water_rays(camera: Camera, uv_px: np.ndarray, cell: CellOptics) -> tuple[np.ndarray, np.ndarray]:
    """The rays in the water of (N, 2) distorted pixels: ``(origins, dirs)``, (N, 3) each, the
    origin on the inner wall and the unit direction away from the camera (NaN where the ray
    misses the cell or the pixel cannot be undistorted)."""
    path = trace_into_water(camera, pixels_to_normalized(camera, uv_px), cell)
    return path.inner_hit, path.dir_water


def intersect_rays(origins: np.ndarray, dirs: np.ndarray, group: np.ndarray, n_groups: int) -> np.ndarray:
    """(n_groups, 3) least-squares intersections of rays grouped by ``group`` (N ints in
    ``[0, n_groups)``): the point nearest all of its rays. NaN for a group of fewer than two
    rays or of parallel rays. ``dirs`` unit (N, 3)."""
    P = np.eye(3)[None] - dirs[:, :, None] * dirs[:, None, :]
    A = np.zeros((n_groups, 3, 3))
    b = np.zeros((n_groups, 3))
    np.add.at(A, group, P)
    np.add.at(b, group, np.einsum("nij,nj->ni", P, origins))
    out = np.full((n_groups, 3), np.nan)
    ok = np.linalg.cond(A) < 1e8
    out[ok] = np.linalg.solve(A[ok], b[ok][:, :, None])[:, :, 0]
    return out


def _project_all(
    cameras: dict[str, Camera], cam_of: np.ndarray, xyz: np.ndarray, cell: CellOptics, xy0: np.ndarray
) -> np.ndarray:
    """(N, 2) exact pixels of points ``xyz`` (N, 3) in cameras ``cam_of`` (N names)."""
    uv = np.full((len(xyz), 2), np.nan)
    for name in np.unique(cam_of):
        sel = cam_of == name
        uv[sel] = project_water(cameras[name], xyz[sel], cell, xy0=xy0[sel])[0]
    return uv


def refine_points(
    cameras: dict[str, Camera],
    cam_of: np.ndarray,
    uv_px: np.ndarray,
    group: np.ndarray,
    xyz: np.ndarray,
    cell: CellOptics,
    iterations: int = 3,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Gauss-Newton on the reprojection error through the refractive path.

    Observations: ``cam_of`` (N camera names), ``uv_px`` (N, 2) distorted pixels, ``group``
    (N point indices into ``xyz``, (M, 3) starting points). Returns the refined points (M, 3),
    the final residuals (N, 2; projection minus observation, NaN where the point does not
    project), ``(J^T J)^-1`` per point (M, 3, 3), pixel^-2 mm^2, and the final Jacobians of the
    projections (N, 2, 3), pixel/mm.
    """
    xyz = np.array(xyz, float, copy=True)
    m = len(xyz)
    xy0 = np.full((len(uv_px), 2), np.nan)
    for name in np.unique(cam_of):
        sel = cam_of == name
        xy0[sel] = pixels_to_normalized(cameras[name], uv_px[sel])
    cov = np.full((m, 3, 3), np.nan)
    for it in range(iterations + 1):
        p = xyz[group]
        r = _project_all(cameras, cam_of, p, cell, xy0) - uv_px
        J = np.stack(
            [(_project_all(cameras, cam_of, p + FD_STEP_MM * e, cell, xy0) - uv_px - r) / FD_STEP_MM
             for e in np.eye(3)], axis=2,
        )  # fmt: skip
        ok = np.isfinite(r).all(axis=1) & np.isfinite(J).all(axis=(1, 2))
        JtJ = np.zeros((m, 3, 3))
        Jtr = np.zeros((m, 3))
        np.add.at(JtJ, group[ok], np.einsum("nki,nkj->nij", J[ok], J[ok]))
        np.add.at(Jtr, group[ok], np.einsum("nki,nk->ni", J[ok], r[ok]))
        good = np.linalg.cond(JtJ) < 1e12
        cov[:] = np.nan
        cov[good] = np.linalg.inv(JtJ[good])
        if it == iterations:
            break
        xyz[good] -= np.einsum("mij,mj->mi", cov[good], Jtr[good])
    return xyz, r, cov, J


@dataclass(frozen=True)
class WaterTargets:
    """Triangulated targets and the fate of every observation."""

    points: pd.DataFrame  # id, x_mm, y_mm, z_mm, n_rays, rms_px, sigma_mm
    residuals: pd.DataFrame  # WATER_RESIDUALS: the observations with du_px, dv_px, used, reason, influence
    sigma0_px: float  # a-posteriori image noise (RMS residual, corrected for the 3 unknowns a point)
    eccentricity_px: np.ndarray  # (N, 2) per residuals row: the eccentricity taken off it (or 0)


def _solve(
    cameras: dict[str, Camera],
    obs: pd.DataFrame,
    cell: CellOptics,
    cfg: TriangulationConfig,
    mark_radius_mm: pd.Series | None = None,
):
    """Intersect and refine every id of ``obs`` (all rows used). Returns ids, group, xyz,
    residuals, cov, the observations' eccentricities (N, 2; zero without ``mark_radius_mm``),
    their influences on their points (N, 3, mm; :func:`triaxtrack.influence.observation_influence`)
    and the points' shifts by the observations' ``codec_u_px`` and ``codec_v_px`` (N, 6, mm,
    :data:`~triaxtrack.influence.CODEC_SHIFT_COLUMNS`; 0 where ``obs`` has no such columns).

    With ``mark_radius_mm`` (printed radius by ID, :func:`triaxtrack.eccentricity.mark_radii`),
    the refined points are corrected for the eccentricity of their marks' images: each
    observation's eccentricity at its point is subtracted from it and the points take one more
    (linear) Gauss-Newton step, their residuals with them (the eccentricity is a few hundredths of
    a pixel, the step a few micrometres)."""
    ids, group = np.unique(obs["id"].to_numpy(), return_inverse=True)
    cam_of = obs["camera"].to_numpy().astype(str)
    uv = obs[["u_px", "v_px"]].to_numpy(float)
    origins = np.full((len(obs), 3), np.nan)
    dirs = np.full((len(obs), 3), np.nan)
    for name in np.unique(cam_of):
        sel = cam_of == name
        origins[sel], dirs[sel] = water_rays(cameras[name], uv[sel], cell)
    ok = np.isfinite(dirs).all(axis=1)
    xyz0 = intersect_rays(origins[ok], dirs[ok], group[ok], len(ids))
    xyz, r, cov, J = refine_points(cameras, cam_of, uv, group, xyz0, cell, cfg.iterations)
    ecc = np.zeros((len(obs), 2))
    if mark_radius_mm is not None:
        radius = mark_radius_mm.reindex(obs["id"].to_numpy()).to_numpy(float)
        ecc = observation_eccentricity(cameras, cam_of, xyz[group], radius, cell)
        r = r + ecc
        ok = np.isfinite(r).all(axis=1) & np.isfinite(J).all(axis=(1, 2))
        Jtr = np.zeros((len(ids), 3))
        np.add.at(Jtr, group[ok], np.einsum("nki,nk->ni", J[ok], r[ok]))
        step = -np.einsum("mij,mj->mi", np.nan_to_num(cov), Jtr)
        xyz = xyz + step
        r = r + np.einsum("nij,nj->ni", J, step[group])
    shift = np.zeros((len(obs), 6))
    if all(c in obs.columns for c in CODEC_COLUMNS):
        codec = obs[list(CODEC_COLUMNS)].to_numpy(float)
        for a in (0, 1):
            error = np.zeros((len(obs), 2))
            error[:, a] = codec[:, a]
            shift[:, 3 * a : 3 * a + 3] = observation_shift(J, cov, group, error)
    return ids, group, xyz, r, cov, ecc, observation_influence(J, cov, group, r), shift


def triangulate_refracted(
    cameras: dict[str, Camera],
    observations: pd.DataFrame,
    cell: CellOptics,
    cfg: TriangulationConfig,
    mark_radius_mm: pd.Series | None = None,
    eccentricity_px: np.ndarray | None = None,
) -> WaterTargets:
    """3-D points of targets in the water from their labelled pixels in several cameras.

    ``observations``: rows ``camera, frame, id, u_px, v_px`` of one frame (distorted pixels);
    cameras not in ``cameras`` are ignored. Outliers are dropped one per point and round, the
    worst first, until every residual is within ``cfg.max_residual_px`` (each round solves again
    only the points that lost a ray); a point left with fewer than ``cfg.min_rays`` rays is not
    reported. ``mark_radius_mm``: the printed radius of each ID's round mark
    (:func:`triaxtrack.eccentricity.mark_radii`); with it and ``cfg.eccentricity``, the points
    are corrected for the eccentricity of the marks' images, computed at the points;
    ``eccentricity_px`` (N, 2, one per row of ``observations``) instead gives them (computed at
    other frames, :func:`triaxtrack.timesteps.triangulate_frames`). ``du_px, dv_px`` are then the
    reprojection plus the eccentricity minus the observation, ``u_px, v_px`` as observed;
    ``ix_mm, iy_mm, iz_mm`` each used observation's influence on its point
    (:func:`triaxtrack.influence.observation_influence`; NaN where not used). With the columns
    ``codec_u_px, codec_v_px`` in ``observations`` (the codec correction's uncertainty,
    :func:`triaxtrack.codec_lag.correct_lag`), the points have
    :data:`~triaxtrack.influence.CODEC_SHIFT_COLUMNS`: their shifts by it, summed over their used
    observations (:func:`triaxtrack.influence.shared_sigma`).
    """
    radii = mark_radius_mm if cfg.eccentricity and eccentricity_px is None else None
    keep = observations["camera"].isin(list(cameras)).to_numpy()
    obs = observations[keep].reset_index(drop=True)
    given = np.zeros((len(obs), 2)) if eccentricity_px is None else np.asarray(eccentricity_px, float)[keep]
    solve_obs = obs.assign(u_px=obs["u_px"] - given[:, 0], v_px=obs["v_px"] - given[:, 1])
    ecc = given.copy()
    all_ids, gid = np.unique(obs["id"].to_numpy(), return_inverse=True)
    xyz = np.full((len(all_ids), 3), np.nan)
    cov = np.full((len(all_ids), 3, 3), np.nan)
    used = np.ones(len(obs), bool)
    reason = np.full(len(obs), "", object)
    du = np.full(len(obs), np.nan)
    dv = np.full(len(obs), np.nan)
    influence = np.full((len(obs), 3), np.nan)
    shift = np.zeros((len(obs), 6))
    todo = np.ones(len(all_ids), bool)  # points to solve (again): all, then those that lost a ray
    while todo.any():
        few = used & (np.bincount(gid[used], minlength=len(all_ids))[gid] < cfg.min_rays)
        reason[few] = f"fewer than {cfg.min_rays} rays"
        used &= ~few
        idx = np.flatnonzero(used & todo[gid])
        if idx.size == 0:
            break
        solution = _solve(cameras, solve_obs.iloc[idx], cell, cfg, radii)
        ids, group, p, r, c, e, influence[idx], shift[idx] = solution
        ecc[idx] = given[idx] + e
        k = np.searchsorted(all_ids, ids)
        xyz[k], cov[k] = p, c
        du[idx], dv[idx] = r[:, 0], r[:, 1]
        err = np.hypot(r[:, 0], r[:, 1])
        err = np.where(np.isfinite(err), err, np.inf)
        worst = pd.Series(err).groupby(group).idxmax().to_numpy()
        worst = worst[err[worst] > cfg.max_residual_px]
        reason[idx[worst]] = np.where(
            np.isfinite(err[worst]), f"residual above {cfg.max_residual_px} px", "does not project"
        )
        used[idx[worst]] = False
        todo[:] = False
        todo[gid[idx[worst]]] = True
    codec = shift if all(c in obs.columns for c in CODEC_COLUMNS) else None
    points, sigma0 = _point_table(all_ids, xyz, cov, gid, used, np.hypot(du, dv), cfg.min_rays, codec)
    influence[~used] = np.nan
    obs = obs.drop(columns=list(CODEC_COLUMNS), errors="ignore")
    residuals = obs.assign(du_px=du, dv_px=dv, used=used, reason=reason,
                           **dict(zip(INFLUENCE_COLUMNS, influence.T, strict=True)))  # fmt: skip
    return WaterTargets(points, residuals, sigma0, ecc)


def _point_table(
    ids: np.ndarray,
    xyz: np.ndarray,
    cov: np.ndarray,
    gid: np.ndarray,
    used: np.ndarray,
    resid: np.ndarray,
    min_rays: int,
    codec: np.ndarray | None = None,
) -> tuple[pd.DataFrame, float]:
    """The solved points of :func:`triangulate_refracted` (``ids`` with their ``xyz`` and
    ``cov``; observations' point ``gid``, ``used`` and residual length ``resid``, px) with at
    least ``min_rays`` rays and a finite position, and the a-posteriori image noise. With the
    observations' ``codec`` shifts (N, 6), each point's sum over its used observations."""
    n_rays = np.bincount(gid[used], minlength=len(ids))
    e2 = np.bincount(gid[used], weights=resid[used] ** 2, minlength=len(ids))
    solved = n_rays >= min_rays
    dof = max(2 * n_rays[solved].sum() - 3 * solved.sum(), 1)
    sigma0 = float(np.sqrt(e2[solved].sum() / dof))
    # a point whose own rays disagree more than the image noise says so in its uncertainty
    own = np.sqrt(e2 / np.maximum(2 * n_rays - 3, 1))
    points = pd.DataFrame({
        "id": ids.astype(np.int64), "x_mm": xyz[:, 0], "y_mm": xyz[:, 1], "z_mm": xyz[:, 2],
        "n_rays": n_rays.astype(np.int64), "rms_px": np.sqrt(e2 / np.maximum(n_rays, 1)),
        "sigma_mm": np.maximum(sigma0, own) * np.sqrt(np.trace(cov, axis1=1, axis2=2)),
    })  # fmt: skip
    if codec is not None:
        per_point = np.zeros((len(ids), 6))
        np.add.at(per_point, gid[used], np.nan_to_num(codec[used]))
        points = points.assign(**dict(zip(CODEC_SHIFT_COLUMNS, per_point.T, strict=True)))
    points = points[solved]
    return points[np.isfinite(points[["x_mm", "y_mm", "z_mm"]]).all(axis=1)].reset_index(drop=True), sigma0


def _sample_ids(ids: np.ndarray, n: int) -> np.ndarray:
    """About ``n`` of ``ids``, evenly spread over the sorted list (all if fewer)."""
    ids = np.unique(ids)
    if len(ids) <= n:
        return ids
    return ids[np.linspace(0, len(ids) - 1, n).round().astype(int)]


@dataclass(frozen=True)
class CellRefinement:
    """The refractive bundle adjustment of the cell (:func:`refine_cell`)."""

    cell: CellOptics
    rms_before_px: float
    rms_after_px: float
    points_used: int


def refine_cell(
    cameras: dict[str, Camera],
    residuals: pd.DataFrame,
    cell: CellOptics,
    cfg: TriangulationConfig,
    outer_radius_sigma_mm: float,
    mark_radius_mm: pd.Series | None = None,
) -> CellRefinement:
    """Refine the outer radius, the wall thickness and the water's index over all targets.

    Minimises the RMS reprojection error of ``cfg.refine_cell_points`` points, spread over the
    IDs, re-triangulating them for every trial. ``residuals``: the used observations of
    :func:`triangulate_refracted` (the outliers it dropped stay out). The cameras and the
    acrylic's index are held (the index and the thickness of the wall are nearly
    interchangeable). The outer radius is also measured in air (:func:`triaxtrack.cell_frame.fit_cylinder`,
    standard error ``outer_radius_sigma_mm``) and enters as a prior: through the water alone the
    three parameters are nearly interchangeable too.
    """
    radii = mark_radius_mm if cfg.eccentricity else None
    obs = residuals[residuals["used"]]
    obs = obs[obs["id"].isin(_sample_ids(obs["id"].to_numpy(), cfg.refine_cell_points))]
    obs = obs.reset_index(drop=True)

    def make(p: np.ndarray) -> CellOptics:
        return replace(cell, outer_radius=p[0], inner_radius=p[0] - p[1], n_water=p[2])

    p0 = np.array([cell.outer_radius, cell.outer_radius - cell.inner_radius, cell.n_water])

    def pixels(p: np.ndarray) -> np.ndarray:
        r = _solve(cameras, obs, make(p), cfg, radii)[3].ravel()
        return np.where(np.isfinite(r), r, UNPROJECTED_PX)

    r0 = pixels(p0)
    sigma0 = float(np.sqrt(np.mean(r0**2)))

    def resid(p: np.ndarray) -> np.ndarray:
        # the outer radius measured in air, as one more observation in image-noise units
        prior = (p[0] - p0[0]) / outer_radius_sigma_mm * sigma0
        return np.r_[pixels(p), prior]

    sol = least_squares(resid, p0, diff_step=np.array(REFINE_CELL_STEPS) / p0, x_scale=[1e-3, 1.0, 1e-3])
    after = float(np.sqrt(np.mean(sol.fun[:-1] ** 2)))
    return CellRefinement(make(sol.x), sigma0, after, int(obs["id"].nunique()))


def pedestal_frame(points: pd.DataFrame, design: pd.DataFrame) -> tuple[np.ndarray, np.ndarray, int]:
    """The rotation about z and the shift along it that put the reconstructed bottom pedestal
    CTs (ids in both ``points`` and ``design``, columns ``id, x_mm, y_mm, z_mm``) at their design
    angle and height: returns ``(A, b, n)`` for ``x' = A x + b`` and the number of CTs used.
    With no CT in common, the identity (``n = 0``)."""
    common = points.merge(design, on="id", suffixes=("", "_d"))
    if common.empty:
        return np.eye(3), np.zeros(3), 0
    dth = np.arctan2(common["y_mm"], common["x_mm"]) - np.arctan2(common["y_mm_d"], common["x_mm_d"])
    angle = -float(np.angle(np.exp(1j * dth.to_numpy()).mean()))
    c, s = np.cos(angle), np.sin(angle)
    A = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
    dz = float((common["z_mm_d"] - common["z_mm"]).mean())
    return A, np.array([0.0, 0.0, dz]), len(common)


@dataclass(frozen=True)
class SpecimenReconstruction:
    """The first-frame reconstruction in the cell frame (:func:`reconstruct_specimen`)."""

    cameras: dict[str, Camera]
    cell: CellOptics
    points: pd.DataFrame  # POINTS columns + sigma_mm, every reconstructed target (cell wall too)
    residuals: pd.DataFrame  # RESIDUALS columns + medium ('air' | 'water')
    sigma0_px: float  # a-posteriori image noise of the water observations
    refinement: CellRefinement | None
    frame_fix: dict  # pedestal_cts, rotation_deg, shift_mm


def reconstruct_specimen(
    cameras: dict[str, Camera],
    cell_points: pd.DataFrame,
    air_residuals: pd.DataFrame,
    labels: pd.DataFrame,
    in_water: np.ndarray,
    bottom_pedestal: pd.DataFrame,
    cell: CellOptics,
    outer_radius_sigma_mm: float,
    cfg: TriangulationConfig,
    frame: int,
    time_s: float,
    mark_radius_mm: pd.Series | None = None,
) -> SpecimenReconstruction:
    """Triangulate the targets in the water at ``frame`` and put everything in the cell frame.

    ``cameras``, ``cell_points`` (``id, x_mm, y_mm, z_mm, n_rays, rms_px``) and
    ``air_residuals``: the cameras-and-cell reconstruction in its axis frame
    (:func:`triaxtrack.sfm.reconstruct_cell`); ``labels``: rows ``camera, frame, id, u_px,
    v_px``; ``in_water``: the IDs of the targets in the water (pedestals, membrane);
    ``bottom_pedestal``: design ``id, x_mm, y_mm, z_mm`` of the bottom pedestal's CTs (they fix
    the rotation about the axis and the origin, :func:`pedestal_frame`). With
    ``cfg.refine_cell`` the cell is refined first (:func:`refine_cell`) and the points solved
    again with it. ``mark_radius_mm``: as for :func:`triangulate_refracted`.
    """
    obs = labels[(labels["frame"] == frame) & labels["id"].isin(in_water)]
    obs = obs[["camera", "frame", "id", "u_px", "v_px"]].reset_index(drop=True)
    water = triangulate_refracted(cameras, obs, cell, cfg, mark_radius_mm)
    refinement = None
    if cfg.refine_cell:
        refinement = refine_cell(cameras, water.residuals, cell, cfg, outer_radius_sigma_mm, mark_radius_mm)
        cell = refinement.cell
        water = triangulate_refracted(cameras, obs, cell, cfg, mark_radius_mm)
    A, b, n = pedestal_frame(water.points[water.points["id"].isin(bottom_pedestal["id"])], bottom_pedestal)
    air = cell_points.assign(sigma_mm=np.nan)
    pts = pd.concat([air, water.points], ignore_index=True)
    pts = transform_points(pts, 1.0, A, b).assign(frame=frame, time_s=time_s)
    residuals = pd.concat(
        [air_residuals.assign(medium="air"), water.residuals.assign(medium="water")], ignore_index=True
    )
    frame_fix = {
        "pedestal_cts": n,
        "rotation_deg": float(np.degrees(np.arctan2(A[1, 0], A[0, 0]))),
        "shift_mm": float(b[2]),
    }
    return SpecimenReconstruction(
        {name: cam.transformed(1.0, A, b) for name, cam in cameras.items()},
        cell,
        pts,
        residuals,
        water.sigma0_px,
        refinement,
        frame_fix,
    )
