"""Parquet table schemas, defined once and checked on every write and read.

The result and truth tables of ``test-folder.md``. Units and conventions where the data is born:
positions in millimetres in the cell frame; pixels in OpenCV convention (the centre of the
top-left pixel is (0, 0)), distorted image coordinates; times in seconds from the first frame;
strains dimensionless, compression positive. In a synthetic test's ``truth/points.parquet``
every target has a row at every frame, with ``n_rays`` the number of cameras that see it; rows
with ``n_rays < 2`` are not expected to be reconstructed.
"""

from __future__ import annotations

from collections.abc import Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path

import pandas as pd
import pyarrow.parquet as pq


@dataclass(frozen=True)
class Schema:
    """Column names and dtypes of a table, and the key it is sorted by."""

    name: str
    columns: dict[str, str]
    key: tuple[str, ...]


POINTS = Schema(
    "points",
    {"frame": "int64", "time_s": "float64", "id": "int64", "x_mm": "float64", "y_mm": "float64",
     "z_mm": "float64", "n_rays": "int64", "rms_px": "float64"},
    ("frame", "id"),
)  # fmt: skip
"""Triangulated targets, one row per target per processed frame (mm, cell frame). Extra columns:
``sigma_mm`` (the 3-D standard uncertainty, the square root of the covariance's trace) and, where
the codec correction ran, ``codec_ux_mm ... codec_vz_mm`` (``triaxtrack.influence``: the point's
shift by the correction's uncertainty along the images' u, then v axis, shared by every camera)."""
OBSERVATIONS = Schema(
    "observations",
    {"camera": "object", "frame": "int64", "id": "int64", "u_px": "float64", "v_px": "float64"},
    ("camera", "frame", "id"),
)
VOLUME = Schema(
    "volume",
    {"frame": "int64", "time_s": "float64", "volume_mm3": "float64", "axial_strain": "float64",
     "volumetric_strain": "float64"},
    ("frame",),
)  # fmt: skip
"""Specimen volume and strains per frame (the truth's ``truth/volume.parquet`` and the leading
columns of the measured one): soil volume (mm^3), axial and volumetric strain (dimensionless,
compression positive) relative to the reference frame."""
VOLUME_RESULT = Schema(
    "volume_result",
    VOLUME.columns | {
        "height_mm": "float64", "axial_sigma": "float64", "radial_strain": "float64",
        "local_axial_strain": "float64", "local_axial_sigma": "float64", "local_radial_strain": "float64",
        "local_radial_sigma": "float64",
        "volume_change_mm3": "float64",
        "mesh_volume_mm3": "float64", "chordal_mm3": "float64", "membrane_mm3": "float64",
        "volume_sigma_mm3": "float64", "measured_fraction": "float64", "filled_dots": "Int64",
        "watertight": "boolean", "reference_frame": "Int64", "warning": "object", "reason": "object",
    },
    ("frame",),
)  # fmt: skip
"""The measured ``results/<test>/volume.parquet`` (``triaxtrack.volume.volume_series``): the
:data:`VOLUME` columns, then ``height_mm`` (top face centre above the bottom face),
``axial_sigma`` the standard uncertainty of ``axial_strain`` from this frame's height (its
top cap's fit, each camera's observations taken as sharing their errors, and the codec's part
as ``volume_sigma_mm3``'s, over H0; the reference height's own error, shared by every frame, is
not in it),
``radial_strain = (volumetric - axial) / 2``; ``local_axial_strain`` and ``local_radial_strain``
over the middle third of the reference height from the measured membrane dots there, with their
standard errors ``local_axial_sigma``, ``local_radial_sigma`` (``triaxtrack.volume.local``; no
bedding errors at the ends: the gauge length of a local transducer);
``volume_change_mm3 = V - V0``, the volume's parts
``mesh_volume_mm3, chordal_mm3, membrane_mm3``; ``volume_sigma_mm3`` the 1-sigma standard
uncertainty of ``volume_mm3`` (mm^3: the measured dots' and the top cap's errors, each camera's
observations taken as sharing theirs, and the fill's leave-out error, in quadrature; NaN when the
fill's part cannot be estimated; ``triaxtrack.volume.uncertainty``);
``measured_fraction`` the share (0-1) of the membrane's dots measured in the frame, each dot
standing for the same design area (known for failed frames too); ``filled_dots`` the dots
filled; ``watertight`` Open3D's check of the dot mesh; ``reference_frame`` the frame the strains
are relative to (the first that succeeded); ``warning`` '' or why a measured frame deserves a
look (many dots filled, unknown fill uncertainty, a later reference); ``reason`` '' or why the
frame has no volume (its values NaN, the nullable ones <NA>)."""

