"""Reading a load-frame log (the lab's control-software export) as test.yaml's ``load_frame``
entry maps it (``docs/test-folder.md``): :func:`read_load_frame_log`.

The result has one row per log sample, sorted by time, in the project's units:
``log_time_s`` (s on the log's own clock; a datetime column counts from its first row),
``axial_load_n`` (N), ``cell_pressure_kpa``, ``pore_pressure_kpa`` (kPa; NaN when not mapped),
``axial_displacement_mm`` (mm, compression positive after ``sign``) and ``volume_change_mm3``
(mm^3, water out of the specimen positive after ``sign``; NaN when the log has no volume gauge).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd

# quantity -> (output column, {unit: factor to the output unit}, required)
QUANTITIES: dict[str, tuple[str, dict[str, float], bool]] = {
    "time": ("log_time_s", {"s": 1.0, "min": 60.0, "h": 3600.0, "ms": 1e-3}, True),
    "axial_load": ("axial_load_n", {"N": 1.0, "kN": 1000.0, "lbf": 4.4482216152605}, True),
    "cell_pressure": ("cell_pressure_kpa", {"kPa": 1.0, "MPa": 1000.0, "Pa": 1e-3, "bar": 100.0}, True),
    "pore_pressure": ("pore_pressure_kpa", {"kPa": 1.0, "MPa": 1000.0, "Pa": 1e-3, "bar": 100.0}, False),
    "axial_displacement": ("axial_displacement_mm", {"mm": 1.0, "m": 1000.0, "um": 1e-3, "in": 25.4}, True),
    "volume_change": ("volume_change_mm3", {"mm3": 1.0, "cm3": 1000.0, "ml": 1000.0, "m3": 1e9}, False),
}
SIGNED = ("axial_displacement", "volume_change")  # quantities whose mapping may carry `sign: -1`
DATETIME = "datetime"  # the time unit of a date/time column (seconds from the log's first row)


def _column(raw: pd.DataFrame, path: Path, quantity: str, spec: dict) -> np.ndarray:
    """One mapped column in the output unit (ValueError naming the file and the column)."""
    out_col, units, _ = QUANTITIES[quantity]
    name = spec.get("name")
    if name not in raw.columns:
        raise ValueError(
            f"{path}: column {name!r} (load_frame.columns.{quantity}) not found; "
            f"the file has {list(raw.columns)}"
        )
    unit = spec.get("unit")
    values = raw[name]
    if quantity == "time" and unit == DATETIME:
        stamps = pd.to_datetime(values, format=spec.get("format"), errors="coerce")
        if stamps.isna().any():
            bad = int(np.flatnonzero(stamps.isna())[0])
            raise ValueError(f"{path}: column {name!r} (time): {values.iloc[bad]!r} is not a date/time")
        return ((stamps - stamps.iloc[0]).dt.total_seconds()).to_numpy(float)
    if unit not in units:
        allowed = sorted(units) + ([DATETIME] if quantity == "time" else [])
        raise ValueError(f"{path}: column {name!r} ({quantity}): unit {unit!r} is not one of {allowed}")
    numbers = pd.to_numeric(values, errors="coerce")
    if numbers.isna().any():
        bad = int(np.flatnonzero(numbers.isna())[0])
        raise ValueError(
            f"{path}: column {name!r} ({quantity}): row {bad + 1} holds {values.iloc[bad]!r}, not a number"
        )
    sign = float(spec.get("sign", 1))
    if sign not in (1.0, -1.0) or (sign != 1.0 and quantity not in SIGNED):
        raise ValueError(
            f"{path}: column {name!r} ({quantity}): sign must be 1 or -1 (displacement and volume only)"
        )
    return sign * numbers.to_numpy(float) * units[unit]


def read_load_frame_log(test_dir: str | Path, entry: dict) -> pd.DataFrame:
    """The load-frame log of a test folder, as its test.yaml ``load_frame`` ``entry`` maps it.

    ``entry``: ``file`` (relative to ``test_dir``), ``columns`` (per quantity of
    :data:`QUANTITIES` a mapping ``{name, unit}``, optionally ``sign`` for the displacement and
    the volume, ``format`` for a datetime), optional ``delimiter`` (default: sniffed),
    ``header_row`` (0-based line of the column names; default 0), ``decimal`` (default ".").
    ValueError naming the file and the column for a missing file or column, an unknown unit or
    a value that is not a number; rows are sorted by time, and a time that repeats is an error.
    """
    path = Path(test_dir) / entry["file"]
    if not path.is_file():
        raise ValueError(f"{path}: load-frame log not found (test.yaml load_frame.file)")
    columns = entry.get("columns") or {}
    missing = [q for q, (_, _, required) in QUANTITIES.items() if required and q not in columns]
    if missing:
        raise ValueError(f"{path}: test.yaml load_frame.columns lacks {missing} (required: time, axial_load, "
                         "cell_pressure, axial_displacement)")  # fmt: skip
    unknown = sorted(set(columns) - set(QUANTITIES))
    if unknown:
        raise ValueError(
            f"{path}: test.yaml load_frame.columns: unknown {unknown}; known {sorted(QUANTITIES)}"
        )
    try:
        raw = pd.read_csv(
            path,
            sep=entry.get("delimiter"),
            engine="python",
            header=int(entry.get("header_row", 0)),
            decimal=entry.get("decimal", "."),
            skipinitialspace=True,
            encoding_errors="replace",
        )
    except (ValueError, pd.errors.ParserError, UnicodeDecodeError) as err:
        raise ValueError(f"{path}: cannot read the load-frame log: {err}") from err
    raw.columns = [str(c).strip() for c in raw.columns]
    out = {}
    for quantity, (out_col, _, _) in QUANTITIES.items():
        out[out_col] = (
            _column(raw, path, quantity, columns[quantity])
            if quantity in columns
            else np.full(len(raw), np.nan)
        )
    df = pd.DataFrame(out).sort_values("log_time_s", kind="stable").reset_index(drop=True)
    if len(df) < 2:
        raise ValueError(f"{path}: the load-frame log has fewer than 2 rows")
    if np.any(np.diff(df["log_time_s"].to_numpy()) <= 0):
        raise ValueError(f"{path}: column {columns['time']['name']!r} (time) repeats a time")
    return df
