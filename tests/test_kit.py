"""The design table equals the paper's Table 1, and the export honours target-kit.md."""

from __future__ import annotations

import json
from dataclasses import replace

import cv2
import numpy as np
import pandas as pd
import pytest

from triaxtrack.codes import code_family, decode_ring_code, necklace_distance, rotations
from triaxtrack.kit import eq1_dot_id, large_dot_index, membrane_id

TABLE_1 = [  # (first ID, last ID, count) per stripe, paper Table 1
    (1, 16, 16), (17, 32, 16), (101, 130, 30), (131, 160, 30), (161, 280, 120),
    (281, 400, 120), (401, 460, 60), (461, 520, 60), (521, 580, 60), (1001, 4840, 3840),
]  # fmt: skip


def test_table_1_ranges_and_counts(table):
    assert len(table) == 4352
    assert table.id.is_unique
    for first, last, count in TABLE_1:
        sel = table[(table.id >= first) & (table.id <= last)]
        assert len(sel) == count == last - first + 1
    assert set(table.loc[table.kind == "coded", "id"]) == set(range(1, 33)) | set(range(101, 161))
    assert (table.kind == "coded").sum() == 92 and (table.kind == "dot").sum() == 4260


def test_eq1_examples_and_geometry(design, table):
    assert eq1_dot_id(114, design) == 213
    assert eq1_dot_id(101, design) == 161
    assert eq1_dot_id(160, design) == 397
    t = table.set_index("id")
    for ct in range(101, 161):
        dot = eq1_dot_id(ct, design)
        assert t.loc[dot, "large"]
        assert t.loc[dot, "theta_rad"] == pytest.approx(t.loc[ct, "theta_rad"], abs=1e-12)
        assert t.loc[dot, "z_mm"] == pytest.approx(t.loc[ct, "z_mm"] - design.cell_targets.dot_offset)
        # the three smaller dots between follow in theta
        assert not t.loc[[dot + 1, dot + 2, dot + 3], "large"].any()
    # pedestal pairs differ by 16 and share theta; CT 17 is on +x
    for i in range(1, 17):
        assert t.loc[i, "theta_rad"] == pytest.approx(t.loc[i + 16, "theta_rad"])
    assert t.loc[17, "theta_rad"] == pytest.approx(0.0)


def test_membrane_equations(design, table):
    m = design.membrane
    t = table.set_index("id")
    assert membrane_id(1, 1, m) == 1001 and membrane_id(60, 64, m) == 4840
    assert membrane_id(2, 1, m) == 1065
    large = t[(t.surface == "membrane") & t.large]
    assert len(large) == 16 * 15
    for C in (1, 7, 16):
        for R in (1, 15):
            c, r = large_dot_index(C, R, m)
            tid = membrane_id(r, c, m)
            assert t.loc[tid, "large"]
            assert t.loc[tid, "theta_rad"] == pytest.approx(t.loc[C + 16, "theta_rad"])  # under CT pair C
    assert large_dot_index(1, 1, m) == (1, 1)  # the printed Eq. 2 would give c = -1 here


def test_ring_codes_family_distance_and_decoding():
    n, d = 17, 3
    fam = code_family(n, d)
    assert len(fam) >= 160
    rng = np.random.default_rng(0)
    pairs = rng.choice(len(fam), size=(400, 2))
    for a, b in pairs:
        if a != b:
            assert necklace_distance(fam[a], fam[b], n) >= d
    table = {i + 1: fam[i] for i in range(160)}
    for tid in (1, 17, 101, 160):
        rot = rotations(table[tid], n)[rng.integers(n)]
        bits = np.array([(rot >> k) & 1 for k in range(n)])
        assert decode_ring_code(bits, table, d) == tid
        bits[rng.integers(n)] ^= 1  # one bad sector is corrected
        assert decode_ring_code(bits, table, d) == tid


