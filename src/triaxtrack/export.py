"""Exports for other tools: the tables as CSV (:func:`write_csv`) and the membrane surface as a
ParaView time series (:func:`write_paraview_series`: one VTU per frame and a PVD collection).

The surface is the membrane's printed surface through the dots on the kit's grid (missing dots
filled as the volume stage fills them, :func:`~triaxtrack.volume.series.frame_grid`), as quads
between neighbouring rows and columns (periodic in theta), mm, cell frame. Point data:
``displacement_mm`` (3-vector from the reference frame), ``radial_mm`` (its radial part),
``measured`` (1 for a measured dot, 0 for a filled one) and the Green-Lagrange membrane strains
``e_zz``, ``e_tt``, ``e_tz`` (tension positive, :func:`~triaxtrack.volume.strains.strain_field`)
averaged from the cells around each dot.

The workflow's stages: :func:`run_export_csv` and :func:`run_export_paraview`.
"""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from xml.sax.saxutils import quoteattr

import numpy as np
import pandas as pd

from triaxtrack.kit_design import KitDesign
from triaxtrack.volume.config import VolumeConfig
from triaxtrack.volume.grid import MAX_MISSING_SHARE, MembraneGrid
from triaxtrack.volume.series import FAILURES, frame_grid
from triaxtrack.volume.strains import strain_field

STRAIN_NAMES = ("e_zz", "e_tt", "e_tz")


