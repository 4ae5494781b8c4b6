"""Per-timestep 3-D: every tracked target triangulated at every processed frame (paper 2.4, 3.3).

The cameras and the cell are those of the first frame (``triaxtrack.sfm``,
``triaxtrack.triangulate``); they are assumed fixed for the whole test, and that is checked:
the cell-wall targets do not move, so each camera's tracked cell-wall targets must stay on the
projections of their first-frame 3-D points. A camera whose median drift exceeds
``moved_px`` at a frame is reported as moved (knocked, or its mount settled), and posed again
at that frame from those targets (PnP in air, at least ``MIN_REPOSE_TARGETS`` of them, their
median reprojection then within ``moved_px``: ``reposed``); where it cannot be, its
observations of that frame are left out of the triangulation (reason ``camera moved``).

Chunks are tracked independently (``triaxtrack.track``); neighbouring chunks share one frame, at
which the IDs carried to the end of one chunk are compared with the labels of the next
(:func:`handover_check`).

The workflow's stages: one chunk triangulated (:func:`run_triangulate_chunk`), and the chunks
of a test collected with its quality report (:func:`run_collect_timesteps`).

Units: millimetres in the cell frame, pixels (distorted, OpenCV convention), seconds.
"""

from __future__ import annotations

import json
from collections.abc import Sequence
from pathlib import Path

import numpy as np
import pandas as pd

from triaxtrack.codec_lag import corrected_tracks, read_lag_files
from triaxtrack.codec_lag.correct import CODEC_COLUMNS
from triaxtrack.eccentricity import mark_radii
from triaxtrack.jsonfile import write_json
from triaxtrack.kit import load_kit_design, target_table
from triaxtrack.optics import Camera, CellOptics, project_air, read_cameras
from triaxtrack.reconstruction_config import SfmConfig, TriangulationConfig
from triaxtrack.refractive_pose import pnp_pose
from triaxtrack.specimen_stage import quality_cell
from triaxtrack.tables import (
    LABELS,
    OBSERVATIONS,
    POINTS,
    TRACKS,
    WATER_RESIDUALS,
    Schema,
    concat_tables,
    read_table,
    write_table,
)
from triaxtrack.testfolder import read_quality, read_test_fps
from triaxtrack.tracking_config import TrackingConfig
from triaxtrack.triangulate import triangulate_refracted

MIN_WALL_TARGETS = 5  # fewer tracked cell-wall targets in a frame: the camera cannot be checked
MIN_REPOSE_TARGETS = 12  # cell-wall targets a moved camera is posed again from (as the first frame's PnP)


def camera_motion(
    cameras: dict[str, Camera],
    wall_points: pd.DataFrame,
    tracks: pd.DataFrame,
    moved_px: float = TrackingConfig.moved_px,
    ransac_px: float = SfmConfig.ransac_px,
) -> tuple[pd.DataFrame, dict[tuple[str, int], Camera]]:
    """Per camera and frame: the median distance (pixels) of the tracked cell-wall targets from
    the projections of their first-frame points, whether the camera has moved, and whether it
    was posed again there; and those poses.

    ``wall_points``: ``id, x_mm, y_mm, z_mm`` of the cell-wall targets (cell frame, in air);
    ``tracks``: ``TRACKS`` rows (only reported ones, ``reason == ''``, count). Returns
    (``MOTION`` rows: ``camera, frame, wall_targets, drift_px, moved, reposed``, ``drift_px``
    NaN and ``moved`` False with fewer than ``MIN_WALL_TARGETS`` targets; ``{(camera, frame):
    the camera posed again}`` for the moved camera-frames it could be posed in, module
    docstring; ``ransac_px``: the PnP inlier threshold, config ``reconstruction.ransac_px``).
    """
    rep = tracks[(tracks["reason"] == "") & tracks["id"].isin(wall_points["id"])]
    xyz_all = wall_points.set_index("id")[["x_mm", "y_mm", "z_mm"]]
    rows, poses = [], {}
    for (name, frame), g in rep.groupby(["camera", "frame"], sort=True):
        if name not in cameras:
            continue
        xyz, seen = xyz_all.loc[g["id"]].to_numpy(np.float64), g[["u_px", "v_px"]].to_numpy(np.float64)
        d = np.hypot(*(project_air(cameras[name], xyz) - seen).T)
        d = d[np.isfinite(d)]
        drift = float(np.median(d)) if len(d) >= MIN_WALL_TARGETS else float("nan")
        moved = bool(drift > moved_px)
        pose = _posed_again(cameras[name], xyz, seen, moved_px, ransac_px) if moved else None
        if pose is not None:
            poses[(str(name), int(frame))] = pose
        rows.append({"camera": name, "frame": int(frame), "wall_targets": int(len(d)), "drift_px": drift,
                     "moved": moved, "reposed": pose is not None})  # fmt: skip
    return pd.DataFrame(rows, columns=list(MOTION.columns)), poses


