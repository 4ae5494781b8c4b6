"""The kit's membrane grid as the report draws it: rows, columns, IDs and design coordinates.

Everything the report draws about the membrane (which IDs are membrane dots, where a dot or a
cell sits on the grid, the grid's design z and theta, the membrane's radius) comes from one
:class:`MembraneLayout`, built from the kit design by :func:`membrane_layout`; no count, ID or
size of a particular kit is written in the report's code.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike

from triaxtrack.kit import membrane_radius, target_table
from triaxtrack.kit_design import KitDesign

__all__ = ["MembraneLayout", "membrane_layout"]


@dataclass(frozen=True, eq=False)
class MembraneLayout:
    """The membrane dot grid of a kit (``config/kit.yaml``'s ``membrane`` section, Eq. 4).

    ``ids`` (rows, columns) int64: the ID of the dot in kit row ``r`` (1 at the top) and column
    ``c`` at ``ids[r - 1, c - 1]``; ``row_z_mm`` (rows,) the design z of each row (mm, cell
    frame, undeformed, decreasing: row 1 is the top); ``col_theta_rad`` (columns,) the design
    theta of each column (rad, increasing); ``radius_mm`` the printed (outer) membrane surface's
    undeformed radius; ``height_mm`` the specimen's height.
    """

    ids: np.ndarray
    row_z_mm: np.ndarray
    col_theta_rad: np.ndarray
    radius_mm: float
    height_mm: float

    @property
    def rows(self) -> int:
        return int(self.ids.shape[0])

    @property
    def columns(self) -> int:
        return int(self.ids.shape[1])

    @property
    def n_dots(self) -> int:
        return int(self.ids.size)

    @property
    def first_id(self) -> int:
        """The smallest membrane ID (the kit's ``membrane: first_id``)."""
        return int(self.ids.min())

    @property
    def last_id(self) -> int:
        return int(self.ids.max())

    @property
    def n_cells(self) -> int:
        """Grid cells between two rows and two columns; the last column's closes the ring."""
        return (self.rows - 1) * self.columns

    def grid_index(self, ids: np.ndarray) -> np.ndarray:
        """(N,) int64 flat grid index ``(r - 1) * columns + (c - 1)`` of each ID, -1 for an ID
        that is not a membrane dot of this kit."""
        flat = self.ids.ravel()
        order = np.argsort(flat, kind="stable")
        ids = np.asarray(ids, np.int64)
        pos = np.clip(np.searchsorted(flat[order], ids), 0, flat.size - 1)
        found = flat[order][pos] == ids
        return np.where(found, order[pos], -1).astype(np.int64)

    def is_membrane(self, ids: np.ndarray) -> np.ndarray:
        """(N,) bool: which IDs are membrane dots of this kit."""
        return self.grid_index(ids) >= 0

    def cell_index(self, row: np.ndarray, col: np.ndarray) -> np.ndarray:
        """(N,) flat index ``(row - 1) * columns + (col - 1)`` of the cells of ``tables.STRAINS``
        (between grid rows ``row, row + 1`` and columns ``col, col + 1``), -1 outside the grid."""
        row, col = np.asarray(row, np.int64), np.asarray(col, np.int64)
        inside = (row >= 1) & (row < self.rows) & (col >= 1) & (col <= self.columns)
        return np.where(inside, (row - 1) * self.columns + col - 1, -1)

    def cell_corners(self) -> np.ndarray:
        """(n_cells, 4) flat grid indices of each cell's corner dots, in order around the quad,
        cells in :meth:`cell_index` order; the last column's cell closes the ring on column 1."""
        rr, cc = np.meshgrid(np.arange(self.rows - 1), np.arange(self.columns), indexing="ij")
        r, c = rr.ravel(), cc.ravel()
        c1 = (c + 1) % self.columns
        n = self.columns
        return np.column_stack([r * n + c, r * n + c1, (r + 1) * n + c1, (r + 1) * n + c])

    def theta_edges_deg(self) -> np.ndarray:
        """(columns + 1,) the design theta of columns 1..columns and column 1 again a turn
        later (deg): the edges of the cells of each row."""
        deg = np.rad2deg(self.col_theta_rad)
        return np.append(deg, deg[0] + 360.0)

    def column_of_theta(self, theta_deg: ArrayLike) -> np.ndarray:
        """The (fractional) column number at design theta (deg): column c is at its dots."""
        deg = np.rad2deg(self.col_theta_rad)
        return (np.asarray(theta_deg, float) - deg[0]) / 360.0 * self.columns + 1.0

    def theta_of_column(self, col: ArrayLike) -> np.ndarray:
        deg = np.rad2deg(self.col_theta_rad)
        return (np.asarray(col, float) - 1.0) * 360.0 / self.columns + deg[0]

    def row_of_z(self, z_mm: ArrayLike) -> np.ndarray:
        """The (fractional) row number at design z (mm), linear through the rows' z."""
        z0, z1 = float(self.row_z_mm[0]), float(self.row_z_mm[-1])
        return 1.0 + (np.asarray(z_mm, float) - z0) / (z1 - z0) * (self.rows - 1)

    def z_of_row(self, row: ArrayLike) -> np.ndarray:
        z0, z1 = float(self.row_z_mm[0]), float(self.row_z_mm[-1])
        return z0 + (np.asarray(row, float) - 1.0) / (self.rows - 1) * (z1 - z0)

    def describe(self) -> str:
        """E.g. '60 x 64 membrane dots, IDs 1001..4840'."""
        return f"{self.rows} x {self.columns} membrane dots, IDs {self.first_id}..{self.last_id}"


def membrane_layout(design: KitDesign) -> MembraneLayout:
    """The :class:`MembraneLayout` of a kit design (``kit.load_design`` or
    ``kit.load_kit_design``), from the kit's own target table. Raises ValueError when the
    design's membrane dots do not form a full grid of at least 2 rows and 2 columns."""
    table = target_table(design)
    mem = table.loc[table["surface"] == "membrane", ["id", "row", "col", "theta_rad", "z_mm"]]
    if mem.empty:
        raise ValueError("the kit design has no membrane dots")
    grid = mem.pivot(index="row", columns="col", values="id").sort_index().sort_index(axis=1)
    if grid.isna().any().any() or min(grid.shape) < 2:
        raise ValueError("the kit's membrane dots do not form a full grid of 2 rows and 2 columns or more")
    z = mem.groupby("row")["z_mm"].first().reindex(grid.index).to_numpy(float)
    theta = mem.groupby("col")["theta_rad"].first().reindex(grid.columns).to_numpy(float)
    return MembraneLayout(
        ids=grid.to_numpy(np.int64),
        row_z_mm=z,
        col_theta_rad=theta,
        radius_mm=float(membrane_radius(design)),
        height_mm=float(design.specimen.height),
    )
