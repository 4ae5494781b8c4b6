"""Volume and strains of every frame of a test, and the PLY meshes of a few (mm, mm^3); the
workflow's stage, from the points to the tables and meshes (:func:`run_measure_volume`)."""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import replace
from pathlib import Path

import numpy as np
import pandas as pd

from triaxtrack.influence import CODEC_SHIFT_COLUMNS, INFLUENCE_COLUMNS
from triaxtrack.kit import load_kit_design, target_table
from triaxtrack.kit_design import KitDesign
from triaxtrack.tables import (
    OBSERVATIONS,
    POINTS,
    STRAINS,
    VOLUME_RESULT,
    conform,
    read_table,
    read_table_batches,
    table_columns,
    write_table,
)
from triaxtrack.volume.cap import TopCap, top_cap, top_cap_from_membrane
from triaxtrack.volume.config import VolumeConfig
from triaxtrack.volume.grid import (
    MAX_MISSING_SHARE,
    WARN_MISSING_SHARE,
    FaceEnds,
    MembraneGrid,
    face_ends,
    grid_ids,
    membrane_grid,
)
from triaxtrack.volume.local import local_strains
from triaxtrack.volume.mesh import (
    REFINE_LEVELS,
    VolumeResult,
    check_mesh,
    closed_mesh,
    membrane_thickness,
    specimen_volume,
    write_ply,
)
from triaxtrack.volume.strains import strain_field
from triaxtrack.volume.uncertainty import (
    VolumeUncertainty,
    height_gradient,
    height_sigma_mm,
    volume_gradient,
    volume_uncertainty,
)

FAILURES = (ValueError, np.linalg.LinAlgError)  # what makes one frame fail (NaN and a reason)


def measured_share(points: pd.DataFrame, table: pd.DataFrame) -> float:
    """Share of the kit's membrane dots with a finite position in ``points`` (one frame)."""
    ids = table.loc[table["surface"] == "membrane", "id"]
    ok = points[points["id"].isin(ids)].dropna(subset=["x_mm", "y_mm", "z_mm"])
    return float(ok["id"].nunique() / max(len(ids), 1))


def frame_grid(
    points: pd.DataFrame, table: pd.DataFrame, design: KitDesign, t0: float, max_missing_share: float
) -> tuple[MembraneGrid, TopCap, FaceEnds]:
    """One frame's top cap (from its coded targets, else from the membrane's top rows), face
    rings and filled membrane grid (ValueError when it fails)."""
    try:
        cap = top_cap(points, table, design)
    except ValueError:
        cap = top_cap_from_membrane(points, table, design)
    ends = face_ends(design, cap, t0)
    return membrane_grid(points, table, max_missing_share, ends), cap, ends


def _measure_frame(
    pf: pd.DataFrame,
    table: pd.DataFrame,
    design: KitDesign,
    t0: float,
    max_missing_share: float,
    grid0: MembraneGrid | None,
    thickness_model: str,
    levels: tuple[int, int],
    check: bool,
    influence: pd.DataFrame | None = None,
) -> tuple[MembraneGrid, TopCap, VolumeResult, VolumeUncertainty, object]:
    """One frame's (``pf``) filled grid, top cap, soil volume (mm^3), its uncertainty (with the
    frame's observations' ``influence`` and the points' codec shifts where ``pf`` has them,
    :func:`volume_uncertainty`) and whether its dot mesh is
    watertight (<NA> unless ``check``), the membrane thinned from ``t0`` (mm) against the
    reference grid ``grid0`` (None: this frame is the reference). Raises ``FAILURES`` when the
    frame cannot be measured."""
    grid, cap, ends = frame_grid(pf, table, design, t0, max_missing_share)
    thickness = membrane_thickness(grid, grid if grid0 is None else grid0, t0, model=thickness_model)
    res = specimen_volume(grid, cap, thickness, levels)
    gradient = height = None
    shifts = pf[["id", *CODEC_SHIFT_COLUMNS]] if all(c in pf.columns for c in CODEC_SHIFT_COLUMNS) else None
    if influence is not None or shifts is not None:
        cap_ids = table.loc[table["surface"] == "pedestal_top", "id"]
        on_cap = pf.loc[pf["id"].isin(cap_ids)].dropna(subset=["x_mm", "y_mm", "z_mm"])["id"].unique()
        gradient = volume_gradient(grid, grid_ids(table), cap, on_cap, res.volume_mm3)
        height = height_gradient(cap, on_cap)
    unc = volume_uncertainty(grid, ends, cap, res.volume_mm3, influence, gradient, shifts)
    unc = replace(unc, height_mm=height_sigma_mm(cap, influence, height, shifts))
    watertight = check_mesh(*closed_mesh(grid, cap))["watertight"] if check else pd.NA
    return grid, cap, res, unc, watertight


