"""Specimen volume and membrane strains from the reconstructed membrane dots.

Units and conventions: positions in mm in the cell frame (origin the centre of the bottom
pedestal's top face, +z up the axis), volumes in mm^3, angles in radians, strains
dimensionless. The specimen strains of :data:`triaxtrack.tables.VOLUME` (axial, radial,
volumetric, and the volume change sign) are compression positive; the local Green-Lagrange
membrane strains of :data:`triaxtrack.tables.STRAINS` are tension positive.

Method
------
The dots are printed on the membrane's *outer* surface on a grid of rows (design z) and columns
(design theta). One frame's dots become a :class:`MembraneGrid`: missing dots -- single dots,
patches, whole columns, end rows -- are filled from that frame's measured dots and the rings
where the membrane is clamped on the two pedestals (:func:`~triaxtrack.volume.grid.fill_grid`:
thin-plate fill of cylindrical coordinates, the same rule for every frame). The top cap is a
rigid body: its coded targets give a rotation and translation from the design (:class:`TopCap`),
hence the specimen's top face plane and current height; the bottom face is the plane z = 0.

The soil volume is that inside the membrane's *inner* surface between the two faces:

1. ``mesh_volume_mm3``: the closed triangle mesh through the dot positions (the lateral surface
   continued per column to the two face planes, flat caps on the faces), by the divergence
   theorem ``V = 1/6 sum v0 . (v1 x v2)``.
2. ``chordal_mm3``: flat facets cut the chords of a convex surface (about 0.16 % of the volume
   for 64 columns). A smooth tensor interpolant of the dots -- periodic cubic spline in theta,
   not-a-knot cubic spline in design z, with two ghost rows beyond each end row extrapolated
   per column by a least-squares quadratic over the four end rows -- is meshed ``m`` and ``2 m``
   times finer (nodes at the dots are kept), and the facet volumes are Richardson-extrapolated
   (error ~ h^2) to the smooth surface's volume. The correction is that minus the dot mesh.
3. ``membrane_mm3``: the membrane shell, the volume between the outer surface and its inward
   offset by the local thickness ``t`` along the interpolant's unit normal (offset surfaces share
   their normals, so this inverts the printed-surface construction exactly). The inner surface
   is meshed, clipped to the face planes and Richardson-extrapolated the same way.
   :func:`membrane_thickness` models thinning of incompressible rubber, ``t = t0 A0 / A``, from
   the local area element of the (inner) surface against the reference (first) frame. The
   simulator instead thins by ``t0 / (lambda_theta lambda_z)``, which ignores the shear angle;
   the two agree except in a shear band (3 mm band: 1e-5 of the volume), and
   ``model="stretch"`` reproduces the simulator's.

``volume_mm3 = mesh_volume_mm3 + chordal_mm3 - membrane_mm3``.

Each column of a surface is cut at the face planes by Newton iteration on its spline in design
z, so every mesh's end rings lie exactly on the faces (a tilted top cap is handled). The grid's
columns are assumed evenly spaced in theta (as the kit prints them).

Each volume carries its 1-sigma standard uncertainty ``volume_sigma_mm3`` (mm^3): the measured
dots' and the top cap's errors (with the observations' influences, cameras as clusters: what
one camera's observations share counts in full) and the fill's error by a leave-out check of
the gaps on measured dots, in quadrature (:mod:`triaxtrack.volume.uncertainty`), and the
``measured_fraction`` of the membrane's dots.

Modules: :mod:`~triaxtrack.volume.grid` (the grid and its fill), :mod:`~triaxtrack.volume.cap`,
:mod:`~triaxtrack.volume.surface` (interpolant, face cuts, rings), :mod:`~triaxtrack.volume.mesh`
(volume, thickness, meshes), :mod:`~triaxtrack.volume.strains`,
:mod:`~triaxtrack.volume.uncertainty`, :mod:`~triaxtrack.volume.series` (all frames),
:mod:`~triaxtrack.volume.config` (the config section ``volume``: :class:`VolumeConfig`).

On the simulator's synthetic frames the soil volume is exact to ~3e-7 (1e-5 in a shear band,
see above); 0.02 mm noise on every point gives ~5e-5 (mostly the top cap's height).
"""

from triaxtrack.volume.cap import TopCap, rigid_fit, top_cap, top_cap_from_membrane
from triaxtrack.volume.config import VolumeConfig
from triaxtrack.volume.grid import (
    MAX_MISSING_SHARE,
    WARN_MISSING_SHARE,
    FaceEnds,
    MembraneGrid,
    face_ends,
    fill_grid,
    membrane_grid,
)
from triaxtrack.volume.mesh import (
    REFINE_LEVELS,
    VolumeResult,
    check_mesh,
    closed_mesh,
    membrane_thickness,
    specimen_volume,
    write_ply,
)
from triaxtrack.volume.series import frame_grid, run_measure_volume, volume_meshes, volume_series
from triaxtrack.volume.strains import strain_field
from triaxtrack.volume.surface import signed_volume
from triaxtrack.volume.uncertainty import VolumeUncertainty, volume_uncertainty

__all__ = [
    "MAX_MISSING_SHARE", "REFINE_LEVELS", "WARN_MISSING_SHARE", "FaceEnds", "MembraneGrid", "TopCap",
    "VolumeConfig", "VolumeResult", "VolumeUncertainty", "check_mesh", "closed_mesh", "face_ends",
    "fill_grid", "frame_grid", "membrane_grid", "membrane_thickness", "rigid_fit", "run_measure_volume",
    "signed_volume", "specimen_volume",
    "strain_field", "top_cap", "top_cap_from_membrane", "volume_meshes", "volume_series",
    "volume_uncertainty", "write_ply",
]  # fmt: skip