def _posed_again(
    camera: Camera, xyz: np.ndarray, uv: np.ndarray, moved_px: float, ransac_px: float
) -> Camera | None:
    """``camera`` posed by PnP on its cell-wall targets (:func:`triaxtrack.refractive_pose.pnp_pose`,
    inliers within ``ransac_px``) where at least ``MIN_REPOSE_TARGETS`` are inliers and their
    median reprojection is within ``moved_px``; else None."""
    if len(xyz) < MIN_REPOSE_TARGETS:
        return None
    posed = pnp_pose(camera, xyz, uv, ransac_px)
    if posed is None or posed[1].sum() < MIN_REPOSE_TARGETS:
        return None
    cam, inlier = posed
    residual = np.hypot(*(project_air(cam, xyz[inlier]) - uv[inlier]).T)
    return cam if float(np.median(residual)) <= moved_px else None


ECCENTRICITY_EVERY = 10  # processed frames between two computations of the marks' eccentricity


def _interpolated_eccentricity(ecc_at: dict[int, pd.DataFrame], frame: int, obs: pd.DataFrame) -> np.ndarray:
    """(N, 2) eccentricity of the observations ``obs`` (``camera, id``) at ``frame``, linear in
    time between the nearest frames before and after it in ``ecc_at`` (frame -> ``camera, id,
    eu, ev``); where only one of them has the observation, its value; where neither, 0."""
    known = np.array(sorted(ecc_at))
    out = np.zeros((len(obs), 2))
    if known.size == 0:
        return out
    before, after = known[known <= frame], known[known >= frame]
    ends = [int(before[-1])] if before.size else []
    ends += [int(after[0])] if after.size and (not ends or after[0] != ends[0]) else []
    keys = obs[["camera", "id"]].reset_index(drop=True)
    vals, weights = [], []
    for f in ends:
        tab = ecc_at[f].drop_duplicates(["camera", "id"])
        v = keys.merge(tab, on=["camera", "id"], how="left")[["eu", "ev"]].to_numpy(float)
        w = 1.0 if len(ends) == 1 else 1.0 - abs(frame - f) / abs(ends[1] - ends[0])
        vals.append(v)
        weights.append(np.where(np.isfinite(v[:, 0]), w, 0.0))
    total = np.sum(weights, axis=0)
    for v, share in zip(vals, weights, strict=True):
        out += np.nan_to_num(v) * (share / np.where(total > 0, total, 1.0))[:, None]
    return out


