"""The report reads the kit: its figures and movie follow the kit's membrane grid (rows, columns,
IDs, size), and no figure or report code holds a kit's counts as constants."""

from __future__ import annotations

import io
import tokenize
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
from matplotlib.collections import QuadMesh
from test_report import FRAMES, points_table, strains_table, tracks_table

from triaxtrack.kit import load_kit_design, target_table
from triaxtrack.kit_design import KitDesign
from triaxtrack.report import (
    figure_image,
    membrane_layout,
    specimen_frames,
    strain_map_figure,
    strain_maps_figure,
    tracking_figure,
)

SRC = Path(__file__).resolve().parents[1] / "src" / "triaxtrack"
#: The code that draws the report's figures, its movie and the reconstruction picture
# report/config.py is left out: its numbers are the config section's defaults (a viewer of at
# most 60 frames, say), which tests/test_config_errors.py holds equal to config/config.yaml
FIGURE_CODE = [path for path in sorted((SRC / "report").glob("*.py")) if path.name != "config.py"]
FIGURE_CODE += [SRC / "camera_report.py", SRC / "plots.py"]


@pytest.fixture(scope="module")
def other_design(design: KitDesign) -> KitDesign:
    """A kit unlike the default one: a smaller specimen with a coarser membrane grid whose IDs
    start elsewhere."""
    membrane = replace(design.membrane, rows=30, columns=48, first_id=5001, large_first=2, large_step=5)
    return replace(design, membrane=membrane, specimen=replace(design.specimen, diameter=50.0, height=100.0))


@pytest.fixture(scope="module")
def layout(design):
    return membrane_layout(design)


@pytest.fixture(scope="module")
def other(other_design):
    return membrane_layout(other_design)


def test_layout_is_the_kits(design, layout, kit_dir):
    m = design.membrane
    table = target_table(design)
    mem = table[table["surface"] == "membrane"]
    assert (layout.rows, layout.columns, layout.first_id) == (m.rows, m.columns, m.first_id)
    assert layout.n_dots == len(mem) and layout.last_id == mem["id"].max()
    for r, c in ((1, 1), (1, m.columns), (m.rows, 1), (7, 13)):
        row = mem[(mem["row"] == r) & (mem["col"] == c)].iloc[0]
        assert layout.ids[r - 1, c - 1] == row["id"]
        assert layout.grid_index(np.array([row["id"]]))[0] == (r - 1) * layout.columns + c - 1
        assert layout.row_z_mm[r - 1] == pytest.approx(row["z_mm"])
        assert layout.col_theta_rad[c - 1] == pytest.approx(row["theta_rad"])
    others = table.loc[table["surface"] != "membrane", "id"].to_numpy()
    assert not layout.is_membrane(others).any()
    spec = design.specimen
    assert layout.radius_mm == pytest.approx(spec.diameter / 2 + spec.membrane_thickness)
    assert layout.height_mm == spec.height
    # what the workflow reads: the test's kit export
    exported = membrane_layout(load_kit_design(kit_dir))
    assert np.array_equal(exported.ids, layout.ids) and np.allclose(exported.row_z_mm, layout.row_z_mm)
    assert exported.radius_mm == pytest.approx(layout.radius_mm)


def test_layout_of_another_kit(other):
    assert (other.rows, other.columns, other.first_id, other.last_id) == (30, 48, 5001, 5000 + 30 * 48)
    assert other.n_cells == 29 * 48 and other.cell_corners().shape == (29 * 48, 4)
    # row r, column c: ID (r - 1) * columns + c + first_id - 1 (Eq. 4)
    assert other.ids[2, 4] == 2 * 48 + 5 + 5000
    assert other.row_of_z(other.row_z_mm[[0, -1]]).tolist() == pytest.approx([1.0, 30.0])
    assert other.column_of_theta(np.rad2deg(other.col_theta_rad[[0, -1]])).tolist() == pytest.approx([1, 48])
    cells = other.cell_index(np.array([1, 29, 30, 0]), np.array([1, 48, 1, 1]))
    assert cells.tolist() == [0, 29 * 48 - 1, -1, -1]  # row 30 and row 0 have no cell


def _drawn_texts(fig) -> list[str]:
    figure_image(fig)
    return [t.get_text() for t in fig.findobj(lambda a: hasattr(a, "get_text")) if t.get_text()]


