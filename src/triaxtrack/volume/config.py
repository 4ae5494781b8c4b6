"""The config section ``volume``: :class:`VolumeConfig`, the settings of the volume stage
(:func:`~triaxtrack.volume.series.run_measure_volume`) and of the stages that rebuild the
membrane surface from it (stress sections, the ParaView export, the 3-D viewer)."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

from triaxtrack.config_section import section_from_dict
from triaxtrack.volume.grid import MAX_MISSING_SHARE, WARN_MISSING_SHARE


@dataclass(frozen=True)
class VolumeConfig:
    """Settings of config section ``volume`` (config/README.md)."""

    membrane_thickness_mm: float | None = None  # unstretched membrane thickness; None: the kit's
    thickness_model: str = "area"  # thinning of the membrane: area (t0 A0/A) | stretch (t0 / (l_theta l_z))
    max_missing_share: float = MAX_MISSING_SHARE  # more membrane dots missing: no volume (NaN, reason)
    warn_missing_share: float = WARN_MISSING_SHARE  # more missing: measured, with a warning
    mesh_frames: int = 3  # frames whose soil surface is exported as PLY (first, last, evenly between)

    @staticmethod
    def from_dict(d: Mapping[str, Any] | None) -> VolumeConfig:
        """From the config's ``volume`` section (ValueError naming an unknown key)."""
        return section_from_dict(VolumeConfig, d, "volume")