def triangulate_frames(
    cameras: dict[str, Camera],
    tracks: pd.DataFrame,
    cell: CellOptics,
    in_water: np.ndarray,
    frames: np.ndarray,
    fps: float,
    cfg: TriangulationConfig,
    motion: pd.DataFrame | None = None,
    poses: dict[tuple[str, int], Camera] | None = None,
    mark_radius_mm: pd.Series | None = None,
) -> tuple[pd.DataFrame, pd.DataFrame]:
    """Refractive triangulation of the tracked targets in the water, frame by frame.

    ``tracks``: ``TRACKS`` rows of every camera (reported ones are used); ``in_water``: IDs of
    the pedestal and membrane targets; ``frames``: the frames to solve; ``motion`` and
    ``poses``: :func:`camera_motion` (a moved camera is taken in its new pose where it was
    posed again, and its observations of that frame are left out where not);
    ``mark_radius_mm``: the marks' printed radii, for their eccentricity
    (:func:`triaxtrack.triangulate.triangulate_refracted`), computed at every
    ``ECCENTRICITY_EVERY``-th frame and the last and interpolated between. Returns
    ``(points, residuals)``: ``POINTS`` rows plus ``sigma_mm`` (and the codec shifts where
    ``tracks`` has ``codec_u_px, codec_v_px``: :func:`triaxtrack.codec_lag.corrected_tracks`),
    and ``WATER_RESIDUALS`` rows (every observation offered, whether it was used and why not).
    """
    rep = tracks[(tracks["reason"] == "") & tracks["id"].isin(in_water) & tracks["frame"].isin(frames)]
    columns = ["camera", "frame", "id", "u_px", "v_px", *[c for c in CODEC_COLUMNS if c in tracks.columns]]
    poses = poses or {}
    moved = set()
    if motion is not None and len(motion):
        m = motion[motion["moved"]]
        moved = set(zip(m["camera"], m["frame"], strict=True)) - set(poses)
    frames = np.sort(np.asarray(frames))
    # the marks' eccentricity is computed at every ECCENTRICITY_EVERY-th frame and the last (so a
    # frame two chunks share gets the same), and interpolated in time at the frames between
    eccentric = mark_radius_mm is not None and cfg.eccentricity
    key = np.unique(np.r_[frames[::ECCENTRICITY_EVERY], frames[-1:]]) if eccentric else frames
    solved: dict[int, tuple[pd.DataFrame, pd.DataFrame]] = {}
    ecc_at: dict[int, pd.DataFrame] = {}
    for frame in [*key, *np.setdiff1d(frames, key)]:
        obs = rep[rep["frame"] == frame][columns].reset_index(drop=True)
        if len(obs) == 0:
            continue
        off = np.array([(c, int(frame)) in moved for c in obs["camera"]], bool)
        posed = {name: cam for (name, f), cam in poses.items() if f == frame}
        given = None if frame in key else _interpolated_eccentricity(ecc_at, int(frame), obs[~off])
        res = triangulate_refracted({**cameras, **posed}, obs[~off], cell, cfg, mark_radius_mm, given)
        if eccentric and frame in key:
            ecc_at[int(frame)] = res.residuals[["camera", "id"]].assign(
                eu=res.eccentricity_px[:, 0], ev=res.eccentricity_px[:, 1]
            )
        dropped = obs[off].assign(du_px=np.nan, dv_px=np.nan, used=False, reason="camera moved")
        solved[int(frame)] = (
            res.points.assign(frame=int(frame), time_s=float(frame) / fps),
            pd.concat([res.residuals, dropped], ignore_index=True),
        )
    points = [solved[f][0] for f in sorted(solved)]
    residuals = [solved[f][1] for f in sorted(solved)]
    if not points:
        empty = pd.DataFrame(columns=["frame", "time_s", "id", "x_mm", "y_mm", "z_mm", "n_rays", "rms_px"])
        return empty, pd.DataFrame(columns=list(WATER_RESIDUALS.columns))
    return pd.concat(points, ignore_index=True), pd.concat(residuals, ignore_index=True)


def handover_check(tracked: pd.DataFrame, labels: pd.DataFrame, tol_px: float = 1.0) -> dict:
    """Compare the targets one chunk carried to a frame with the next chunk's labels there.

    ``tracked``: ``TRACKS`` rows of one camera at the shared frame; ``labels``: the next chunk's
    ``LABELS`` rows of that camera and frame. Returns counts: ``both`` (reported by the tracker
    and labelled), ``agree`` (within ``tol_px``), ``disagree`` (farther: a wrong ID on one side),
    ``tracked_only``, ``labelled_only``, and the largest distance and the disagreeing IDs.
    """
    t = tracked[tracked["reason"] == ""].set_index("id")[["u_px", "v_px"]]
    lab = labels[labels["id"] > 0].drop_duplicates("id").set_index("id")[["u_px", "v_px"]]
    common = t.index.intersection(lab.index)
    d = np.hypot(*(t.loc[common].to_numpy() - lab.loc[common].to_numpy()).T) if len(common) else np.zeros(0)
    bad = common[d > tol_px]
    return {
        "both": int(len(common)),
        "agree": int((d <= tol_px).sum()),
        "disagree": int(len(bad)),
        "disagreeing_ids": [int(i) for i in bad[:20]],
        "max_distance_px": float(d.max()) if len(d) else float("nan"),
        "tracked_only": int(len(t.index.difference(lab.index))),
        "labelled_only": int(len(lab.index.difference(t.index))),
    }