def write_csv(table: pd.DataFrame, path: str | Path) -> None:
    """A table as CSV (comma, '.', a header line, no index; NaN as an empty field), for
    spreadsheets and pandas.read_csv."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    table.to_csv(path, index=False, float_format="%.10g")


@dataclass(frozen=True)
class MembraneFrame:
    """One frame's membrane surface on the kit's grid: ``xyz`` (R, C, 3) mm, bottom row first;
    ``point_data`` per dot (R, C[, 3]) arrays (see the module docstring)."""

    frame: int
    time_s: float
    xyz: np.ndarray
    point_data: dict[str, np.ndarray]


def node_strains(grid: MembraneGrid, grid0: MembraneGrid) -> dict[str, np.ndarray]:
    """(R, C) membrane strains at the dots: the mean of the (up to four) grid cells around each."""
    cells = strain_field(grid, grid0)
    rows = np.asarray(grid.rows)
    cell_row = np.minimum(rows[:-1], rows[1:])
    n_r, n_c = grid.measured.shape
    out = {}
    for name in STRAIN_NAMES:
        pivot = cells.pivot(index="row", columns="col", values=name)
        e = pivot.reindex(index=cell_row, columns=np.asarray(grid.cols)).to_numpy(float)  # (R-1, C)
        acc = np.zeros((n_r, n_c))
        cnt = np.zeros((n_r, n_c))
        for di in (0, 1):  # the cell below (di = 0: cell i-1 ... ) and above each node
            for dj in (0, 1):
                shifted = np.roll(e, dj, axis=1)  # cell j - dj
                acc[di : n_r - 1 + di] += shifted
                cnt[di : n_r - 1 + di] += 1
        out[name] = acc / cnt
    return out


def membrane_frames(
    points: pd.DataFrame,
    table: pd.DataFrame,
    design: KitDesign,
    frames: list[int],
    reference_frame: int,
    t0: float | None = None,
    max_missing_share: float = MAX_MISSING_SHARE,
) -> Iterator[MembraneFrame | tuple[int, str]]:
    """The membrane surface of each of ``frames`` (a :class:`MembraneFrame`), or ``(frame,
    reason)`` for a frame that fails; displacements and strains from ``reference_frame``."""
    if t0 is None:
        t0 = float(design.specimen.membrane_thickness)
    try:
        grid0 = frame_grid(points[points["frame"] == reference_frame], table, design, t0, max_missing_share)[
            0
        ]
    except FAILURES as err:
        for frame in frames:
            yield int(frame), f"reference frame {reference_frame} failed: {err}"
        return
    x0 = np.asarray(grid0.xyz, float)
    radial0 = x0[..., :2] / np.linalg.norm(x0[..., :2], axis=-1, keepdims=True)
    for frame in frames:
        pf = points[points["frame"] == frame]
        try:
            grid = frame_grid(pf, table, design, t0, max_missing_share)[0]
            strains = node_strains(grid, grid0)
        except FAILURES as err:
            yield int(frame), str(err)
            continue
        xyz = np.asarray(grid.xyz, float)
        disp = xyz - x0
        data = {"displacement_mm": disp, "radial_mm": np.sum(disp[..., :2] * radial0, axis=-1),
                "measured": np.asarray(grid.measured, float)} | strains  # fmt: skip
        yield MembraneFrame(int(frame), float(pf["time_s"].iloc[0]), xyz, data)


def measured_membrane_frames(
    kit_dir: str | Path,
    volume_path: str | Path,
    points_path: str | Path,
    volume_config: VolumeConfig,
    max_frames: int | None = None,
) -> Iterator[MembraneFrame | tuple[int, str]]:
    """:func:`membrane_frames` of the frames ``volume.parquet`` measured (at most ``max_frames``
    of them, spread over the test as the report's, :func:`triaxtrack.report.chosen_frames`),
    read from the test's kit, ``volume.parquet`` and ``points.parquet``; ``volume_config``: the
    config's ``volume`` section (membrane thickness, largest missing share)."""
    from triaxtrack.kit import load_kit_design, target_table
    from triaxtrack.tables import POINTS, VOLUME_RESULT, read_table

    design = load_kit_design(kit_dir)
    volume = read_table(volume_path, VOLUME_RESULT)
    frames = volume.loc[volume["reason"] == "", "frame"].tolist()
    if max_frames is not None:
        from triaxtrack.report import chosen_frames

        frames = chosen_frames(frames, max_frames)
    reference = volume["reference_frame"].dropna()
    return membrane_frames(
        read_table(points_path, POINTS), target_table(design), design, frames,
        int(reference.iloc[0]) if len(reference) else -1, t0=volume_config.membrane_thickness_mm,
        max_missing_share=volume_config.max_missing_share,
    )  # fmt: skip


def grid_quads(n_r: int, n_c: int) -> np.ndarray:
    """(M, 4) int64 quads of a (R, C) grid stored row-major, periodic in C (outward for rows
    bottom-up and columns by increasing theta)."""
    i, j = np.meshgrid(np.arange(n_r - 1), np.arange(n_c), indexing="ij")
    a = i * n_c + j
    b = i * n_c + (j + 1) % n_c
    return np.stack([a, b, b + n_c, a + n_c], axis=-1).reshape(-1, 4).astype(np.int64)


def _data_array(name: str, values: np.ndarray) -> str:
    comps = values.shape[1] if values.ndim == 2 else 1
    text = " ".join(f"{v:.7g}" for v in np.asarray(values, float).ravel())
    return (f'        <DataArray type="Float64" Name={quoteattr(name)} NumberOfComponents="{comps}" '
            f'format="ascii">{text}</DataArray>\n')  # fmt: skip


def write_vtu(path: str | Path, mf: MembraneFrame) -> None:
    """One frame's surface as a VTK XML unstructured grid (ASCII, quads, point data)."""
    n_r, n_c = mf.xyz.shape[:2]
    pts = mf.xyz.reshape(-1, 3)
    quads = grid_quads(n_r, n_c)
    point_data = "".join(
        _data_array(k, v.reshape(len(pts), -1) if v.ndim == 3 else v.reshape(-1))
        for k, v in mf.point_data.items()
    )
    conn = " ".join(map(str, quads.ravel()))
    offsets = " ".join(map(str, 4 * np.arange(1, len(quads) + 1)))
    types = " ".join(["9"] * len(quads))  # VTK_QUAD
    Path(path).write_text(
        '<?xml version="1.0"?>\n'
        '<VTKFile type="UnstructuredGrid" version="1.0" byte_order="LittleEndian">\n'
        "  <UnstructuredGrid>\n"
        f'    <Piece NumberOfPoints="{len(pts)}" NumberOfCells="{len(quads)}">\n'
        "      <PointData>\n" + point_data + "      </PointData>\n"
        "      <Points>\n" + _data_array("Points", pts) + "      </Points>\n"
        "      <Cells>\n"
        f'        <DataArray type="Int64" Name="connectivity" format="ascii">{conn}</DataArray>\n'
        f'        <DataArray type="Int64" Name="offsets" format="ascii">{offsets}</DataArray>\n'
        f'        <DataArray type="UInt8" Name="types" format="ascii">{types}</DataArray>\n'
        "      </Cells>\n    </Piece>\n  </UnstructuredGrid>\n</VTKFile>\n"
    )


def write_paraview_series(frames: Iterator[MembraneFrame | tuple[int, str]], out_dir: str | Path) -> dict:
    """Write ``out_dir/frame_<frame>.vtu`` per frame and ``out_dir/membrane.pvd`` (the time series:
    ParaView's File > Open on it gives a time slider in test-clock seconds). Returns
    ``{"written": [frames], "failed": {frame: reason}}``."""
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    entries, written, failed = [], [], {}
    for mf in frames:
        if not isinstance(mf, MembraneFrame):
            failed[int(mf[0])] = mf[1]
            continue
        name = f"frame_{mf.frame:06d}.vtu"
        write_vtu(out_dir / name, mf)
        entries.append(f'    <DataSet timestep="{mf.time_s:.6f}" part="0" file="{name}"/>\n')
        written.append(mf.frame)
    (out_dir / "membrane.pvd").write_text(
        '<?xml version="1.0"?>\n<VTKFile type="Collection" version="0.1" byte_order="LittleEndian">\n'
        "  <Collection>\n" + "".join(entries) + "  </Collection>\n</VTKFile>\n"
    )
    return {"written": written, "failed": failed}


def run_export_csv(*, table: str | Path, csv: str | Path, name: str) -> None:
    """Rule export_csv: the result ``table`` called ``name`` (``volume`` or ``stress_strain``,
    read with its schema) as CSV at ``csv`` (:func:`write_csv`)."""
    from triaxtrack.tables import STRESS_STRAIN, VOLUME_RESULT, read_table

    schema = {"volume": VOLUME_RESULT, "stress_strain": STRESS_STRAIN}[name]
    write_csv(read_table(table, schema), csv)


def run_export_paraview(
    *, kit: str | Path, volume: str | Path, points: str | Path, series: str | Path, volume_cfg: dict
) -> None:
    """Rule export_paraview: the membrane surface of every frame ``volume`` measured
    (:func:`measured_membrane_frames` of the kit folder ``kit`` and ``points``; ``volume_cfg``:
    the config's ``volume`` section) as a ParaView series in the folder ``series``
    (:func:`write_paraview_series`); prints the frames written and those that failed."""
    frames = measured_membrane_frames(kit, volume, points, VolumeConfig.from_dict(volume_cfg))
    done = write_paraview_series(frames, series)
    print(f"{len(done['written'])} frames written; failed: {done['failed']}")