def test_export_files(kit_dir, table):
    kit = json.loads((kit_dir / "kit.json").read_text())
    assert kit["version"] == 1 and kit["units"] == "mm"
    assert {s["name"] for s in kit["surfaces"]} == {
        "membrane",
        "cell_outer",
        "pedestal_bottom",
        "pedestal_top",
    }
    csv = pd.read_csv(kit_dir / "targets.csv")
    assert list(csv.columns[:6]) == ["id", "kind", "surface", "theta_rad", "z_mm", "diameter_mm"]
    assert len(csv) == 4352
    for s in kit["surfaces"]:
        img = cv2.imread(str(kit_dir / s["texture"]), cv2.IMREAD_UNCHANGED)
        assert img.shape == (s["texture_size"][1], s["texture_size"][0], 4) and img.dtype == np.uint8
        assert (kit_dir / "sheets" / f"{s['name']}.svg").read_text().count("check bar") == 1
    board = json.loads((kit_dir / "board.json").read_text())
    assert board["type"] == "checkerboard" and board["inner_corners"] == [15, 10]
    assert cv2.imread(str(kit_dir / "board.png")).shape[:2] == (1775, 2400)  # (137.5 + 40) x (200 + 40) mm
    assert (kit_dir / "README.md").exists()
    assert len(kit["coded_target"]["codes"]) == 92


@pytest.mark.parametrize("surface", ["membrane", "cell_outer"])
def test_target_centre_is_centroid_of_printed_texels(kit_dir, surface):
    """A dot's centre in targets.csv is the alpha-weighted centroid of its texels (< 0.05 texel)."""
    kit = json.loads((kit_dir / "kit.json").read_text())
    s = next(x for x in kit["surfaces"] if x["name"] == surface)
    rgba = cv2.imread(str(kit_dir / s["texture"]), cv2.IMREAD_UNCHANGED)
    w, h = s["texture_size"]
    # ink = dark and printed: alpha * (1 - grey / 255)
    ink = rgba[..., 3] / 255.0 * (1 - rgba[..., 0] / 255.0)
    t = pd.read_csv(kit_dir / "targets.csv")
    dots = t[(t.surface == surface) & (t.kind == "dot")].sample(200, random_state=1)
    errs = []
    for r in dots.itertuples():
        u = r.theta_rad * w / (2 * np.pi) - 0.5
        v = (s["z_max"] - r.z_mm) * h / (s["z_max"] - s["z_min"]) - 0.5
        half = int(np.ceil(r.diameter_mm / 2 * kit["texture_px_per_mm"])) + 2
        u0, v0 = int(round(u)), int(round(v))
        if u0 - half < 0 or u0 + half >= w:
            continue  # wraps around theta = 0
        win = ink[v0 - half : v0 + half + 1, u0 - half : u0 + half + 1]
        ys, xs = np.mgrid[v0 - half : v0 + half + 1, u0 - half : u0 + half + 1]
        errs.append(np.hypot((win * xs).sum() / win.sum() - u, (win * ys).sum() / win.sum() - v))
    assert len(errs) > 150
    assert max(errs) < 0.05


def test_sheets_print_targets_across_theta_zero(kit_dir):
    """CT 17 sits at theta = 0: its sheet prints it whole, split over both ends of the sheet."""
    import re

    svg = (kit_dir / "sheets" / "pedestal_bottom.svg").read_text()
    width = float(re.search(r'width="([\d.]+)mm"', svg).group(1))
    xs = np.array([float(x) for x in re.findall(r"[ML]([-\d.]+),", svg)])
    assert xs.min() < 0 and xs.max() > width  # copies on both sides of the seam


def test_pedestal_theta0_must_be_zero(design):
    from triaxtrack.kit import target_table

    bad = replace(design, pedestal_targets=replace(design.pedestal_targets, theta0=5.0))
    with pytest.raises(ValueError, match="CT 17"):
        target_table(bad)


def test_codes_read_back_from_the_export(kit_dir, design, table):
    from triaxtrack.kit import ct_codes, load_kit_design

    assert ct_codes(load_kit_design(kit_dir), table) == ct_codes(design, table)
