"""The results folder's and the test folder's layout (triaxtrack.layout, issue 19): every path
pattern written once, there; the rules take theirs from it."""

from __future__ import annotations

import re
from dataclasses import fields
from pathlib import Path

import pytest

from triaxtrack.layout import CSV_TABLES, RESULTS, TEST_FOLDER, TRUTH, ResultsLayout, _Layout

REPO = Path(__file__).resolve().parents[1]


def patterns(layout: _Layout) -> dict[str, str]:
    """field path ("simulated.truth.cameras") -> pattern, nested layouts included."""
    out = {}
    for f in fields(layout):
        value = getattr(layout, f.name)
        if isinstance(value, _Layout):
            out |= {f"{f.name}.{k}": v for k, v in patterns(value).items()}
        elif f.name != "root":
            out[f.name] = value
    return out


def test_every_pattern_is_one_file():
    for layout in (RESULTS, TEST_FOLDER, TRUTH):
        found = patterns(layout)
        assert len(set(found.values())) == len(found), found


def test_under_puts_a_root_before_every_pattern():
    R = RESULTS.under("results/{test}")
    assert R.root == "results/{test}"
    assert R.points == "results/{test}/points.parquet"
    assert R.simulated.root == "results/{test}/simulated"
    assert R.simulated.truth.board_poses == "results/{test}/simulated/truth/calibration/{camera}.json"
    assert all(p.startswith("results/{test}/") for p in patterns(R).values())
    concrete = RESULTS.under(Path("results") / "demo")
    assert concrete.calibration.format(camera="cam01") == "results/demo/calibration/cam01.json"
    assert Path("results/demo") / RESULTS.points == Path(concrete.points)
    assert TEST_FOLDER.under(".").video == "videos/{camera}.mp4"  # as pathlib joins


def test_csv_of():
    assert RESULTS.csv_of("volume") == "volume.csv"
    assert [RESULTS.csv_of(t) for t in CSV_TABLES] == [f"{t}.csv" for t in CSV_TABLES]
    with pytest.raises(ValueError, match="not exported"):
        RESULTS.csv_of("points")


def test_rules_write_no_results_path():
    """Outside common.smk's one root, no rule file spells a path under results/<test>/."""
    for smk in sorted((REPO / "workflow" / "rules").glob("*.smk")):
        text = smk.read_text()
        found = re.findall(r'"results/\{test\}[^"]*"', text)
        assert found == (['"results/{test}"'] if smk.name == "common.smk" else []), smk.name


def test_results_layout_has_no_wildcards_but_the_workflows():
    allowed = {"camera", "chunk", "segment", "table"}
    for pattern in patterns(ResultsLayout()).values():
        assert set(re.findall(r"\{(\w+)\}", pattern)) <= allowed, pattern