FRAME_MAP = Schema(
    "frame_map",
    {"frame": "int64", "time_s": "float64", "video_index": "int64", "missing": "bool", "reason": "object",
     "video_time_s": "float64"},
    ("frame",),
)  # fmt: skip
"""One camera's frame map (``triaxtrack.frames``): test frame k at ``time_s = k / fps``;
``video_index`` the 0-based index in the camera's video file (-1 when ``missing``); ``reason``
``before_start``, ``dropped``, ``after_end`` or ''; ``video_time_s`` the test-clock time the
video frame was taken (NaN when missing)."""


def conform(df: pd.DataFrame, schema: Schema, source: str = "table") -> pd.DataFrame:
    """A copy of ``df`` with exactly the schema's leading columns and dtypes, sorted by its key.

    Extra columns are kept after the schema's. Raises ValueError naming ``source`` when a
    column is missing or cannot take its dtype.
    """
    missing = [c for c in schema.columns if c not in df.columns]
    if missing:
        raise ValueError(f"{source}: {schema.name} table lacks columns {missing}")
    out = df.copy()
    for col, dtype in schema.columns.items():
        try:
            if dtype == "object":
                out[col] = out[col].astype(str).astype(object)
            else:
                if dtype.startswith("int") and out[col].isna().any():
                    raise ValueError(f"column {col} has missing values")
                out[col] = out[col].astype(dtype)
        except (TypeError, ValueError) as err:
            raise ValueError(f"{source}: {schema.name} column {col!r} is not {dtype}: {err}") from err
    extra = [c for c in out.columns if c not in schema.columns]
    out = out[list(schema.columns) + extra]
    if not schema.key:
        return out.reset_index(drop=True)
    return out.sort_values(list(schema.key), kind="stable").reset_index(drop=True)