@pytest.mark.parametrize("which", ["layout", "other"])
def test_strain_map_follows_the_kit(which, request):
    """The map's grid, its row and column axes and its proportions are the kit's."""
    kit = request.getfixturevalue(which)
    strains = strains_table(kit)
    fig = strain_map_figure(strains, kit, FRAMES - 1, "e_tt")
    ax = fig.axes[0]
    mesh = next(c for c in ax.collections if isinstance(c, QuadMesh))
    assert mesh.get_array().size == kit.n_cells and np.ma.count_masked(mesh.get_array()) == 0
    assert ax.get_ylim() == pytest.approx((kit.row_z_mm[-1], kit.row_z_mm[0]))
    assert ax.get_aspect() == pytest.approx(360.0 / (2 * np.pi * kit.radius_mm))
    texts = _drawn_texts(fig)
    assert f"row (of {kit.rows}; 1 at the top)" in texts and f"column (of {kit.columns})" in texts
    row_axis = next(a for a in ax.child_axes if a.get_ylabel().startswith("row"))
    column_axis = next(a for a in ax.child_axes if a.get_xlabel().startswith("column"))
    assert sorted(row_axis.get_ylim()) == pytest.approx([1, kit.rows])  # the kit's rows, top to bottom
    assert sorted(column_axis.get_xlim()) == pytest.approx([1, kit.columns + 1])  # a full turn
    assert _drawn_texts(strain_maps_figure(strains, kit, [0, FRAMES - 1]))


def test_tracking_figure_counts_the_kits_membrane_dots(layout, other):
    for kit in (layout, other):
        tracks = tracks_table(kit)
        fig = tracking_figure(tracks, kit)
        share = fig.axes[0]
        assert f"IDs {kit.first_id}..{kit.last_id}" in share.get_title()
        n_membrane = int(kit.is_membrane(tracks["id"].to_numpy()).sum())
        labels = [t.get_text() for t in share.get_legend().get_texts()]
        assert labels[0] == f"membrane dots ({n_membrane} target-frames)"
    # the other kit's dots are not the default kit's membrane dots, and the figure says so
    theirs = tracks_table(other)
    assert theirs["id"].isin(other.ids.ravel()).any()
    assert not layout.is_membrane(theirs["id"].to_numpy()).any()
    labels = [t.get_text() for t in tracking_figure(theirs, layout).axes[0].get_legend().get_texts()]
    assert labels == [f"other targets ({len(theirs)} target-frames)"]


def test_movie_follows_the_kit(layout, other):
    points = points_table(other)
    frames = list(specimen_frames(points, other, height=200))
    assert len(frames) == FRAMES and frames[-1].astype(float).std() > 10
    with pytest.raises(ValueError, match=f"IDs {layout.first_id}..{layout.last_id}"):
        specimen_frames(points, layout)  # another kit's grid: no membrane dot of this one
    strains = strains_table(other)
    frame = next(specimen_frames(points, other, strains, colour_by="e_zz", frames=[FRAMES - 1], height=200))
    assert frame.shape[0] == 200


def _numbers(path: Path) -> list[tuple[int, str]]:
    """(line, literal) of every number literal in a Python file's code (not its strings or
    comments)."""
    tokens = tokenize.generate_tokens(io.StringIO(path.read_text()).readline)
    return [(t.start[0], t.string) for t in tokens if t.type == tokenize.NUMBER]


def test_no_kit_counts_in_figure_code(design):
    """The counts and sizes of the default kit (membrane rows, columns, first and last ID, number
    of dots, specimen size) appear nowhere in the figure and report code as number literals:
    they are read from the kit."""
    m, spec = design.membrane, design.specimen
    counts = {m.rows, m.columns, m.first_id, m.rows * m.columns,
              m.first_id + m.rows * m.columns - 1, spec.diameter, spec.height,
              spec.diameter / 2, round(spec.diameter / 2, 1)}  # fmt: skip
    assert len(FIGURE_CODE) >= 7
    found = [
        f"{path.relative_to(SRC)}:{line}: {text}"
        for path in FIGURE_CODE
        for line, text in _numbers(path)
        if float(text.replace("_", "")) in {float(c) for c in counts}
    ]
    assert not found, "kit counts written as constants:\n" + "\n".join(found)
