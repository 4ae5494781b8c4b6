"""Score a results folder against a synthetic test's truth.

``score(results_dir, truth_dir, tolerances)`` compares whatever results exist (the per-camera
calibrations ``calibration/<camera>.json`` and ``cameras.json`` now; points, IDs and volume as
the later stages land) with ``truth/`` and returns a tidy table with one row per metric and
item: ``metric``, ``item`` (a camera name or 'all'), ``value``, ``tolerance`` (NaN when only
reported), ``unit``, ``passed``, ``source`` (the results file scored).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd

from triaxtrack.calibrate import calibrated_camera
from triaxtrack.kit_design import KitDesign
from triaxtrack.layout import RESULTS, TEST_FOLDER, TRUTH
from triaxtrack.optics import Camera, read_cameras
from triaxtrack.score_cameras import score_calibrations, score_cameras
from triaxtrack.score_table import AT_LEAST, COLUMNS, ScoreTolerances, _metric
from triaxtrack.testfolder import read_calibration_folder, read_quality

__all__ = ["AT_LEAST", "COLUMNS", "ScoreTolerances", "_metric", "format_table", "score", "summarise_frames"]


def read_calibrations(folder: str | Path) -> dict[str, Camera]:
    """The calibrated cameras ``folder/<camera>.json`` (identity pose;
    :func:`~triaxtrack.testfolder.read_calibration_folder`)."""
    return {name: calibrated_camera(cal) for name, cal in read_calibration_folder(folder).items()}


# ---------------------------------------------------------------- identification (issue 3)


def true_projections(
    cam: Camera, ids: np.ndarray, frame: int, points: pd.DataFrame, table: pd.DataFrame, design: KitDesign
) -> np.ndarray:
    """(N, 2) exact distorted pixels of targets ``ids`` at ``frame`` in ``cam``, from the truth's
    3-D points: through the air for cell-wall targets, through both walls for the others."""
    from triaxtrack.optics import cell_optics, project_air, project_water

    pts = points[points.frame == frame].set_index("id").reindex(ids)
    xyz = pts[["x_mm", "y_mm", "z_mm"]].to_numpy()
    air = (table.set_index("id").surface.reindex(ids) == "cell_outer").to_numpy()
    uv = np.full((len(ids), 2), np.nan)
    ok = np.isfinite(xyz).all(axis=1)
    if (air & ok).any():
        uv[air & ok] = project_air(cam, xyz[air & ok])
    if (~air & ok).any():
        uv[~air & ok] = project_water(cam, xyz[~air & ok], cell_optics(design))[0]
    return uv


# Reported beside coverage: the share labelled of the seen targets facing the camera within 60
# degrees (in air). Beyond that, dots are foreshortened to half their width or less; on soft 720p
# footage (blur 1 px) they merge with their neighbours and centroids found there were 1-2.5 px off.
FRONTAL_COS = 0.5


def _view_cos(cam: Camera, ids: np.ndarray, frame: int, points: pd.DataFrame) -> np.ndarray:
    """(N,) cosine of the angle between each target's outward radial direction (the cell, the
    pedestals and the membrane are near-cylinders about the z axis) and the line of sight to the
    camera's centre, through the air (the water's refraction ignored); NaN where unknown."""
    xyz = points[points.frame == frame].set_index("id").reindex(ids)[["x_mm", "y_mm", "z_mm"]].to_numpy()
    radial = np.c_[xyz[:, :2], np.zeros(len(xyz))]
    radial /= np.linalg.norm(radial, axis=1, keepdims=True)
    sight = cam.center - xyz
    sight /= np.linalg.norm(sight, axis=1, keepdims=True)
    return np.einsum("ij,ij->i", radial, sight)


def score_identification(
    labels: pd.DataFrame,
    truth_obs: pd.DataFrame,
    points: pd.DataFrame,
    cameras: dict[str, Camera],
    table: pd.DataFrame,
    design: KitDesign,
    tol: ScoreTolerances,
    source: str = RESULTS.labels,
) -> pd.DataFrame:
    """Per camera and labelled frame: wrong IDs, coverage, cell-wall centroid errors.

    ``labels``: rows ``camera, frame, id, u_px, v_px`` (id -1: unlabelled, ignored). An ID is
    wrong when its centroid is more than ``tol.wrong_id_px`` from that target's exact projection
    (from truth observations, or, for a target the truth does not list as seen, from its true 3-D
    point). Coverage: the share of the targets the truth says the camera sees (whole image in the
    frame, facing, not hidden) that are labelled; ``coverage_frontal`` (reported only): the same
    among those facing the camera within 60 degrees (``FRONTAL_COS``). Centroid errors of
    cell-wall dots (seen in air) against their exact projection: median and 95th percentile over
    the camera's labelled dots.
    """
    rows = []
    surface = table.set_index("id").surface
    lab = labels[labels.id > 0]
    for (cam, frame), got in lab.groupby(["camera", "frame"], sort=True):
        item = f"{cam}@{frame}"
        if cam not in cameras:
            rows.append(_metric("camera_unknown", item, np.nan, source=source))
            continue
        seen = truth_obs[(truth_obs.camera == cam) & (truth_obs.frame == frame)].set_index("id")
        true_uv = seen[["u_px", "v_px"]].reindex(got.id).to_numpy().copy()
        missing = ~np.isfinite(true_uv).all(axis=1)
        if missing.any():
            ids = got.id.to_numpy()[missing]
            true_uv[missing] = true_projections(cameras[cam], ids, frame, points, table, design)
        err = np.hypot(got.u_px.to_numpy() - true_uv[:, 0], got.v_px.to_numpy() - true_uv[:, 1])
        wrong = ~(err <= tol.wrong_id_px)
        rows.append(_metric("wrong_ids", item, float(wrong.sum()), tol.wrong_ids, "IDs", source))
        coverage = float(seen.index.isin(got.id).mean()) if len(seen) else np.nan
        rows.append(_metric("coverage", item, coverage, tol.coverage, "", source, minimum=True))
        frontal = seen.index[_view_cos(cameras[cam], seen.index.to_numpy(), frame, points) >= FRONTAL_COS]
        share = float(frontal.isin(got.id).mean()) if len(frontal) else np.nan
        rows.append(_metric("coverage_frontal", item, share, source=source))
        cell = (surface.reindex(got.id) == "cell_outer").to_numpy() & (got.kind == "dot").to_numpy() & ~wrong
        if cell.any():
            med, p95 = float(np.median(err[cell])), float(np.quantile(err[cell], 0.95))
            rows.append(_metric("cell_centroid_median", item, med, tol.cell_centroid_median_px, "px", source))
            rows.append(_metric("cell_centroid_p95", item, p95, tol.cell_centroid_p95_px, "px", source))
    return pd.DataFrame(rows, columns=COLUMNS)


# ---------------------------------------------------------------- reconstruction (issue 4)


def score_points(
    points: pd.DataFrame,
    truth: pd.DataFrame,
    table: pd.DataFrame,
    tol: ScoreTolerances,
    source: str = RESULTS.points,
) -> pd.DataFrame:
    """Per reconstructed frame (item ``all@<frame>``): RMS 3-D error against the truth of the
    membrane dots (``membrane_rms_error``), and reported only: their largest error
    (``membrane_max_error``) and the RMS error of the pedestal CTs and of the cell-wall targets;
    the share of the design's membrane dots reconstructed from 3 or more rays
    (``membrane_3_rays``). ``points``, ``truth``: POINTS tables; ``table``: the kit's targets."""
    rows = []
    surface = table.set_index("id")["surface"]
    n_membrane = int((surface == "membrane").sum())
    for frame, got in points.groupby("frame", sort=True):
        item = f"all@{frame}"
        tru = truth[truth["frame"] == frame].set_index("id")[["x_mm", "y_mm", "z_mm"]]
        known = got["id"].isin(tru.index).to_numpy()
        err = np.full(len(got), np.nan)
        d = got[["x_mm", "y_mm", "z_mm"]].to_numpy()[known] - tru.loc[got["id"][known]].to_numpy()
        err[known] = np.sqrt((d**2).sum(axis=1))
        where = surface.reindex(got["id"]).to_numpy()
        for name, surf, limit in (
            ("membrane_rms_error", ["membrane"], tol.membrane_rms_mm),
            ("pedestal_rms_error", ["pedestal_bottom", "pedestal_top"], np.nan),
            ("cell_wall_rms_error", ["cell_outer"], np.nan),
        ):
            sel = np.isin(where, surf) & np.isfinite(err)
            if sel.any():
                rows.append(_metric(name, item, float(np.sqrt(np.mean(err[sel] ** 2))), limit, "mm", source))
                if name == "membrane_rms_error":
                    rows.append(
                        _metric("membrane_max_error", item, float(err[sel].max()), np.nan, "mm", source)
                    )
        share = float(((where == "membrane") & (got["n_rays"].to_numpy() >= 3)).sum() / max(n_membrane, 1))
        rows.append(_metric("membrane_3_rays", item, share, tol.membrane_3_rays, "", source, minimum=True))
    return summarise_frames(pd.DataFrame(rows, columns=COLUMNS))