def _frame_warning(
    share: float, unc: VolumeUncertainty, cap: TopCap, k0: int, first: int, warn_missing_share: float
) -> str:
    """Why a measured frame's volume is less sure than usual ('' when it is not): more than
    ``warn_missing_share`` of its membrane dots filled (``share``: the share measured), no
    leave-out place for the fill's uncertainty, the top cap not from its coded targets, or the
    reference frame ``k0`` not the test's ``first``."""
    warnings = []
    if 1 - share > warn_missing_share:
        warnings.append(f"{1 - share:.1%} of the membrane dots filled")
    if not np.isfinite(unc.fill_mm3):
        warnings.append("the fill's uncertainty is unknown (no leave-out place)")
    if cap.source != "coded targets":
        warnings.append(f"top cap from the {cap.source} (its coded targets not measured)")
    if k0 != first:
        warnings.append(f"strains relative to frame {k0}: the first frame {first} failed")
    return "; ".join(warnings)


def _volume_figures(
    res: VolumeResult, unc: VolumeUncertainty, watertight: object, ref: tuple[int, MembraneGrid, float, float]
) -> dict:
    """A measured frame's :data:`~triaxtrack.tables.VOLUME_RESULT` volumes (mm^3), height (mm) and
    specimen strains (compression positive) against the reference ``ref`` (frame, grid, H0 in mm,
    V0 in mm^3)."""
    k0, _, h0, v0 = ref
    axial = (h0 - res.height_mm) / h0
    volumetric = (v0 - res.volume_mm3) / v0
    return {
        "volume_mm3": res.volume_mm3, "axial_strain": axial, "volumetric_strain": volumetric,
        "height_mm": res.height_mm, "axial_sigma": unc.height_mm / h0,
        "radial_strain": (volumetric - axial) / 2,
        "volume_change_mm3": res.volume_mm3 - v0, "mesh_volume_mm3": res.mesh_volume_mm3,
        "chordal_mm3": res.chordal_mm3, "membrane_mm3": res.membrane_mm3,
        "volume_sigma_mm3": unc.sigma_mm3, "filled_dots": res.filled_dots, "watertight": watertight,
        "reference_frame": k0,
    }  # fmt: skip


def _strain_table(strain_parts: list[pd.DataFrame]) -> pd.DataFrame:
    """The measured frames' membrane strains (:data:`~triaxtrack.tables.STRAINS` columns), sorted
    by frame, row and column; empty, with the columns' dtypes, when no frame was measured."""
    strain_cols = ["frame", "time_s", "row", "col", "theta_rad", "z_mm", "e_zz", "e_tt", "e_tz"]
    strains = pd.concat(strain_parts, ignore_index=True)[strain_cols] if strain_parts else (
        pd.DataFrame({c: pd.Series(dtype="int64" if c in ("frame", "row", "col") else "float64")
                      for c in strain_cols})
    )  # fmt: skip
    return strains.sort_values(["frame", "row", "col"], kind="stable").reset_index(drop=True)