LARGE_LOSS_SHARE = 0.5  # a camera-frame reporting less than this share of the camera's best
# frame has lost targets wholesale (flicker, an occluder, a moved or failing camera), not one by one


def large_losses(tracks: pd.DataFrame) -> pd.DataFrame:
    """The camera-frames of ``tracks`` (``TRACKS``; a row repeated, a frame two chunks share, is
    counted once) that report less than ``LARGE_LOSS_SHARE`` of the targets the camera reports
    at its best frame: columns camera, frame, reported, share (of that best frame). The best
    frame, not the median one: a camera whose video is damaged from some frame on loses most of
    its targets at more than half of its frames, and its median frame is then one of those."""
    t = tracks.drop_duplicates(["camera", "frame", "id"], keep="last")
    reported = (t["reason"] == "").groupby([t["camera"], t["frame"]]).sum().rename("reported").reset_index()
    best = reported.groupby("camera")["reported"].transform("max")
    reported["share"] = reported["reported"] / best.where(best > 0)
    return reported[reported["share"] < LARGE_LOSS_SHARE].reset_index(drop=True)


def tracking_summary(tracks: pd.DataFrame) -> pd.DataFrame:
    """Per camera and frame: targets followed, reported, and dropped by reason (wide table)."""
    t = tracks.assign(reason=tracks["reason"].replace("", "reported"))
    out = pd.crosstab([t["camera"], t["frame"]], t["reason"]).reset_index()
    out.columns.name = None
    return out


MOTION = Schema(
    "camera_motion",
    {"camera": "object", "frame": "int64", "wall_targets": "int64", "drift_px": "float64", "moved": "bool",
     "reposed": "bool"},
    ("camera", "frame"),
)  # fmt: skip
"""Per camera and frame (:func:`camera_motion`): tracked cell-wall targets, their median distance
from the projections of their first-frame points, whether the camera has moved, and whether it
was posed again there."""


def _camera_quality(residuals: pd.DataFrame, reference: dict) -> dict[str, dict]:
    """Per camera: the mean reprojection error (pixels) of its observations used, how many were
    used and dropped, and its reference-frame figures (``reference["per_camera"]``)."""
    per_camera = {}
    for name, g in residuals.groupby("camera"):
        u = g["used"].astype(bool)
        e = np.hypot(g.loc[u, "du_px"], g.loc[u, "dv_px"])
        per_camera[str(name)] = {
            "mean_reprojection_px": float(e.mean()) if len(e) else float("nan"),
            "observations_used": int(u.sum()),
            "observations_dropped": int((~u).sum()),
            "reference_frame": reference.get("per_camera", {}).get(name, {}),
        }
    return per_camera


def _frame_quality(
    points: pd.DataFrame, used: pd.DataFrame, err: pd.Series, rep: pd.DataFrame, membrane_ids: np.ndarray
) -> list[dict]:
    """Per processed frame of ``points``: its time (s), the targets tracked (``rep``: reported
    ``TRACKS`` rows) and reconstructed, the membrane dots reconstructed (by 3 rays or more), the
    mean reprojection error (pixels; ``err`` of the ``used`` residuals) and the membrane points'
    median ``sigma_mm``."""
    frames = []
    for frame, pts in points.groupby("frame"):
        mem = pts[pts["id"].isin(membrane_ids)]
        e = err[used["frame"] == frame]
        frames.append({
            "frame": int(frame),
            "time_s": float(pts["time_s"].iloc[0]),
            "targets_tracked": int(rep.loc[rep["frame"] == frame, "id"].nunique()),
            "targets_reconstructed": int(len(pts)),
            "membrane_dots": int(len(membrane_ids)),
            "membrane_dots_reconstructed": int(len(mem)),
            "membrane_dots_3_rays": int((mem["n_rays"] >= 3).sum()),
            "mean_reprojection_px": float(e.mean()) if len(e) else float("nan"),
            "median_sigma_mm": float(mem["sigma_mm"].median()) if len(mem) else float("nan"),
        })  # fmt: skip
    return frames