def summarise_frames(df: pd.DataFrame) -> pd.DataFrame:
    """Per-frame rows (items ``<what>@<frame>``) cut down to the first and the last frame and, per
    metric, the worst frame (``worst@<frame>``) and a count of the frames that failed
    (``failed frames``, tolerance 0), so that a long test gives a short table."""
    if df.empty:
        return df
    frame = df["item"].str.rsplit("@", n=1).str[1].astype(int)
    first, last = frame.min(), frame.max()
    keep = [df[frame.isin([first, last])]]
    for metric, g in df.groupby("metric", sort=False):
        if g["item"].nunique() <= 2 or g["value"].isna().all():  # all NaN: nothing measured, no worst
            continue
        worst = g.loc[g["value"].idxmin() if metric in AT_LEAST else g["value"].idxmax()]
        keep.append(worst.to_frame().T.assign(item="worst@" + str(worst["item"]).rsplit("@", 1)[1]))
        if g["tolerance"].notna().any():
            failed = float((~g["passed"]).sum())
            row = _metric(metric, "failed frames", failed, 0.0, "frames", g["source"].iloc[0])
            keep.append(pd.DataFrame([row]))
    out = pd.concat(keep, ignore_index=True)
    return out.astype({"value": float, "tolerance": float, "passed": bool})


