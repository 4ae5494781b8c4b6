"""Parquet table schemas, defined once and checked on every write and read.

The result and truth tables of ``test-folder.md``. Units and conventions where the data is born:
positions in millimetres in the cell frame; pixels in OpenCV convention (the centre of the
top-left pixel is (0, 0)), distorted image coordinates; times in seconds from the first frame;
strains dimensionless, compression positive. In a synthetic test's ``truth/points.parquet``
every target has a row at every frame, with ``n_rays`` the number of cameras that see it; rows
with ``n_rays < 2`` are not expected to be reconstructed.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import pandas as pd


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