def volume_series(
    points: pd.DataFrame,
    table: pd.DataFrame,
    design: KitDesign,
    t0: float | None = None,
    max_missing_share: float = MAX_MISSING_SHARE,
    levels: tuple[int, int] = REFINE_LEVELS,
    check: bool = True,
    thickness_model: str = "area",
    warn_missing_share: float = WARN_MISSING_SHARE,
    influence: pd.DataFrame | None = None,
) -> tuple[pd.DataFrame, pd.DataFrame]:
    """Volume and membrane strains of every frame of ``points`` (columns ``frame, time_s, id,
    x_mm, y_mm, z_mm``, optionally ``sigma_mm``; mm, cell frame).

    The reference is the first frame that succeeds (``reference_frame``; normally the first
    frame): its height H0 and volume V0, and its dot grid, where the membrane has the thickness
    ``t0`` (mm; default the design's ``specimen.membrane_thickness``). Returns ``(volume,
    strains)``: ``volume`` has the :data:`~triaxtrack.tables.VOLUME_RESULT` columns
    (``axial_strain = (H0 - H) / H0``, ``volumetric_strain = (V0 - V) / V0``, compression
    positive, ``radial_strain = (volumetric - axial) / 2``, the local axial and radial strains
    over the middle third (:func:`~triaxtrack.volume.local.local_strains`, from the measured
    dots only), ``volume_change_mm3 = V - V0``,
    ``volume_sigma_mm3`` the 1-sigma standard uncertainty of ``volume_mm3``
    (:mod:`triaxtrack.volume.uncertainty`; with ``influence``, rows ``camera, frame, id, ix_mm,
    iy_mm, iz_mm`` of the used observations, it counts what each camera's observations share),
    ``measured_fraction`` the share of membrane dots measured); ``strains`` has the
    :data:`~triaxtrack.tables.STRAINS` columns for every frame
    that succeeded (filled dots included). Missing dots are filled (:func:`membrane_grid`); a
    frame with more than ``warn_missing_share`` missing gets a ``warning``; one that fails
    (more than ``max_missing_share`` missing, fewer than 3 cap targets, ...) gets NaN values,
    ``filled_dots``/``watertight`` <NA> and its ``reason``. ``check`` runs :func:`check_mesh`
    on each frame's dot mesh (``watertight``); ``thickness_model`` is passed to
    :func:`membrane_thickness`. Never raises for a frame's data.
    """
    if t0 is None:
        t0 = float(design.specimen.membrane_thickness)
    frames = sorted(points["frame"].unique())
    membrane_ids = table.loc[table["surface"] == "membrane", "id"].to_numpy()
    rows: list[dict] = []
    strain_parts: list[pd.DataFrame] = []
    ref: tuple[int, MembraneGrid, float, float] | None = None
    ref_points = points.iloc[:0]
    if influence is not None:  # one frame's rows are a slice (no copy per frame)
        influence = influence.sort_values("frame", kind="stable", ignore_index=True)
        at = influence["frame"].to_numpy()
    for frame in frames:
        pf = points[points["frame"] == frame]
        time_s = float(pf["time_s"].iloc[0])
        share = measured_share(pf, table)
        row = {"frame": int(frame), "time_s": time_s, "measured_fraction": share}
        mine = None
        if influence is not None:
            mine = influence.iloc[np.searchsorted(at, frame) : np.searchsorted(at, frame, "right")]
        try:
            grid0 = None if ref is None else ref[1]
            grid, cap, res, unc, watertight = _measure_frame(
                pf, table, design, t0, max_missing_share, grid0, thickness_model, levels, check,
                mine,
            )  # fmt: skip
            if ref is None:
                ref = (int(frame), grid, res.height_mm, res.volume_mm3)
                ref_points = pf
            strains = strain_field(grid, ref[1])
        except FAILURES as err:
            rows.append(row | {"reason": str(err)})
            continue
        warning = _frame_warning(share, unc, cap, ref[0], frames[0], warn_missing_share)
        rows.append(
            row
            | _volume_figures(res, unc, watertight, ref)
            | {"warning": warning, "reason": ""}
            | local_strains(pf, ref_points, ref[2], membrane_ids)
        )
        strain_parts.append(strains.assign(frame=int(frame), time_s=time_s))
    vol = pd.DataFrame(rows).reindex(columns=list(VOLUME_RESULT.columns))
    vol[["warning", "reason"]] = vol[["warning", "reason"]].fillna("")
    return conform(vol, VOLUME_RESULT, "volume_series"), _strain_table(strain_parts)


def volume_meshes(
    points: pd.DataFrame,
    table: pd.DataFrame,
    design: KitDesign,
    frames: list[int],
    out_dir: str | Path,
    t0: float | None = None,
    thickness_model: str = "area",
    refine: int = 2,
    max_missing_share: float = MAX_MISSING_SHARE,
    reference_frame: int | None = None,
) -> Iterator[tuple[int, Path | None, str]]:
    """Write the soil surface (the membrane's inner surface closed by the pedestal faces, mm,
    cell frame) of each of ``frames`` as ``out_dir/frame_<frame>.ply``; yields ``(frame, path,
    '')``, or ``(frame, None, reason)`` for a frame that fails (nothing written). The reference
    for the membrane's thinning is ``reference_frame`` (:func:`volume_series`'
    ``reference_frame``; None when no frame succeeded: every frame is skipped)."""
    if t0 is None:
        t0 = float(design.specimen.membrane_thickness)
    grid0, ref_error = None, "no frame of the test succeeds"
    if reference_frame is not None:
        try:
            pk = points[points["frame"] == reference_frame]
            grid0 = frame_grid(pk, table, design, t0, max_missing_share)[0]
        except FAILURES as err:
            ref_error = f"reference frame {reference_frame} failed: {err}"
    for frame in frames:
        if grid0 is None:
            yield int(frame), None, ref_error
            continue
        try:
            grid, cap, _ = frame_grid(points[points["frame"] == frame], table, design, t0, max_missing_share)
            thickness = membrane_thickness(grid, grid0, t0, model=thickness_model)
            vertices, triangles = closed_mesh(grid, cap, refine, thickness, inner=True)
        except FAILURES as err:
            yield int(frame), None, str(err)
            continue
        path = Path(out_dir) / f"frame_{int(frame):06d}.ply"
        write_ply(path, vertices, triangles)
        yield int(frame), path, ""