def score_tracking(
    observations: pd.DataFrame,
    truth: pd.DataFrame,
    tol: ScoreTolerances,
    source: str = RESULTS.observations,
) -> pd.DataFrame:
    """ID swaps: reported observations (every camera and processed frame) farther than
    ``wrong_id_px`` from their own true projection (``id_swaps``, tolerance ``tol.id_swaps``),
    the largest distance, and (reported only) the observations the truth has no projection for
    (a target the simulator counts as hidden or too oblique)."""
    m = observations.merge(truth, on=["camera", "frame", "id"], how="left", suffixes=("", "_true"))
    d = np.hypot(m["u_px"] - m["u_px_true"], m["v_px"] - m["v_px_true"])
    known = np.isfinite(d)
    n_frames = observations["frame"].nunique()
    swaps = float((d[known] > tol.wrong_id_px).sum())
    worst = float(np.max(d[known].to_numpy(), initial=0.0))
    rows = [
        _metric("id_swaps", f"all ({n_frames} frames)", swaps, tol.id_swaps, "observations", source),
        _metric("observation_max_error", "all", worst, np.nan, "px", source),
        _metric("observation_median_error", "all", float(np.median(d[known])) if known.any() else np.nan,
                np.nan, "px", source),
        _metric("observations_without_truth", "all", float((~known).sum()), np.nan, "observations", source),
    ]  # fmt: skip
    return pd.DataFrame(rows, columns=COLUMNS)


def score_kept(
    points: pd.DataFrame, truth: pd.DataFrame, table: pd.DataFrame, tol: ScoreTolerances,
    source: str = RESULTS.points,
) -> pd.DataFrame:  # fmt: skip
    """Share of the membrane dots visible at the start (the truth's first frame: seen by two or
    more cameras) that are still reconstructed at the last processed frame (``membrane_kept``)."""
    membrane = table.loc[table["surface"] == "membrane", "id"]
    first, last = int(points["frame"].min()), int(points["frame"].max())
    t0 = truth[(truth["frame"] == first) & truth["id"].isin(membrane) & (truth["n_rays"] >= 2)]
    end = points[(points["frame"] == last) & points["id"].isin(t0["id"])]
    share = len(end) / max(len(t0), 1)
    return pd.DataFrame([_metric("membrane_kept", f"{first}->{last}", share, tol.membrane_kept, "", source,
                                 minimum=True)], columns=COLUMNS)  # fmt: skip


