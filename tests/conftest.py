"""Shared fixtures: the default kit design and a tiny simulated test (built once per session)."""

from __future__ import annotations

from pathlib import Path

import pytest

from triaxtrack.kit import export_kit, load_design, target_table
from triaxtrack.kit_design import KitDesign

ROOT = Path(__file__).resolve().parents[1]


@pytest.fixture(scope="session")
def design() -> KitDesign:
    return load_design(ROOT / "config" / "kit.yaml")


@pytest.fixture(scope="session")
def table(design):
    return target_table(design)


@pytest.fixture(scope="session")
def kit_dir(design, tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("kit")
    export_kit(design, out)
    return out


@pytest.fixture(scope="session")
def small_test(kit_dir, tmp_path_factory) -> Path:
    """3 cameras x 4 frames at 960x540, a GOP of 2 frames and chunks of 2 (so two video
    segments are joined, each starting on the GOP grid)."""
    from triaxtrack.simulate import SimulationConfig, simulate_test

    out = tmp_path_factory.mktemp("sim") / "small"
    cfg = SimulationConfig(
        cameras=3, frames=4, width=960, height=540, calibration_images=3, axial_strain=0.08,
        gop_s=2 / 15,
    )  # fmt: skip
    simulate_test(cfg, kit_dir, out, "small", chunk_size=2)
    return out
