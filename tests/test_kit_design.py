"""The kit design as typed, frozen dataclasses (issue 19): ``config/kit.yaml`` round-trips through
:class:`KitDesign`, a kit export reads back to the same design, and a bad design file is an error
naming the file, the section and the key."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import pytest
import yaml

from triaxtrack.calibrate import read_board
from triaxtrack.kit import load_kit_design
from triaxtrack.kit_design import BoardDesign, KitDesign, PedestalStripe, load_design

KIT_YAML = Path(__file__).resolve().parents[1] / "config" / "kit.yaml"


def write_design(tmp_path: Path, doc: dict) -> Path:
    path = tmp_path / "kit.yaml"
    path.write_text(yaml.safe_dump(doc, sort_keys=False))
    return path


def test_load_to_dict_from_dict_is_identity_on_config_kit_yaml(design):
    raw = yaml.safe_load(KIT_YAML.read_text())
    assert isinstance(design, KitDesign)
    assert design.to_dict() == raw and list(design.to_dict()) == list(raw)  # the file's keys, its order
    assert KitDesign.from_dict(design.to_dict()) == design
    assert design.specimen.height == 142.2 and design.membrane.columns == 64
    assert design.pedestal_targets.stripes[1] == PedestalStripe(
        "pedestal_bottom", "pedestal_bottom", 17, 16, 12.5
    )
    assert design.cell_targets.longitudinal_stripes[2].ct == 121
    assert design.coded_target.codes is None and design.cell.temperature_c == 20.0


def test_the_design_is_frozen(design):
    with pytest.raises(dataclasses.FrozenInstanceError):
        design.membrane.rows = 30
    assert isinstance(design.cell_targets.ct_stripes, tuple)


def test_a_kit_export_reads_back_to_the_design_with_its_printed_codes(design, kit_dir):
    back = load_kit_design(kit_dir)
    assert back.coded_target.codes is not None and len(back.coded_target.codes) == 92
    assert (
        dataclasses.replace(back, coded_target=dataclasses.replace(back.coded_target, codes=None)) == design
    )
    assert KitDesign.from_dict(back.to_dict()) == back
    assert read_board(kit_dir) == design.board


def test_a_board_json_of_another_printer_is_read_for_what_calibration_needs(tmp_path):
    """target-kit.md asks board.json for the type, squares and square size (and a marker
    dictionary if any): other keys are not read, a missing sheet margin is 0."""
    (tmp_path / "board.json").write_text(
        '{"type": "checkerboard", "squares_x": 9, "squares_y": 6, "square_mm": 25.0, "dictionary": null}'
    )
    board = read_board(tmp_path)
    assert (board.squares_x, board.squares_y, board.square_mm, board.margin_mm) == (9, 6, 25.0, 0.0)


def test_an_unknown_key_names_the_file_the_section_and_the_key(tmp_path):
    doc = yaml.safe_load(KIT_YAML.read_text())
    doc["membrane"]["colums"] = 64
    path = write_design(tmp_path, doc)
    with pytest.raises(
        ValueError, match=r"kit\.yaml: membrane: unknown key 'colums' \(did you mean 'columns'\?\)"
    ):
        load_design(path)
    doc = yaml.safe_load(KIT_YAML.read_text())
    doc["cell_targets"]["ct_stripes"][1]["zz"] = 1.0
    with pytest.raises(ValueError, match=r"kit\.yaml: cell_targets\.ct_stripes\[1\]: unknown key 'zz'"):
        load_design(write_design(tmp_path, doc))
    doc = yaml.safe_load(KIT_YAML.read_text())
    doc["lights"] = {}
    with pytest.raises(ValueError, match=r"kit\.yaml: kit design: unknown key 'lights'"):
        load_design(write_design(tmp_path, doc))


def test_a_missing_key_names_the_file_the_section_and_the_key(tmp_path):
    doc = yaml.safe_load(KIT_YAML.read_text())
    del doc["specimen"]["height"]
    with pytest.raises(ValueError, match=r"kit\.yaml: specimen: missing key 'height'"):
        load_design(write_design(tmp_path, doc))
    doc = yaml.safe_load(KIT_YAML.read_text())
    del doc["pedestal_targets"]["stripes"][0]["count"]
    with pytest.raises(ValueError, match=r"kit\.yaml: pedestal_targets\.stripes\[0\]: missing key 'count'"):
        load_design(write_design(tmp_path, doc))
    doc = yaml.safe_load(KIT_YAML.read_text())
    del doc["board"]
    with pytest.raises(ValueError, match=r"kit\.yaml: kit design: missing key 'board'"):
        load_design(write_design(tmp_path, doc))
    with pytest.raises(ValueError, match=r"kit\.yaml: not a kit design"):
        load_design(write_design(tmp_path, {"specimen": {}}))


def test_optional_keys_left_out_stay_out():
    doc = yaml.safe_load(KIT_YAML.read_text())
    del doc["cell"]["wavelength_nm"], doc["cell"]["temperature_c"], doc["board"]["type"]
    design = KitDesign.from_dict(doc)
    assert design.cell.wavelength_nm is None and design.board == BoardDesign(
        squares_x=16, squares_y=11, square_mm=12.5, margin_mm=20.0
    )
    assert (
        "wavelength_nm" not in design.to_dict()["cell"]
        and design.to_dict()["board"]["type"] == "checkerboard"
    )