def observation_influences(path: str | Path) -> pd.DataFrame | None:
    """The used observations' rows ``camera, frame, id, ix_mm, iy_mm, iz_mm`` of an
    ``observations.parquet`` (:data:`~triaxtrack.tables.WATER_RESIDUALS`' influences), None when
    it has no influences (written before they were). Read in batches, kept compact (the camera
    a category, the influences float32: about 30 bytes an observation)."""
    cols = ["camera", "frame", "id", "used", *INFLUENCE_COLUMNS]
    if not set(cols) <= set(table_columns(path)):
        return None
    parts = []
    for obs in read_table_batches(path, OBSERVATIONS, cols):
        psi = obs[list(INFLUENCE_COLUMNS)].to_numpy(float)
        keep = obs["used"].astype(bool).to_numpy() & np.isfinite(psi).all(axis=1)
        part = obs.loc[keep, ["camera", "frame", "id"]].astype({"camera": "category"})
        compact = {c: psi[keep, k].astype(np.float32) for k, c in enumerate(INFLUENCE_COLUMNS)}
        parts.append(part.assign(**compact))
    empty = pd.DataFrame(columns=["camera", "frame", "id", *INFLUENCE_COLUMNS])
    return pd.concat(parts or [empty], ignore_index=True).astype({"camera": "category"})


def run_measure_volume(
    *,
    points: str | Path,
    kit: str | Path,
    volume: str | Path,
    strains: str | Path,
    meshes: str | Path,
    volume_cfg: dict,
    observations: str | Path | None = None,
) -> None:
    """Rule measure_volume: :func:`volume_series` of every frame of ``points`` with the kit
    folder ``kit`` (``volume_cfg``: the config's ``volume`` section) and the influences of the
    ``observations`` (``observations.parquet``; :func:`observation_influences`), written to ``volume`` and
    ``strains``; the PLY meshes of ``mesh_frames`` (:class:`VolumeConfig`) measured frames spread over the
    test in the folder ``meshes`` (:func:`volume_meshes`); prints the meshes, a summary and the
    frames with warnings or failed."""
    from triaxtrack.report.common import chosen_frames

    cfg = VolumeConfig.from_dict(volume_cfg)
    design = load_kit_design(kit)
    table = target_table(design)
    pts = read_table(points, POINTS)
    influence = None if observations is None else observation_influences(observations)
    if influence is None:
        print("no observation influences: the volume's uncertainty takes the points as independent")
    t0, model = cfg.membrane_thickness_mm, cfg.thickness_model
    share = cfg.max_missing_share
    result, strain = volume_series(
        pts, table, design, t0=t0, max_missing_share=share, thickness_model=model,
        warn_missing_share=cfg.warn_missing_share, influence=influence,
    )  # fmt: skip
    write_table(result, volume, VOLUME_RESULT)
    write_table(strain, strains, STRAINS)
    good = result.loc[result["reason"] == "", "frame"].tolist()
    out = Path(meshes)
    out.mkdir(parents=True, exist_ok=True)
    chosen = chosen_frames(good, cfg.mesh_frames)
    reference = result["reference_frame"].dropna()
    written = volume_meshes(
        pts, table, design, chosen, out, t0=t0, thickness_model=model, max_missing_share=share,
        reference_frame=int(reference.iloc[0]) if len(reference) else None,
    )  # fmt: skip
    for frame, path, reason in written:
        print(f"frame {frame}: {path or 'no mesh: ' + reason}")
    print(result.drop(columns=["warning", "reason"]).describe().T.to_string())
    warned = result[result["warning"] != ""]
    if len(warned):
        print(f"{len(warned)} frames with warnings:\n{warned[['frame', 'warning']].to_string(index=False)}")
    failed = result[result["reason"] != ""]
    if len(failed):
        print(f"{len(failed)} frames failed:\n{failed[['frame', 'reason']].to_string(index=False)}")
