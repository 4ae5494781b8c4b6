"""The workflow's JSON documents (calibration results, ``cell.json``, ``cameras.json``, the
``quality.json`` files, ``clock.json``), read and written one way: written with an indent of 2
and no trailing newline, read with an error naming the file."""

from __future__ import annotations

import json
from pathlib import Path


def write_json(path: str | Path, doc: dict, sort_keys: bool = False) -> None:
    """Write ``doc`` to ``path`` as JSON, indented by 2 (its keys sorted with ``sort_keys``)."""
    Path(path).write_text(json.dumps(doc, indent=2, sort_keys=sort_keys))


def read_json(path: str | Path, what: str) -> dict:
    """The JSON object in ``path``; ValueError naming the file and ``what`` it should be (for
    example ``"cell.json"``) when it is missing, not JSON or not an object."""
    try:
        doc = json.loads(Path(path).read_text())
    except (OSError, ValueError) as err:
        raise ValueError(f"{path}: not a readable {what}: {err}") from err
    if not isinstance(doc, dict):
        raise ValueError(f"{path}: not a readable {what}: not a JSON object")
    return doc