def write_table(df: pd.DataFrame, path: str | Path, schema: Schema) -> None:
    """Check ``df`` against ``schema``, sort it by the key and write it as Parquet."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    conform(df, schema, str(path)).to_parquet(path, index=False)


def read_table(path: str | Path, schema: Schema) -> pd.DataFrame:
    """Read a Parquet table and check it against ``schema`` (ValueError naming the file)."""
    path = Path(path)
    try:
        df = pd.read_parquet(path)
    except (OSError, ValueError) as err:
        raise ValueError(f"{path}: cannot read {schema.name} table: {err}") from err
    return conform(df, schema, str(path))


def table_columns(path: str | Path) -> list[str]:
    """The column names of a Parquet table, without reading it (ValueError naming the file)."""
    try:
        return list(pq.read_schema(path).names)
    except (OSError, ValueError) as err:
        raise ValueError(f"{path}: cannot read a table's columns: {err}") from err


def read_table_batches(
    path: str | Path, schema: Schema, columns: Sequence[str], rows: int = 200_000
) -> Iterator[pd.DataFrame]:
    """A large Parquet table's ``columns`` in batches of about ``rows`` rows, in the file's order,
    each checked against the schema's columns among them (a few columns of millions of rows,
    never all in memory as Python objects at once). ValueError naming the file when it cannot be
    read or lacks one of ``columns``."""
    try:
        f = pq.ParquetFile(path)
    except (OSError, ValueError) as err:
        raise ValueError(f"{path}: cannot read {schema.name} table: {err}") from err
    missing = [c for c in columns if c not in f.schema_arrow.names]
    if missing:
        raise ValueError(f"{path}: {schema.name} table lacks columns {missing}")
    sub = Schema(schema.name, {c: t for c, t in schema.columns.items() if c in columns}, ())
    for batch in f.iter_batches(batch_size=rows, columns=list(columns)):
        yield conform(batch.to_pandas(), sub, str(path))


LABELS = Schema(
    "labels",
    {"camera": "object", "frame": "int64", "id": "int64", "kind": "object", "group": "object",
     "u_px": "float64", "v_px": "float64", "u_undist_px": "float64", "v_undist_px": "float64",
     "area_px": "float64", "roundness": "float64", "quality": "float64", "reason": "object"},
    ("camera", "frame", "id", "v_px", "u_px"),
)  # fmt: skip
"""Targets detected in one camera frame (``triaxtrack.identify``): ``id`` the Table 1 ID, -1
where not labelled (``reason`` says why); ``kind`` 'coded' or 'dot'; ``group`` the stripe or
membrane region; ``u_px, v_px`` the distorted centroid and ``u_undist_px, v_undist_px`` the same
point undistorted (ideal pinhole pixels of the calibrated K), pixel centres at integers;
``area_px`` the binarised blob's area; ``roundness`` its minor over major axis; ``quality`` 0-1
(CTs: the weakest code sector's contrast; dots: 1 for the Eq. 1 dots and stripe ends found from
a CT, 0.9 for dots found by interpolation or the grid walk, 0.5 for two membrane dots merged in
one blob and fitted apart, each with its own row: half the blob's area, the fit's roundness)."""


def concat_tables(paths: Sequence[str | Path], schema: Schema) -> pd.DataFrame:
    """Several tables of one schema, read and checked, as one (sorted by the schema's key)."""
    parts = [read_table(p, schema) for p in paths]
    if not parts:
        raise ValueError(f"no {schema.name} tables to join")
    return conform(pd.concat(parts, ignore_index=True), schema, f"{len(parts)} {schema.name} tables")


RESIDUALS = Schema(
    "residuals",
    {"camera": "object", "frame": "int64", "id": "int64", "u_px": "float64", "v_px": "float64",
     "du_px": "float64", "dv_px": "float64", "used": "bool", "reason": "object"},
    ("camera", "frame", "id"),
)  # fmt: skip
"""Every observation offered to a reconstruction (``triaxtrack.sfm``: cell-wall targets in air;
``triaxtrack.triangulate``: targets in the water): ``u_px, v_px`` the labelled distorted pixel,
``du_px, dv_px`` the reprojection of the reconstructed point minus it (NaN where there is no
point; with ``reconstruction.eccentricity``, the reprojection plus the eccentricity of the
mark's image, :mod:`triaxtrack.eccentricity`), ``used`` whether it entered the solution,
``reason`` why not ('' when used)."""
WATER_RESIDUALS = Schema(
    "water_residuals",
    RESIDUALS.columns | {"ix_mm": "float64", "iy_mm": "float64", "iz_mm": "float64"},
    RESIDUALS.key,
)
"""``RESIDUALS`` of the targets in the water (``triaxtrack.triangulate.triangulate_refracted``,
per chunk of the time steps), with each used observation's influence on its point ``ix_mm,
iy_mm, iz_mm`` (mm, cell frame; NaN where not used): the point's shift that the observation's
error, estimated from its leverage-corrected residual, caused (``triaxtrack.influence``)."""


TRACKS = Schema(
    "tracks",
    {"camera": "object", "frame": "int64", "id": "int64", "u_px": "float64", "v_px": "float64",
     "area_px": "float64", "sigma_px": "float64", "reason": "object"},
    ("camera", "frame", "id"),
)  # fmt: skip
"""One camera's targets followed through a chunk (``triaxtrack.track``): one row per target
labelled at the chunk's first recorded frame, per processed frame of the chunk (and the frame
the chunk shares with the next one); ``u_px, v_px`` the distorted centroid (NaN where the target
is not reported), ``area_px`` its blob's area, ``reason`` '' when reported, else why not
('edge', 'lost', 'merged', 'shape', 'jump', 'ambiguous', 'drift', 'unconfirmed',
'disagrees', 'not_recorded': :mod:`triaxtrack.track`; counts per camera and reason:
``tracks.groupby(["camera", "reason"]).size()``); ``sigma_px`` the standard uncertainty of each
coordinate of a reported centroid, from its window's pixel noise (NaN where not reported), pixels."""

STRAINS = Schema(
    "strains",
    {"frame": "int64", "time_s": "float64", "row": "int64", "col": "int64", "theta_rad": "float64",
     "z_mm": "float64", "e_zz": "float64", "e_tt": "float64", "e_tz": "float64"},
    ("frame", "row", "col"),
)  # fmt: skip
"""Local Green-Lagrange strain of the membrane, per grid cell (``triaxtrack.volume``): the cell
between membrane grid rows ``row, row + 1`` and columns ``col, col + 1`` (1-based, Eq. 4),
``theta_rad, z_mm`` its centre in design (material) coordinates; ``e_zz`` axial (along the
undeformed generatrix), ``e_tt`` circumferential, ``e_tz`` shear, in the undeformed tangent basis;
tension positive (the opposite sign to the compression-positive strains of ``volume``)."""


STRESS_TRUTH = Schema(
    "stress_truth",
    {"frame": "int64", "time_s": "float64", "axial_strain": "float64", "volumetric_strain": "float64",
     "height_mm": "float64", "volume_mm3": "float64", "area_mean_mm2": "float64", "area_mid_mm2": "float64",
     "area_min_mm2": "float64", "soil_force_n": "float64", "q_mean_kpa": "float64", "q_mid_kpa": "float64",
     "q_min_kpa": "float64", "cell_pressure_kpa": "float64", "pore_pressure_kpa": "float64",
     "p_kpa": "float64", "p_eff_kpa": "float64"},
    ("frame",),
)  # fmt: skip
"""A simulated test's ``truth/stress_strain.parquet`` (``triaxtrack.simulate.loadlog``), per
frame: true strains (compression positive), height, soil volume, the true mean area ``V / H``,
the horizontal sections at mid-height and the smallest (``triaxtrack.stress.sections``'
margin and levels), ``soil_force_n`` the force the soil carries (the log's load less the
membrane's share and the load cell's offset), ``q_*_kpa`` that force on each area
(``q_mean_kpa`` is the hyperbolic law's), the cell and pore pressures, ``p = sigma_3 + q / 3``
and ``p' = p - u`` (on ``q_mean_kpa``)."""

_F = "float64"
STRESS_STRAIN = Schema(
    "stress_strain",
    {"frame": "int64", "time_s": _F, "log_time_s": _F, "axial_strain": _F, "volumetric_strain": _F,
     "axial_strain_log": _F, "volumetric_strain_gauge": _F, "height_mm": _F, "volume_mm3": _F,
     "axial_load_n": _F, "force_n": _F, "soil_force_n": _F, "cell_pressure_kpa": _F, "pore_pressure_kpa": _F,
     "area_mean_mm2": _F, "area_mid_mm2": _F, "area_min_mm2": _F, "area_standard_mm2": _F,
     "membrane_kpa": _F, "filter_paper_kpa": _F, "q_mean_kpa": _F, "q_mean_sigma_kpa": _F,
     "q_mid_kpa": _F, "q_mid_sigma_kpa": _F, "q_min_kpa": _F, "q_min_sigma_kpa": _F,
     "q_standard_kpa": _F, "q_standard_sigma_kpa": _F, "p_kpa": _F, "p_eff_kpa": _F, "p_sigma_kpa": _F,
     "p_eff_sigma_kpa": _F, "axial_strain_sigma": _F, "e_secant_kpa": _F, "e_secant_sigma_kpa": _F,
     "e_tangent_kpa": _F, "e_tangent_sigma_kpa": _F, "reason": "object"},
    ("frame",),
)  # fmt: skip
"""The measured ``results/<test>/stress_strain.parquet`` (``triaxtrack.stress``), per processed
frame, compression positive, kPa, N, mm: ``log_time_s`` the frame's time on the log's clock;
``axial_strain``, ``volumetric_strain`` from the measured height and volume, zeroed at the
stress stage's zero time; ``axial_strain_log`` from the log's external displacement over the
nominal height, ``volumetric_strain_gauge`` from its volume gauge over the nominal volume (NaN
without one); ``axial_load_n`` the log's load, ``force_n`` zeroed, ``soil_force_n`` less the
membrane's and filter paper's shares (``membrane_kpa``, ``filter_paper_kpa``, on the mean area);
``area_mean_mm2 = V / H``, ``area_mid_mm2`` the section at mid-height, ``area_min_mm2`` the
smallest section (``triaxtrack.stress.sections``), ``area_standard_mm2 = A0 (1 - ev_gauge) /
(1 - ea_log)``; ``q_*_kpa`` the deviator stress on each (``q_standard_kpa`` the lab's standard,
with its own corrections), ``p_kpa = sigma_3 + q_mean / 3``, ``p_eff_kpa = p - u``; secant and
tangent Young's moduli of ``q_mean`` against ``axial_strain``; ``*_sigma_*`` the standard
uncertainties (``triaxtrack.stress.compute``); ``reason`` '' or why a frame lacks values."""
