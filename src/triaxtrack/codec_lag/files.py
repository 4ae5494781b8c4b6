"""The per-camera codec-lag file (``results/<test>/codec_lag/<camera>.json``): its one writer
and reader, and the rule ``measure_codec_lag`` that makes it."""

from __future__ import annotations

import json
from collections.abc import Iterable, Mapping, Sequence
from pathlib import Path
from typing import NamedTuple

import numpy as np
import pandas as pd

from triaxtrack.codec_lag.measure import LAG_COLUMNS, estimate_lag_chunks, rigid_bodies


def write_lags(
    path: str | Path,
    camera: str,
    keyframes: np.ndarray,
    lags: pd.DataFrame,
    note: str = "",
    bodies: Mapping[str, Sequence[int]] | None = None,
) -> None:
    """Write one camera's measured departures (``results/<test>/codec_lag/<camera>.json``):
    its keyframes (test frames, every one of the test), :func:`estimate_lag`'s rows (null
    where NaN), the rigid ``bodies`` they were measured on (name -> target IDs) and a ``note``
    (why nothing is measured or applied, if so)."""
    rows = lags[list(LAG_COLUMNS)].astype({"body": str}).to_numpy(object).tolist()
    doc = {
        "camera": camera,
        "keyframes": [int(k) for k in np.asarray(keyframes, np.int64)],
        "columns": list(LAG_COLUMNS),
        "lags": [[_json_value(v) for v in row] for row in rows],
        "bodies": {str(name): [int(i) for i in ids] for name, ids in (bodies or {}).items()},
        "note": note,
    }
    Path(path).write_text(json.dumps(doc, indent=1, allow_nan=False) + "\n")


def _json_value(v: object) -> object:
    """A table cell as JSON: numbers as Python numbers, NaN as null, strings as they are."""
    if isinstance(v, str):
        return v
    x = float(v)  # type: ignore[arg-type]
    return None if np.isnan(x) else (int(x) if x.is_integer() and abs(x) < 2**53 else x)


class LagFile(NamedTuple):
    """One camera's file of :func:`write_lags`, as :func:`correct_lag` takes it."""

    keyframes: np.ndarray
    lags: pd.DataFrame
    bodies: dict[str, list[int]]


def read_lags(path: str | Path) -> tuple[str, LagFile]:
    """``(camera, LagFile(keyframes, lags, bodies))`` of a file written by :func:`write_lags`."""
    try:
        doc = json.loads(Path(path).read_text())
        lags = pd.DataFrame(doc["lags"], columns=doc["columns"])
        keys = np.asarray(doc["keyframes"], np.int64)
        camera = str(doc["camera"])
        bodies = {str(k): [int(i) for i in v] for k, v in doc["bodies"].items()}
        if list(lags.columns) != list(LAG_COLUMNS):
            raise ValueError(
                f"columns {list(lags.columns)}, expected {list(LAG_COLUMNS)}: written by another"
                " version of triaxtrack, run rule measure_codec_lag again (--forcerun measure_codec_lag)"
            )
        numbers = [c for c in LAG_COLUMNS if c != "body"]
        lags = lags.astype({"body": str, **dict.fromkeys(numbers, np.float64)})
    except (OSError, ValueError, KeyError, TypeError, AttributeError) as err:
        raise ValueError(f"{path}: not a codec-lag file ({err})") from None
    return camera, LagFile(
        keys, lags.astype({"keyframe": np.int64, "side": np.int64, "dots": np.int64}), bodies
    )


def read_lag_files(paths: Iterable[str | Path]) -> dict[str, LagFile]:
    """Camera -> its :class:`LagFile` of several files written by :func:`write_lags` (the
    argument of :func:`corrected_tracks`)."""
    return dict(map(read_lags, paths))


def run_measure_codec_lag(
    *,
    camera: str,
    tracks: Sequence[str | Path],
    video: str | Path,
    frames: str | Path,
    kit: str | Path,
    lags: str | Path,
) -> None:
    """Rule measure_codec_lag: :func:`estimate_lag_chunks` of one ``camera`` over its chunks'
    ``tracks`` in order, at every keyframe of its ``video`` (frame map ``frames``), with the
    rigid bodies of the ``kit`` folder's design, written to ``lags`` (:func:`write_lags`, with a
    note when nothing could be measured); prints the rows."""
    from triaxtrack.frames import keyframe_test_frames
    from triaxtrack.kit import load_kit_design, target_table
    from triaxtrack.tables import FRAME_MAP, TRACKS, read_table

    fmap = read_table(frames, FRAME_MAP)
    keys = keyframe_test_frames(video, fmap, 0, len(fmap))
    bodies = rigid_bodies(target_table(load_kit_design(kit)))
    found = estimate_lag_chunks((read_table(path, TRACKS) for path in tracks), keys, bodies)
    note = "" if len(found) else "not measured: no keyframe with enough P frames on either side"
    write_lags(lags, camera, keys, found, note, bodies)
    print(f"{camera}: P frames against keyframes {keys.tolist()} (triaxtrack.codec_lag):")
    print(note or found.to_string(index=False))
