"""Where every file of a test folder and of a results folder lives: each path pattern once.

Three layouts, each a frozen dataclass whose fields are path patterns relative to its folder
(``docs/test-folder.md``, "Layout" and "Results"; ``docs/architecture.md``, "Paths"), with
Snakemake's wildcards (``{camera}``, ``{chunk}``, ``{segment}``, ``{table}``) where a file is
one of many:

* :data:`RESULTS` (:class:`ResultsLayout`): a test's results, ``results/<test>/``; its
  ``simulated`` is the simulated test folder the workflow writes there;
* :data:`TEST_FOLDER` (:class:`TestFolderLayout`): a test folder (recorded or simulated):
  ``test.yaml``, ``videos/``, ``calibration/``, ``kit/``; its ``truth`` is a simulated one's
  ``truth/``;
* :data:`TRUTH` (:class:`TruthLayout`): a simulated test's ``truth/``.

``layout.under(root)`` is the same layout with ``root/`` before every pattern (nested layouts
too), and ``root`` set to it: the workflow's patterns are ``RESULTS.under("results/{test}")``
(``workflow/rules/common.smk``), one test's files ``RESULTS.under("results/demo")``; a wildcard
is filled by ``str.format`` (``R.calibration.format(camera="cam01")``) or Snakemake's
``expand``. The relative patterns join a folder's :class:`~pathlib.Path` as they are
(``results_dir / RESULTS.points``).
"""

from __future__ import annotations

from dataclasses import dataclass, field, fields, replace
from pathlib import Path
from typing import Any, TypeVar

L = TypeVar("L", bound="_Layout")


def _join(root: str, pattern: str) -> str:
    """root/pattern, as pathlib joins them (no "./" before a pattern under ".")."""
    return f"{root}/{pattern}" if root not in ("", ".") else pattern


@dataclass(frozen=True)
class _Layout:
    root: str = ""
    """The folder the patterns are under ("": relative to the layout's own folder)."""

    def under(self: L, root: str | Path) -> L:
        """This layout with ``root/`` before ``root`` and every pattern (nested layouts too)."""
        base = Path(root).as_posix() if isinstance(root, Path) else root.rstrip("/")
        moved: dict[str, Any] = {"root": _join(base, self.root) if self.root else base}
        for f in fields(self):
            value = getattr(self, f.name)
            if isinstance(value, _Layout):
                moved[f.name] = value.under(base)
            elif f.name != "root":
                moved[f.name] = _join(base, value)
        return replace(self, **moved)


@dataclass(frozen=True)
class TruthLayout(_Layout):
    """A simulated test's ``truth/``: the simulator's exact answers, which ``triaxtrack score`` reads."""

    cameras: str = "cameras.json"
    scene: str = "scene.json"
    volume: str = "volume.parquet"
    points: str = "points.parquet"
    observations: str = "observations.parquet"
    board_poses: str = "calibration/{camera}.json"
    load_frame: str = "loadframe.json"
    stress_strain: str = "stress_strain.parquet"


TRUTH = TruthLayout()


@dataclass(frozen=True)
class TestFolderLayout(_Layout):
    """A test folder (``docs/test-folder.md``, "Layout"): what a recorder writes, or the simulator."""

    __test__ = False  # not a pytest test class

    test_yaml: str = "test.yaml"
    kit: str = "kit"  # test.yaml's `kit` when it gives none
    video: str = "videos/{camera}.mp4"
    calibration_images: str = "calibration/{camera}"  # the camera's board images, *.png
    load_frame_log: str = "loadframe.csv"  # a simulated test's (a recorded one's: test.yaml)
    truth: TruthLayout = field(default_factory=lambda: TRUTH.under("truth"))


TEST_FOLDER = TestFolderLayout()


CSV_TABLES = ("volume", "stress_strain")
"""The result tables also exported as CSV (:class:`ResultsLayout` ``table_csv``), by name."""


@dataclass(frozen=True)
class ResultsLayout(_Layout):
    """A test's results folder, ``results/<test>/``, stage by stage (``docs/architecture.md``)."""

    # simulation (simulated tests only)
    simulated: TestFolderLayout = field(default_factory=lambda: TEST_FOLDER.under("simulated"))
    sim_chunk_video: str = "sim_chunks/{camera}/{segment}.mp4"
    sim_chunk_observations: str = "sim_chunks/{camera}/{segment}.parquet"
    simulation_check: str = "simulation_check.json"
    # inventory (recorded tests only)
    probe: str = "inventory/{camera}.json"
    inventory: str = "inventory.json"
    # per camera
    calibration: str = "calibration/{camera}.json"
    frames: str = "frames/{camera}.parquet"
    # identification, per camera and chunk, then collected
    chunk_labels: str = "identify/{camera}/{chunk}.parquet"
    chunk_frame: str = "identify/{camera}/{chunk}.png"
    chunk_overlay: str = "identify/{camera}/{chunk}_labels.png"
    labels: str = "labels.parquet"
    # the first frame's reconstruction
    cell: str = "reconstruction/cell.json"
    cell_points: str = "reconstruction/cell_points.parquet"
    air_residuals: str = "reconstruction/air_residuals.parquet"
    cameras: str = "cameras.json"
    first_points: str = "reconstruction/points.parquet"
    first_observations: str = "reconstruction/observations.parquet"
    first_quality: str = "reconstruction/quality.json"
    first_residuals: str = "reconstruction/residuals.parquet"
    reconstruction_picture: str = "reconstruction/reconstruction.png"
    # tracking, per camera and chunk; triangulation per chunk; then collected
    tracks: str = "track/{camera}/{chunk}.parquet"
    handover: str = "track/{camera}/{chunk}_handover.parquet"
    codec_lag: str = "codec_lag/{camera}.json"
    chunk_points: str = "timesteps/{chunk}.parquet"
    chunk_residuals: str = "timesteps/{chunk}_residuals.parquet"
    chunk_motion: str = "timesteps/{chunk}_motion.parquet"
    points: str = "points.parquet"
    observations: str = "observations.parquet"
    tracking: str = "tracking.parquet"
    quality: str = "quality.json"
    # volume, stress and exports
    volume: str = "volume.parquet"
    strains: str = "strains.parquet"
    mesh: str = "mesh"
    stress_strain: str = "stress_strain.parquet"
    clock: str = "clock.json"
    table: str = "{table}.parquet"  # a table of CSV_TABLES ...
    table_csv: str = "{table}.csv"  # ... and its CSV export
    paraview: str = "paraview"
    # the report's figures, movie and viewer
    volume_strain_figure: str = "report/volume_strain.png"
    strain_maps_figure: str = "report/strain_maps.png"
    reprojection_figure: str = "report/reprojection.png"
    tracking_figure: str = "report/tracking.png"
    cameras_figure: str = "report/cameras.png"
    specimen_movie: str = "report/specimen.mp4"
    specimen_player: str = "report/specimen.html"
    viewer: str = "report/viewer.html"
    q_strain_figure: str = "report/q_strain.png"
    volumetric_strain_figure: str = "report/volumetric_strain.png"
    modulus_figure: str = "report/modulus.png"

    def csv_of(self, table: str) -> str:
        """``table_csv`` of one of :data:`CSV_TABLES`: its CSV export."""
        if table not in CSV_TABLES:
            raise ValueError(f"{table!r} is not exported as CSV; tables: {CSV_TABLES}")
        return self.table_csv.replace("{table}", table)


RESULTS = ResultsLayout()