def score_volume(
    volume: pd.DataFrame, truth: pd.DataFrame, tol: ScoreTolerances, source: str = RESULTS.volume
) -> pd.DataFrame:
    """Per processed frame: the volume's relative error (``volume_error``), the volume change's
    error over the true initial volume (``volume_change_error``) and the axial strain's error,
    cut down by :func:`summarise_frames`; a frame the results do not measure fails. Reported
    only, when ``volume`` has the columns: ``volume_error_sigmas`` = |V - V_true| /
    ``volume_sigma_mm3`` (frames with a finite, positive sigma) and ``measured_fraction_min``,
    the smallest share of membrane dots measured (item ``worst@<frame>``)."""
    missing = sorted(set(volume["frame"]) - set(truth["frame"]))
    if missing:
        raise ValueError(f"{source}: frames {missing[:5]} are not in the truth")
    m = truth.merge(volume, on="frame", how="inner", suffixes=("_true", ""))
    v0t = float(m["volume_mm3_true"].iloc[0]) if len(m) else np.nan
    v0 = float(m["volume_mm3"].iloc[0]) if len(m) else np.nan
    rows = []
    for r in m.itertuples(index=False):
        item = f"all@{r.frame}"
        rows += [
            _metric("volume_error", item, abs(r.volume_mm3 - r.volume_mm3_true) / r.volume_mm3_true,
                    tol.volume_rel, "", source),
            _metric("volume_change_error", item, abs((r.volume_mm3 - v0) - (r.volume_mm3_true - v0t)) / v0t,
                    tol.volume_change_rel, "", source),
            _metric("axial_strain_error", item, abs(r.axial_strain - r.axial_strain_true), tol.axial_strain,
                    "", source),
        ]  # fmt: skip
        sigma = getattr(r, "volume_sigma_mm3", np.nan)
        if np.isfinite(sigma) and sigma > 0 and np.isfinite(r.volume_mm3):
            err = abs(r.volume_mm3 - r.volume_mm3_true) / sigma
            rows.append(_metric("volume_error_sigmas", item, err, unit="sigma", source=source))
    out = summarise_frames(pd.DataFrame(rows, columns=COLUMNS))
    measured = int(np.isfinite(volume["volume_mm3"]).sum())
    share = float(measured) / max(len(volume), 1)
    extra = [_metric("frames_measured", "all", share, 1.0, "", source, minimum=True)]
    fraction = volume["measured_fraction"] if "measured_fraction" in volume else pd.Series(dtype=float)
    if fraction.notna().any():
        k = fraction.astype(float).idxmin()
        item = f"worst@{volume.loc[k, 'frame']}"
        extra.append(_metric("measured_fraction_min", item, float(fraction[k]), source=source))
    return pd.concat([out, pd.DataFrame(extra, columns=COLUMNS)]).reset_index(drop=True)


def score_quality(quality: dict, tol: ScoreTolerances, source: str = RESULTS.quality) -> pd.DataFrame:
    """The mean reprojection error of the reconstruction, over all cameras and per camera."""
    values = {"all": quality["mean_reprojection_px"]}
    values |= {name: q["mean_reprojection_px"] for name, q in sorted(quality.get("per_camera", {}).items())}
    rows = [
        _metric("mean_reprojection", item, float(v), tol.mean_reprojection_px, "px", source)
        for item, v in values.items()
    ]
    return pd.DataFrame(rows, columns=COLUMNS)


def score(results_dir: str | Path, truth_dir: str | Path, tol: ScoreTolerances | None = None) -> pd.DataFrame:
    """Every metric that the results present in ``results_dir`` allow, against ``truth_dir``.

    ``truth_dir`` may be a test folder (its ``truth/`` is used) or the truth folder itself.
    """
    tol = tol or ScoreTolerances()
    results_dir, truth_dir = Path(results_dir), Path(truth_dir)
    if (truth_dir / TEST_FOLDER.truth.root).is_dir():
        truth_dir = truth_dir / TEST_FOLDER.truth.root
    if not (truth_dir / TRUTH.cameras).exists():
        raise ValueError(f"{truth_dir}: no truth here ({TRUTH.cameras} missing)")
    if not results_dir.is_dir():
        raise ValueError(f"{results_dir}: no such results folder")
    parts = []
    truth_cameras = read_cameras(truth_dir / TRUTH.cameras)
    quality_path = results_dir / RESULTS.quality
    quality = read_quality(quality_path) if quality_path.exists() else {}
    calibrations = read_calibrations(results_dir / Path(RESULTS.calibration).parent)
    if calibrations:
        left_out = quality.get("cameras_left_out", {})
        parts.append(score_calibrations(calibrations, truth_cameras, tol, left_out=left_out))
    if (results_dir / RESULTS.cameras).exists():
        cameras = read_cameras(results_dir / RESULTS.cameras)
        parts.append(score_cameras(cameras, truth_cameras, tol, left_out=quality.get("cameras_left_out", {})))
    if (results_dir / RESULTS.labels).exists():
        parts.append(_score_labels(results_dir / RESULTS.labels, truth_dir, truth_cameras, tol))
    if quality:
        parts.append(score_quality(quality, tol))
    if (results_dir / RESULTS.points).exists():
        parts.append(_score_points(results_dir / RESULTS.points, truth_dir, tol))
    if (results_dir / RESULTS.tracking).exists() and (results_dir / RESULTS.observations).exists():
        parts.append(_score_tracking(results_dir / RESULTS.observations, truth_dir, tol))
    if (results_dir / RESULTS.tracking).exists():
        parts.append(_score_cameras_footage(results_dir))
    if (results_dir / RESULTS.volume).exists():
        from triaxtrack.tables import VOLUME, read_table

        parts.append(score_volume(read_table(results_dir / RESULTS.volume, VOLUME),
                                  read_table(truth_dir / TRUTH.volume, VOLUME), tol))  # fmt: skip
    if (results_dir / RESULTS.stress_strain).exists() and (truth_dir / TRUTH.stress_strain).exists():
        from triaxtrack.stress.score import score_stress_files

        parts.append(score_stress_files(results_dir, truth_dir, tol))
    if not parts:
        return pd.DataFrame(columns=COLUMNS)
    return pd.concat(parts, ignore_index=True)


