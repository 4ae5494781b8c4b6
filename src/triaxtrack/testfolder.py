"""The test folder and the JSON documents the stages pass on: the one module that reads them.

Each artifact has one reader here (and one writer where the package writes it), built on
:mod:`triaxtrack.jsonfile`; every error names the file. ``test-folder.md`` describes them.

* ``test.yaml`` (a recorded test's metadata): :class:`TestFolder` reads and validates it once,
  for the workflow (``workflow/rules/common.smk``); :func:`read_test_yaml`,
  :func:`read_test_fps`, :func:`read_test_cameras` and :func:`read_test_frames` read it for a
  stage, unvalidated (the workflow validated it when it loaded);
* ``calibration/<camera>.json`` (rule calibrate_camera): :func:`read_calibration`,
  :func:`read_calibration_folder`, :func:`write_calibration`;
* ``cameras.json`` (a test's truth, rules trace_specimen and collect_timesteps):
  :func:`read_cameras_doc`, :func:`write_cameras_doc` (as :class:`~triaxtrack.optics.Camera`
  objects: :func:`triaxtrack.optics.read_cameras`);
* ``reconstruction/cell.json`` (rule reconstruct_cell: cameras and the fitted cell):
  :func:`read_cell`, :func:`write_cell`;
* ``quality.json`` (rules trace_specimen and collect_timesteps, a report): :func:`read_quality`,
  :func:`write_quality`.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import yaml

from triaxtrack.errors import schema_problems, unknown_top_level_keys
from triaxtrack.jsonfile import read_json, write_json
from triaxtrack.layout import TEST_FOLDER

TEST_YAML = TEST_FOLDER.test_yaml
DEFAULT_KIT = TEST_FOLDER.kit  # test.yaml's ``kit`` when it gives none: the folder kit/ beside it


# ---------------------------------------------------------------- test.yaml


def _load_test_yaml(path: Path) -> Any:
    """The parsed document of a test.yaml (any YAML value); OSError or YAMLError as raised. The
    package's one ``yaml.safe_load`` of test.yaml."""
    return yaml.safe_load(path.read_text())


def camera_entries(cameras: Sequence[str | dict]) -> list[dict]:
    """test.yaml's ``cameras`` as mappings: a bare name ``n`` is ``{"name": n}``."""
    return [c if isinstance(c, dict) else {"name": c} for c in cameras]


class TestFolderError(ValueError):
    """A test folder whose test.yaml is missing, unreadable or not valid (the message says
    which); ``unknown_keys``: test.yaml's top-level keys the workflow does not read, if known."""

    __test__ = False  # not a pytest test class

    def __init__(self, message: str, unknown_keys: Sequence[str] = ()) -> None:
        super().__init__(message)
        self.unknown_keys = tuple(unknown_keys)


@dataclass(frozen=True)
class TestFolder:
    """A recorded test folder (``test-folder.md``) and its test.yaml, read and validated once.

    ``doc``: test.yaml with ``cameras`` as mappings (:func:`camera_entries`) and ``kit``
    defaulted to ``"kit"``; ``unknown_keys``: its top-level keys the workflow does not read
    (allowed, since a recorder may write more: the workflow warns)."""

    __test__ = False  # not a pytest test class

    path: Path
    doc: dict
    unknown_keys: tuple[str, ...] = ()

    @staticmethod
    def load(folder: str | Path, schema: dict) -> TestFolder:
        """Read ``folder/test.yaml`` and validate it against the test.yaml ``schema``
        (``workflow/schemas/test.schema.yaml``). TestFolderError naming the file, the key and
        a near miss on any problem."""
        path = Path(folder) / TEST_YAML
        if not path.is_file():
            raise TestFolderError(f"recorded test folder {folder!s}: {path} not found")
        try:
            doc = _load_test_yaml(path)
        except yaml.YAMLError as exc:
            raise TestFolderError(f"{path}: not valid YAML: {exc}") from exc
        unknown = unknown_top_level_keys(doc, schema)
        problems = schema_problems(doc, schema, [(str(path), doc)])
        if problems:
            raise TestFolderError(
                "a recorded test's test.yaml is not valid (see config/README.md, `tests`):\n  "
                + "\n  ".join(problems),
                unknown,
            )
        cameras = camera_entries(doc["cameras"])
        names = [c["name"] for c in cameras]
        duplicates = sorted({n for n in names if names.count(n) > 1})
        if duplicates:
            raise TestFolderError(f"{path}: camera names listed more than once: {duplicates}", unknown)
        full = {**doc, "cameras": cameras, "kit": doc.get("kit", DEFAULT_KIT)}
        return TestFolder(Path(folder), full, tuple(unknown))

    @property
    def test_yaml(self) -> Path:
        return self.path / TEST_YAML

    @property
    def cameras(self) -> list[str]:
        """The camera names, in test.yaml's order."""
        return [c["name"] for c in self.doc["cameras"]]


def read_test_yaml(test_yaml: str | Path) -> dict:
    """A test.yaml as a mapping (``test-folder.md``; not validated: the workflow validates it
    when it loads); ValueError naming the file when it is unreadable or not a mapping."""
    path = Path(test_yaml)
    try:
        doc = _load_test_yaml(path)
    except (OSError, yaml.YAMLError) as err:
        raise ValueError(f"{path}: not a readable test.yaml: {err}") from err
    if not isinstance(doc, dict):
        raise ValueError(f"{path}: not a readable test.yaml: not a mapping")
    return doc