def _tracking_quality(points: pd.DataFrame, tracks: pd.DataFrame, membrane_ids: np.ndarray) -> dict:
    """The tracking's figures: camera-frames, observations reported and dropped (by reason), the
    membrane dots reconstructed at the first processed frame and kept to the last, and the
    camera-frames that lost targets wholesale (:func:`large_losses`)."""
    first, last = (points["frame"].min(), points["frame"].max()) if len(points) else (0, 0)
    mem0 = set(points.loc[(points["frame"] == first) & points["id"].isin(membrane_ids), "id"])
    mem1 = set(points.loc[(points["frame"] == last) & points["id"].isin(membrane_ids), "id"])
    losses = tracks.loc[tracks["reason"] != "", "reason"].value_counts()
    return {
        "camera_frames": int(tracks[["camera", "frame"]].drop_duplicates().shape[0]),
        "observations_reported": int((tracks["reason"] == "").sum()),
        "observations_dropped": {str(k): int(v) for k, v in losses.items()},
        "membrane_dots_first_frame": len(mem0),
        "membrane_dots_kept_to_last_frame": len(mem0 & mem1),
        "membrane_kept_share": len(mem0 & mem1) / len(mem0) if mem0 else float("nan"),
        "large_losses": [
            {
                "camera": str(r.camera),
                "frame": int(r.frame),
                "reported": int(r.reported),
                "share_of_best": round(float(r.share), 3),
            }
            for r in large_losses(tracks).itertuples(index=False)
        ],
    }


def _motion_quality(motion: pd.DataFrame) -> dict:
    """The camera-motion check (``MOTION`` rows): the largest drift (pixels), overall and per
    camera, and per camera that moved its first moved frame, the frames it was posed again at
    and those left out."""
    moved = motion[motion["moved"].astype(bool)]
    reposed = moved["reposed"].astype(bool).groupby(moved["camera"]).sum()
    left_out = moved["camera"].value_counts() - reposed
    return {
        "max_drift_px": float(motion["drift_px"].max()) if len(motion) else float("nan"),
        "per_camera_max_drift_px": {str(c): float(g.max()) for c, g in motion.groupby("camera")["drift_px"]},
        "moved": {str(c): int(g["frame"].min()) for c, g in moved.groupby("camera")},
        "reposed_frames": {str(c): int(n) for c, n in reposed.items()},
        "left_out_frames": {str(c): int(n) for c, n in left_out.items()},
    }


def timestep_quality(
    reference: dict,
    points: pd.DataFrame,
    residuals: pd.DataFrame,
    tracks: pd.DataFrame,
    motion: pd.DataFrame,
    handovers: list[dict],
    membrane_ids: np.ndarray,
    cameras_left_out: dict[str, str] | None = None,
) -> dict:
    """``quality.json`` of the whole test: the first-frame reconstruction's (``reference``:
    cell, cell frame, air residuals) with the reprojection errors and counts of every processed
    frame, the tracking losses (``large_losses``: camera-frames that lost targets wholesale,
    :func:`large_losses`), the camera-motion check, the chunk handovers and the cameras left out
    of the test (``{camera: why}``, e.g. an unreadable video)."""
    used = residuals[residuals["used"].astype(bool)]
    err = np.hypot(used["du_px"], used["dv_px"])
    return {
        **{k: v for k, v in reference.items() if k not in ("per_camera", "frames", "mean_reprojection_px")},
        "mean_reprojection_px": float(err.mean()) if len(err) else float("nan"),
        "reference_frame": {k: reference.get(k) for k in ("mean_reprojection_px", "frames")},
        "per_camera": _camera_quality(residuals, reference),
        "cameras_left_out": dict(cameras_left_out or {}),
        "frames": _frame_quality(points, used, err, tracks[tracks["reason"] == ""], membrane_ids),
        "tracking": _tracking_quality(points, tracks, membrane_ids),
        "camera_motion": _motion_quality(motion),
        "handovers": {
            "checked": len(handovers),
            "disagreements": int(sum(h.get("disagree", 0) for h in handovers)),
            "details": handovers,
        },
    }