def _score_labels(
    path: Path, truth_dir: Path, cameras: dict[str, Camera], tol: ScoreTolerances
) -> pd.DataFrame:
    """Identification scores of a results folder's labels.parquet (the kit is the test's kit/)."""
    from triaxtrack.kit import target_table
    from triaxtrack.tables import LABELS, OBSERVATIONS, POINTS, read_table

    design = _test_kit(truth_dir)
    return score_identification(
        read_table(path, LABELS),
        read_table(truth_dir / TRUTH.observations, OBSERVATIONS),
        read_table(truth_dir / TRUTH.points, POINTS),
        cameras,
        target_table(design),
        design,
        tol,
        path.name,
    )


def _test_kit(truth_dir: Path) -> KitDesign:
    """The design of a test's kit/ (beside truth/)."""
    from triaxtrack.kit import load_kit_design

    kit = truth_dir.parent / TEST_FOLDER.kit
    if not (kit / "kit.json").exists():
        raise ValueError(f"{truth_dir}: the test's kit/ (beside truth/) is needed to score targets")
    return load_kit_design(kit)


def _score_points(path: Path, truth_dir: Path, tol: ScoreTolerances) -> pd.DataFrame:
    """Reconstruction scores of a results folder's points.parquet."""
    from triaxtrack.kit import target_table
    from triaxtrack.tables import POINTS, read_table

    table = target_table(_test_kit(truth_dir))
    truth = read_table(truth_dir / TRUTH.points, POINTS)
    points = read_table(path, POINTS)
    parts = [score_points(points, truth, table, tol, path.name)]
    if points["frame"].nunique() > 1:
        parts.append(score_kept(points, truth, table, tol, path.name))
    return pd.concat(parts, ignore_index=True)


def _score_tracking(path: Path, truth_dir: Path, tol: ScoreTolerances) -> pd.DataFrame:
    """ID swaps of a results folder's observations.parquet (every tracked frame)."""
    from triaxtrack.tables import OBSERVATIONS, read_table

    truth = read_table(truth_dir / TRUTH.observations, OBSERVATIONS)
    return score_tracking(read_table(path, OBSERVATIONS), truth, tol, path.name)


def _score_cameras_footage(results_dir: Path) -> pd.DataFrame:
    """Per-camera centroid uncertainty and tracked share of a results folder's tracking.parquet
    (:mod:`triaxtrack.camera_report`; reported only)."""
    from triaxtrack.camera_report import camera_quality, score_camera_quality
    from triaxtrack.tables import TRACKS, read_table

    tracks = read_table(results_dir / RESULTS.tracking, TRACKS)
    return score_camera_quality(camera_quality(tracks), RESULTS.tracking)


def format_table(df: pd.DataFrame) -> str:
    """Human-readable score table."""
    if df.empty:
        return (
            "nothing to score: the results folder holds none of calibration/*.json, cameras.json, "
            "labels.parquet, quality.json, points.parquet, tracking.parquet, volume.parquet"
        )
    lines = [f"{'metric':<26} {'item':<10} {'value':>12} {'tolerance':>10} {'unit':<4} result source"]
    for r in df.itertuples(index=False):
        tol = "" if pd.isna(r.tolerance) else f"{r.tolerance:.4g}"
        val = "missing" if pd.isna(r.value) else f"{r.value:.5g}"
        result = "ok  " if r.passed else "FAIL"
        lines.append(f"{r.metric:<26} {r.item:<10} {val:>12} {tol:>10} {r.unit:<4} {result}   {r.source}")
    lines.append(f"{int(df.passed.sum())} of {len(df)} within tolerance")
    return "\n".join(lines)