def read_test_fps(test_yaml: str | Path) -> float:
    """test.yaml's ``fps``: the test clock's frames per second (:mod:`triaxtrack.frames`);
    ValueError naming the file when it is unreadable or has no positive ``fps``."""
    doc = read_test_yaml(test_yaml)
    try:
        fps = float(doc["fps"])
    except (KeyError, TypeError, ValueError) as err:
        raise ValueError(f"{test_yaml}: test.yaml has no usable fps: {err!r}") from err
    if not fps > 0:
        raise ValueError(f"{test_yaml}: test.yaml's fps must be positive, not {fps}")
    return fps


def read_test_cameras(test_yaml: str | Path) -> tuple[float, list[dict]]:
    """test.yaml's ``fps`` and its ``cameras`` as mappings (:func:`camera_entries`); ValueError
    naming the file when it is unreadable or lacks either."""
    path = Path(test_yaml)
    try:
        doc = _load_test_yaml(path)
        return float(doc["fps"]), camera_entries(doc["cameras"])
    except (OSError, yaml.YAMLError, KeyError, TypeError, ValueError) as err:
        raise ValueError(f"{path}: not a readable test.yaml (needs fps and cameras): {err}") from err


def read_test_frames(test_yaml: str | Path) -> int | None:
    """test.yaml's ``frames`` (the number of test frames), or None when it gives none;
    ValueError naming the file when it is unreadable."""
    path = Path(test_yaml)
    try:
        doc = _load_test_yaml(path)
    except (OSError, yaml.YAMLError) as err:
        raise ValueError(f"{path}: not a readable test.yaml: {err}") from err
    if isinstance(doc, dict) and doc.get("frames") is not None:
        return int(doc["frames"])
    return None


# ---------------------------------------------------------------- calibration/<camera>.json


def read_calibration(path: str | Path) -> dict:
    """A calibration result (:mod:`triaxtrack.calibrate`: ``camera``, ``width``, ``height``,
    ``K`` 3 x 3, ``dist`` 4+ coefficients, ...); ValueError naming the file if it is not one."""
    path = Path(path)
    cal = read_json(path, "calibration result")
    try:
        for key in ("camera", "width", "height", "K", "dist"):
            if key not in cal:
                raise ValueError(f"no {key!r}")
        K = np.asarray(cal["K"], float)
        dist = np.asarray(cal["dist"], float)
        if K.shape != (3, 3) or dist.ndim != 1 or len(dist) < 4:
            raise ValueError(f"K must be 3 x 3 and dist 4+ coefficients, not {K.shape} and {dist.shape}")
    except (ValueError, TypeError) as err:
        raise ValueError(f"{path}: not a calibration result: {err}") from err
    return cal


def write_calibration(path: str | Path, result: dict) -> None:
    """Write a calibration result, the file :func:`read_calibration` reads."""
    write_json(path, result)


def read_calibration_folder(folder: str | Path) -> dict[str, dict]:
    """camera -> calibration result of every ``folder/<camera>.json``; ValueError naming a file
    that is not a calibration result or whose ``camera`` is not its file name. A truth folder's
    board poses (``truth/calibration/<camera>.json``, key ``board_poses``) are skipped."""
    cals = {}
    for path in sorted(Path(folder).glob("*.json")):
        if _is_board_poses(path):
            continue
        cal = read_calibration(path)
        if cal["camera"] != path.stem:
            raise ValueError(f"{path}: holds camera {cal['camera']!r}, not {path.stem!r}")
        cals[path.stem] = cal
    return cals


def _is_board_poses(path: Path) -> bool:
    try:
        doc = read_json(path, "calibration file")
    except ValueError:
        return False
    return "board_poses" in doc and "K" not in doc


# ---------------------------------------------------------------- cameras.json, cell.json, quality.json


def read_cameras_doc(path: str | Path) -> dict[str, dict]:
    """camera -> its entry (``K``, ``dist``, ``R``, ``t``, ``width``, ``height``) of a
    ``cameras.json`` (or of a ``cell.json``, which holds its cameras the same way); ValueError
    naming the file."""
    try:
        cams = read_json(path, "cameras.json")["cameras"]
    except KeyError as err:
        raise ValueError(f"{path}: not a cameras.json: {err}") from err
    if not isinstance(cams, dict):
        raise ValueError(f"{path}: not a cameras.json: `cameras` is not an object")
    return cams


def write_cameras_doc(path: str | Path, cameras: dict[str, dict]) -> None:
    """Write camera -> entry (in the order given) as a ``cameras.json``, the file
    :func:`read_cameras_doc` reads."""
    write_json(path, {"cameras": cameras})


def read_cell(path: str | Path) -> dict:
    """A ``cell.json`` (rule reconstruct_cell: :func:`~triaxtrack.sfm.cell_summary`); ValueError
    naming the file."""
    return read_json(path, "cell.json")


def write_cell(path: str | Path, summary: dict) -> None:
    """Write a ``cell.json``, the file :func:`read_cell` reads."""
    write_json(path, summary)


def read_quality(path: str | Path) -> dict:
    """A ``quality.json`` report; ValueError naming the file."""
    return read_json(path, "quality.json")


def write_quality(path: str | Path, report: dict) -> None:
    """Write a ``quality.json`` report, the file :func:`read_quality` reads."""
    write_json(path, report)