def handover_checks(
    shared: pd.DataFrame, labels: pd.DataFrame, tol_px: float = TrackingConfig.handover_px
) -> list[dict]:
    """:func:`handover_check` of every camera at every frame in ``shared`` (``TRACKS`` rows the
    chunks carried to their next chunk's first frame) against ``labels`` (``LABELS`` of the
    chunk starts). A camera whose next labels are of a later frame is listed, not compared."""
    out = []
    for (camera, frame), got in shared.groupby(["camera", "frame"]):
        lab = labels[(labels["camera"] == camera) & (labels["frame"] == frame)]
        check = {"camera": str(camera), "frame": int(frame)}
        if lab.empty:
            check["note"] = "the next chunk's labels are of a later frame: not compared"
        else:
            check.update(handover_check(got, lab, tol_px))
        out.append(check)
    return out


def observations_table(tracks: pd.DataFrame, residuals: pd.DataFrame) -> pd.DataFrame:
    """``OBSERVATIONS`` of the whole test: every reported tracked target (cell wall too), with
    its reprojection residual ``du_px, dv_px`` where it was offered to the triangulation, ``used``
    (it entered a 3-D point) and ``reason`` (why not; '' when used or not in the water). Where it
    was offered, ``u_px, v_px`` are the pixel the triangulation used (a P frame's membrane dot
    moved by the codec lag, ``triaxtrack.codec_lag``), so that ``u_px + du_px`` is the
    reprojection; elsewhere the tracked centroid. The influences ``ix_mm, iy_mm, iz_mm``
    (``WATER_RESIDUALS``) come along where ``residuals`` has them."""
    res = residuals[[c for c in WATER_RESIDUALS.columns if c in residuals.columns]]
    obs = tracks.loc[tracks["reason"] == "", ["camera", "frame", "id", "u_px", "v_px"]]
    out = obs.merge(res, on=["camera", "frame", "id"], how="left", suffixes=("_tracked", ""))
    for axis in ("u_px", "v_px"):
        out[axis] = out[axis].fillna(out.pop(f"{axis}_tracked"))
    out["used"] = out["used"].astype("boolean").fillna(False).astype(bool)
    out["reason"] = out["reason"].fillna("").astype(str)
    return out


# ---------------------------------------------------------------- the workflow's stages


