"""The target-kit design as typed, frozen dataclasses: :class:`KitDesign` and one dataclass per
section of ``config/kit.yaml`` (the kit export's ``kit.json`` + ``board.json`` hold the same).

Lengths in millimetres, angles in degrees (the file's units; :mod:`triaxtrack.kit` turns them
into radians), positions in the cell frame of ``target-kit.md``. Field names are the file's
keys. A section is read by :func:`triaxtrack.config_section.section_from_dict` (an unknown key
is a ValueError naming the section and the key); a key without a default that the file leaves
out is a ValueError naming the section and the key (:func:`load_design` and
:func:`triaxtrack.kit.load_kit_design` add the file). Values are kept as the file gives them
(no conversion), so the kit export writes them back unchanged. Lists of stripes are tuples.

:meth:`KitDesign.to_dict` is the mapping back (lists for tuples; a field that is None, one the
file may leave out, is left out): ``KitDesign.from_dict(d.to_dict()) == d``, and for a design
file whose optional keys are all given, ``to_dict`` gives the file's mapping back.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import MISSING, dataclass, fields, is_dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any, TypeVar

import yaml

from triaxtrack.config_section import field_names, section_dict, section_from_dict

if TYPE_CHECKING:
    from _typeshed import DataclassInstance

    T = TypeVar("T", bound=DataclassInstance)

__all__ = [
    "BoardDesign", "CellDesign", "CellDotStripe", "CellTargetsDesign", "CodedTargetDesign",
    "CtStripe", "KitDesign", "LongitudinalStripe", "MembraneDesign", "PedestalDesign",
    "PedestalStripe", "PedestalTargetsDesign", "SpecimenDesign", "WaterDesign", "board_design",
    "load_design",
]  # fmt: skip


def _checked(d: Mapping[str, Any] | None, section: str, cls: type[DataclassInstance]) -> dict[str, Any]:
    """A copy of the design section ``d`` whose keys are all ``cls``'s fields and hold every field
    without a default (values unconverted); ValueError naming ``section`` and the key at fault
    (:func:`section_dict` for an unknown key), or saying that ``d`` is not a mapping."""
    if d is None:
        raise ValueError(f"{section}: missing (a mapping of settings)")
    items = section_dict(d, section, field_names(cls))
    missing = [f.name for f in fields(cls) if f.default is MISSING and f.name not in items]
    if missing:
        plural = "s" if len(missing) > 1 else ""
        raise ValueError(f"{section}: missing key{plural} {', '.join(repr(k) for k in missing)}")
    return items


def _section(cls: type[T], d: Mapping[str, Any] | None, section: str) -> T:
    """``cls`` from the flat design section ``d`` (:func:`section_from_dict`, after
    :func:`_checked`); ValueError naming ``section`` and the key at fault."""
    _checked(d, section, cls)
    return section_from_dict(cls, d, section)


def _stripes(cls: type[T], items: Any, section: str) -> tuple[T, ...]:
    """A tuple of ``cls`` from the list of stripes ``items`` of ``section`` (each named
    ``section[i]`` in errors); ValueError for anything but a list."""
    if not isinstance(items, list | tuple):
        raise ValueError(f"{section}: must be a list of stripes, not {items!r}")
    return tuple(_section(cls, item, f"{section}[{i}]") for i, item in enumerate(items))


def _plain(value: Any) -> Any:
    """``value`` as the design file writes it: a dataclass a dict of its fields (None ones left
    out), a tuple a list, a dict copied; anything else as it is."""
    if is_dataclass(value) and not isinstance(value, type):
        return {f.name: _plain(v) for f in fields(value) if (v := getattr(value, f.name)) is not None}
    if isinstance(value, tuple | list):
        return [_plain(v) for v in value]
    if isinstance(value, dict):
        return {k: _plain(v) for k, v in value.items()}
    return value


@dataclass(frozen=True)
class SpecimenDesign:
    """The soil specimen, undeformed (section ``specimen``): ``diameter`` and ``height`` of the
    soil (mm), ``membrane_thickness`` of the latex (mm; the dots are on its outer surface)."""

    diameter: float
    height: float
    membrane_thickness: float


@dataclass(frozen=True)
class CellDesign:
    """The acrylic cell (section ``cell``): ``inner_radius``, ``outer_radius``, ``z_min``,
    ``z_max`` (mm, cell frame), ``refractive_index`` of the acrylic; ``wavelength_nm`` and
    ``temperature_c`` at which that index holds (None: not given, left out of the export)."""

    inner_radius: float
    outer_radius: float
    z_min: float
    z_max: float
    refractive_index: float
    wavelength_nm: float | None = None
    temperature_c: float | None = None


@dataclass(frozen=True)
class WaterDesign:
    """The water in the cell (section ``water``): its ``refractive_index``."""

    refractive_index: float


@dataclass(frozen=True)
class PedestalDesign:
    """Each of the two pedestals (section ``pedestal``): ``radius`` and ``height`` (mm)."""

    radius: float
    height: float


@dataclass(frozen=True)
class CodedTargetDesign:
    """The ring-coded target (section ``coded_target``), black on white: ``sectors`` of the code
    ring and the codes' ``min_distance`` (Hamming, rotation-invariant); radii (mm) of the black
    ``centre`` dot, of the code ring (``ring_inner_radius`` to ``ring_outer_radius``) and of the
    white ``label`` disc behind a pedestal CT. ``codes``: a kit export's printed code of every CT
    (ID as a string -> bit string, sector 0 first; authoritative); None for a design file (the
    family's codes, :func:`triaxtrack.kit.ct_codes`)."""

    sectors: int
    min_distance: int
    centre_radius: float
    ring_inner_radius: float
    ring_outer_radius: float
    label_radius: float
    codes: dict[str, str] | None = None


@dataclass(frozen=True)
class PedestalStripe:
    """A stripe of pedestal CTs: ``count`` CTs from ``first_id`` evenly around ``surface``
    (``pedestal_top`` or ``pedestal_bottom``), ``z_from_face`` (mm) from the specimen's face."""

    name: str
    surface: str
    first_id: int
    count: int
    z_from_face: float


@dataclass(frozen=True)
class PedestalTargetsDesign:
    """The pedestals' CTs (section ``pedestal_targets``): ``theta0`` (deg; must be 0, CT 17
    defines +x) of each stripe's first CT, and the ``stripes``."""

    theta0: float
    stripes: tuple[PedestalStripe, ...]

    @staticmethod
    def from_dict(d: Mapping[str, Any] | None, section: str = "pedestal_targets") -> PedestalTargetsDesign:
        """From the design's ``pedestal_targets`` section; ValueError naming section and key."""
        items = _checked(d, section, PedestalTargetsDesign)
        items["stripes"] = _stripes(PedestalStripe, items["stripes"], f"{section}.stripes")
        return PedestalTargetsDesign(**items)


@dataclass(frozen=True)
class CtStripe:
    """A stripe of cell-wall CTs: ``count`` CTs from ``first_id`` evenly around the cell from
    ``theta0`` of :class:`CellTargetsDesign`, at height ``z`` (mm)."""

    name: str
    first_id: int
    count: int
    z: float


@dataclass(frozen=True)
class CellDotStripe:
    """A stripe of cell-wall dots under the CT stripe named ``ct_stripe``: ``count`` dots from
    ``first_id`` (``dots_per_ct`` per CT; Eq. 1)."""

    name: str
    ct_stripe: str
    first_id: int
    count: int


@dataclass(frozen=True)
class LongitudinalStripe:
    """A longitudinal stripe of cell-wall dots at the angle of CT ``ct``: ``count`` dots from
    ``first_id``, IDs increasing downwards."""

    name: str
    first_id: int
    count: int
    ct: int


@dataclass(frozen=True)
class CellTargetsDesign:
    """The cell wall's targets (section ``cell_targets``): ``theta0`` (deg) of the first CT;
    the CT, dot and longitudinal stripes; ``dots_per_ct`` (the larger dot and smaller ones,
    evenly in theta); ``dot_offset`` (mm, D1: a dot stripe below its CT stripe); dot diameters
    (mm); the longitudinal stripes from ``longitudinal_z_top`` down to ``longitudinal_z_bottom``
    (mm); ``band_margin`` (mm) of the white label bands beyond the targets and the longitudinal
    bands' width (mm)."""

    theta0: float
    ct_stripes: tuple[CtStripe, ...]
    dot_stripes: tuple[CellDotStripe, ...]
    dots_per_ct: int
    dot_offset: float
    large_dot_diameter: float
    small_dot_diameter: float
    longitudinal_stripes: tuple[LongitudinalStripe, ...]
    longitudinal_z_top: float
    longitudinal_z_bottom: float
    longitudinal_dot_diameter: float
    band_margin: float
    longitudinal_band_width: float

    @staticmethod
    def from_dict(d: Mapping[str, Any] | None, section: str = "cell_targets") -> CellTargetsDesign:
        """From the design's ``cell_targets`` section; ValueError naming section and key."""
        items = _checked(d, section, CellTargetsDesign)
        for key, cls in (("ct_stripes", CtStripe), ("dot_stripes", CellDotStripe),
                         ("longitudinal_stripes", LongitudinalStripe)):  # fmt: skip
            items[key] = _stripes(cls, items[key], f"{section}.{key}")
        return CellTargetsDesign(**items)

    def longitudinal_spacing(self, stripe: LongitudinalStripe) -> float:
        """The distance (mm) between consecutive dots of a longitudinal ``stripe``: its dots evenly
        from ``longitudinal_z_top`` down to ``longitudinal_z_bottom``."""
        return (self.longitudinal_z_top - self.longitudinal_z_bottom) / (stripe.count - 1)


@dataclass(frozen=True)
class MembraneDesign:
    """The membrane's dot grid (section ``membrane``): ``rows`` (row 1 at the top) x ``columns``
    (column c at ``theta0`` (deg) + 360 (c - 1) / columns), IDs from ``first_id`` (Eq. 4); dot
    diameters (mm); every ``large_step``-th row and column from ``large_first`` a larger dot."""

    first_id: int
    columns: int
    rows: int
    theta0: float
    small_dot_diameter: float
    large_dot_diameter: float
    large_first: int
    large_step: int


@dataclass(frozen=True, kw_only=True)
class BoardDesign:
    """The camera-calibration board (section ``board``, the export's ``board.json``): a
    ``checkerboard`` (``type``, the only one) of ``squares_x`` x ``squares_y`` squares of
    ``square_mm`` (mm) on a sheet ``margin_mm`` (mm) wider on every side."""

    type: str = "checkerboard"
    squares_x: int
    squares_y: int
    square_mm: float
    margin_mm: float


@dataclass(frozen=True)
class KitDesign:
    """The whole kit design (``config/kit.yaml``; a kit export's ``kit.json`` + ``board.json``):
    format ``version``, the set-up (``specimen``, ``cell``, ``water``, ``pedestal``), the
    textures' ``texture_px_per_mm`` (texels per mm), the targets (``coded_target``,
    ``pedestal_targets``, ``cell_targets``, ``membrane``) and the calibration ``board``."""

    specimen: SpecimenDesign
    cell: CellDesign
    water: WaterDesign
    pedestal: PedestalDesign
    texture_px_per_mm: float
    coded_target: CodedTargetDesign
    pedestal_targets: PedestalTargetsDesign
    cell_targets: CellTargetsDesign
    membrane: MembraneDesign
    board: BoardDesign
    version: int = 1

    @staticmethod
    def from_dict(d: Mapping[str, Any] | None) -> KitDesign:
        """From a design mapping (the YAML file's); ValueError naming the section and the key."""
        items = _checked(d, "kit design", KitDesign)
        for key, cls in (("specimen", SpecimenDesign), ("cell", CellDesign), ("water", WaterDesign),
                         ("pedestal", PedestalDesign), ("coded_target", CodedTargetDesign),
                         ("membrane", MembraneDesign)):  # fmt: skip
            items[key] = _section(cls, items[key], key)
        items["board"] = board_design(items["board"])
        items["pedestal_targets"] = PedestalTargetsDesign.from_dict(items["pedestal_targets"])
        items["cell_targets"] = CellTargetsDesign.from_dict(items["cell_targets"])
        return KitDesign(**items)

    def to_dict(self) -> dict[str, Any]:
        """The design mapping (sections dicts, stripes lists of dicts, fields that are None left
        out; ``version`` first as the file writes it): ``from_dict(to_dict()) == self``."""
        plain = _plain(self)
        return {"version": plain.pop("version"), **plain}


def board_design(d: Mapping[str, Any] | None) -> BoardDesign:
    """:class:`BoardDesign` from a ``board`` section (``board.json`` less what the kit export
    adds); ValueError naming the section and the key at fault."""
    return _section(BoardDesign, d, "board")


def load_design(path: str | Path) -> KitDesign:
    """Read a kit design YAML (see ``config/kit.yaml``); raises ValueError naming the file (and
    the section and key at fault)."""
    path = Path(path)
    try:
        doc = yaml.safe_load(path.read_text())
    except (OSError, yaml.YAMLError) as err:
        raise ValueError(f"{path}: cannot read the kit design: {err}") from err
    if not isinstance(doc, dict) or "membrane" not in doc:
        raise ValueError(f"{path}: not a kit design (no 'membrane' section)")
    try:
        return KitDesign.from_dict(doc)
    except ValueError as err:
        raise ValueError(f"{path}: {err}") from err
