"""The config section ``tracking``: :class:`TrackingConfig`, the settings of the tracker
(:func:`triaxtrack.track.track_frames`) and of the stages around it (which frames are decoded,
the codec-lag correction, camera motion and the chunk handover checks)."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

from triaxtrack.config_section import section_from_dict
from triaxtrack.detect import DetectParams


@dataclass(frozen=True)
class TrackingConfig:
    """Settings of config section ``tracking`` (config/README.md): ``step_s`` to
    ``ink_fraction`` are the tracker's (:func:`~triaxtrack.track.track_frames`), the rest the
    stages'."""

    step_s: float | None = None  # processed frames: every frame (None) or one every step_s seconds
    gate: float = 0.3  # max centroid shift from the prediction, x distance to the nearest detection
    min_separation: float = 0.5  # two targets closer than this x that distance: ambiguous
    mass_change: float = 0.25  # max relative change of a blob's mass from the chunk's first frame
    mass_step: float = 0.1  # max relative change of a blob's mass from the frame it was last seen
    max_flow_residual_px: float = 0.5  # max departure from the neighbours' affine motion, pixels
    first_agreement_px: float = 0.25  # at the labelled frame: max distance to the detection's centroid
    disc_margin_px: float = 1.0  # the blob's disc: its semi-major axis plus this, pixels
    ink_fraction: float = DetectParams.ink_fraction  # ink: darker than ink_fraction x the white level
    # the stages (rules track_targets, triangulate_chunk, collect_timesteps; the workflow)
    fast: bool = True  # with step_s: decode only the processed frames (False: every frame)
    complete_grid: bool = True  # take on membrane dots not labelled at a chunk's first frame
    codec_lag: bool = True  # correct the P frames' motion lag (rule measure_codec_lag)
    moved_px: float = 0.3  # a camera whose cell-wall targets drift by more (median) has moved, pixels
    handover_px: float = 1.0  # at a chunk boundary, tracked and labelled positions agree within this

    @staticmethod
    def from_dict(d: Mapping[str, Any] | None) -> TrackingConfig:
        """From the config's ``tracking`` section (ValueError naming an unknown key)."""
        return section_from_dict(TrackingConfig, d, "tracking")