def run_triangulate_chunk(
    *,
    tracks: Sequence[str | Path],
    lags: Sequence[str | Path],
    cameras: str | Path,
    reference: str | Path,
    reference_points: str | Path,
    kit: str | Path,
    test_yaml: str | Path,
    points: str | Path,
    residuals: str | Path,
    motion: str | Path,
    reconstruction_cfg: dict,
    tracking_cfg: dict,
) -> None:
    """Rule triangulate_chunk: every tracked target in the water at every processed frame of
    one chunk (``tracks``: every camera's), with the ``cameras`` (``cameras.json``) and the cell
    of the first frame (``reference``: its ``quality.json``), each camera's P frames corrected
    by its codec lag (``lags``: :mod:`triaxtrack.codec_lag` files, none for no correction), and
    the cameras checked for motion against the first frame's cell-wall points
    (``reference_points``; :func:`camera_motion`); kit folder ``kit``, ``test_yaml``'s fps,
    ``reconstruction_cfg`` and ``tracking_cfg`` the config's ``reconstruction`` and ``tracking``
    sections. Writes the ``points``, ``residuals`` and ``motion`` tables; prints counts."""
    posed = read_cameras(cameras)
    cell = quality_cell(read_quality(reference))
    design = load_kit_design(kit)
    table = target_table(design)
    fps = read_test_fps(test_yaml)
    tracked = concat_tables(tracks, TRACKS)
    if lags:  # P frames moved by each camera's codec lag (rule measure_codec_lag)
        tracked = corrected_tracks(tracked, read_lag_files(lags))
    first = read_table(reference_points, POINTS)
    wall = first[first["id"].isin(table.loc[table["surface"] == "cell_outer", "id"])]
    moved_px = TrackingConfig.from_dict(tracking_cfg).moved_px
    ransac_px = SfmConfig.from_dict(reconstruction_cfg).ransac_px
    moves, poses = camera_motion(posed, wall, tracked, moved_px, ransac_px)
    in_water = table.loc[table["surface"] != "cell_outer", "id"].to_numpy()
    frames = np.unique(tracked["frame"].to_numpy())
    cfg = TriangulationConfig.from_dict(reconstruction_cfg)
    radii = mark_radii(design, table)
    pts, res = triangulate_frames(posed, tracked, cell, in_water, frames, fps, cfg, moves, poses, radii)
    write_table(pts, points, POINTS)
    write_table(res, residuals, WATER_RESIDUALS)
    write_table(moves, motion, MOTION)
    print(f"{len(frames)} frames, {len(pts)} points, {int(res['used'].sum())} observations used")
    print(pts.groupby("frame").size().describe().to_string())
    moved = moves[moves["moved"]]
    if len(moved):
        print(f"cameras moved (cell-wall drift above {moved_px} px): {sorted(set(moved['camera']))}, "
              f"posed again at {int(moved['reposed'].sum())} of their {len(moved)} frames")  # fmt: skip
    print(f"largest cell-wall drift: {moves['drift_px'].max():.3f} px")


def run_collect_timesteps(
    *,
    chunk_points: Sequence[str | Path],
    chunk_residuals: Sequence[str | Path],
    chunk_motion: Sequence[str | Path],
    tracks: Sequence[str | Path],
    handovers: Sequence[str | Path],
    labels: str | Path,
    reference: str | Path,
    kit: str | Path,
    points: str | Path,
    observations: str | Path,
    tracking: str | Path,
    quality: str | Path,
    handover_px: float,
    cameras_left_out: dict[str, str],
) -> None:
    """Rule collect_timesteps: the chunks of a test in one: their ``chunk_points``,
    ``chunk_residuals``, ``chunk_motion`` (rule triangulate_chunk) and ``tracks``, the
    ``handovers`` (the tracks each chunk carried to the next chunk's first frame) checked
    against the ``labels`` within ``handover_px`` (:func:`handover_checks`); with the first
    frame's ``reference`` (its ``quality.json``), the kit folder ``kit`` and the cameras left out
    of the test (``{camera: why}``). Writes ``points``, ``observations``
    (:func:`observations_table`), ``tracking`` and the test's ``quality``
    (:func:`timestep_quality`); prints its summary."""
    table = target_table(load_kit_design(kit))
    membrane_ids = table.loc[table["surface"] == "membrane", "id"].to_numpy()
    pts = concat_tables(chunk_points, POINTS)
    res = concat_tables(chunk_residuals, WATER_RESIDUALS)
    moves = concat_tables(chunk_motion, MOTION)
    tracked = concat_tables(tracks, TRACKS)
    shared = concat_tables(handovers, TRACKS)
    checks = handover_checks(shared, read_table(labels, LABELS), handover_px)
    first = read_quality(reference)
    report = timestep_quality(first, pts, res, tracked, moves, checks, membrane_ids, cameras_left_out)
    write_table(pts, points, POINTS)
    write_table(observations_table(tracked, res), observations, OBSERVATIONS)
    write_table(tracked, tracking, TRACKS)
    write_json(quality, report)
    print(json.dumps({k: report[k] for k in ("mean_reprojection_px", "tracking", "camera_motion")}, indent=2))
    print(pd.DataFrame(report["frames"]).describe().to_string())
    h = report["handovers"]
    print(f"handovers: {h['checked']} checked, {h['disagreements']} disagreements")
