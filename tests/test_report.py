"""Tests for triaxtrack.report: figures and the movie of the HTML report, on synthetic tables."""

from __future__ import annotations

import av
import numpy as np
import pandas as pd
import pytest

from triaxtrack.report import (
    DIVERGING,
    MEMBRANE_COLS,
    MEMBRANE_FIRST_ID,
    MEMBRANE_ROWS,
    PALETTE,
    REASON_COLOURS,
    REPORTED,
    Series,
    bar_chart,
    chosen_frames,
    line_chart,
    reprojection_plot,
    specimen_frames,
    strain_map,
    strain_maps,
    tracking_plot,
    volume_strain_plot,
    write_movie,
    write_movie_page,
)
from triaxtrack.tables import POINTS, STRAINS, TRACKS, VOLUME, conform

FRAMES = 6
FPS = 5.0
HEIGHT_MM = 142.0
RADIUS_MM = 35.5
AXIAL = 0.05  # axial strain at the last frame, compression positive
BULGE_MM = 2.0  # radial bulge at mid-height at the last frame


def _progress(frame: int) -> float:
    return frame / (FRAMES - 1)


@pytest.fixture(scope="module")
def volume() -> pd.DataFrame:
    f = np.arange(FRAMES)
    s = f / (FRAMES - 1)
    v0 = np.pi * RADIUS_MM**2 * HEIGHT_MM
    df = pd.DataFrame({
        "frame": f, "time_s": f / FPS, "volume_mm3": v0 * (1 - 0.02 * s),
        "axial_strain": AXIAL * s, "volumetric_strain": 0.02 * s,
    })  # fmt: skip
    return conform(
        df.assign(
            height_mm=HEIGHT_MM * (1 - AXIAL * s),
            radial_strain=(0.02 * s - AXIAL * s) / 2,
            volume_change_mm3=-0.02 * s * v0,
        ),
        VOLUME,
    )


@pytest.fixture(scope="module")
def strains() -> pd.DataFrame:
    """Cells of the 60 x 64 grid at every frame: e_zz compressive with a cos(theta) tilt,
    e_tt tensile, largest at mid-height (a bulge)."""
    row, col = np.meshgrid(np.arange(1, MEMBRANE_ROWS), np.arange(1, MEMBRANE_COLS + 1), indexing="ij")
    theta = (col - 0.5) / MEMBRANE_COLS * 2 * np.pi
    z = (row - 0.5) * HEIGHT_MM / (MEMBRANE_ROWS - 1)
    parts = []
    for f in range(FRAMES):
        s = _progress(f)
        parts.append(pd.DataFrame({
            "frame": f, "time_s": f / FPS, "row": row.ravel(), "col": col.ravel(),
            "theta_rad": theta.ravel(), "z_mm": z.ravel(),
            "e_zz": (-AXIAL * s * (1 + 0.3 * np.cos(theta))).ravel(),
            "e_tt": (BULGE_MM / RADIUS_MM * s * np.sin(np.pi * z / HEIGHT_MM)).ravel(),
            "e_tz": 0.0,
        }))  # fmt: skip
    return conform(pd.concat(parts, ignore_index=True), STRAINS)


@pytest.fixture(scope="module")
def points() -> pd.DataFrame:
    """The membrane dots (IDs 1001..4840) of a specimen shortening and bulging, and 32 pedestal
    coded targets (IDs 1..32) on the two platens; dot 1001 is missing at frame 2."""
    r, c = np.meshgrid(np.arange(1, MEMBRANE_ROWS + 1), np.arange(1, MEMBRANE_COLS + 1), indexing="ij")
    ids = ((r - 1) * MEMBRANE_COLS + c + MEMBRANE_FIRST_ID - 1).ravel()
    theta = ((c - 1) / MEMBRANE_COLS * 2 * np.pi).ravel()
    z0 = ((r - 1) * HEIGHT_MM / (MEMBRANE_ROWS - 1)).ravel()
    ct = np.arange(32)
    parts = []
    for f in range(FRAMES):
        s = _progress(f)
        radius = RADIUS_MM + BULGE_MM * s * np.sin(np.pi * z0 / HEIGHT_MM)
        z = z0 * (1 - AXIAL * s)
        top = HEIGHT_MM * (1 - AXIAL * s) + 5
        parts.append(pd.DataFrame({
            "frame": f, "time_s": f / FPS, "id": ids, "x_mm": radius * np.cos(theta),
            "y_mm": radius * np.sin(theta), "z_mm": z, "n_rays": 4, "rms_px": 0.1,
        }))  # fmt: skip
        a = ct % 16 / 16 * 2 * np.pi
        parts.append(pd.DataFrame({
            "frame": f, "time_s": f / FPS, "id": ct + 1, "x_mm": 45 * np.cos(a), "y_mm": 45 * np.sin(a),
            "z_mm": np.where(ct < 16, -5.0, top), "n_rays": 3, "rms_px": 0.1,
        }))  # fmt: skip
    df = pd.concat(parts, ignore_index=True)
    df = df[~((df["frame"] == 2) & (df["id"] == MEMBRANE_FIRST_ID))]
    return conform(df, POINTS)


@pytest.fixture(scope="module")
def tracks() -> pd.DataFrame:
    rng = np.random.default_rng(3)
    cams = [f"cam{k:02d}" for k in range(1, 5)]
    cam, frame, tid = (
        a.ravel() for a in np.meshgrid(cams, np.arange(FRAMES), np.arange(1001, 1201), indexing="ij")
    )
    reasons = np.array(["", "lost", "edge", "merged", "jump"], dtype=object)  # object: room for longer ones
    reason = rng.choice(reasons, size=cam.size, p=[0.9, 0.04, 0.03, 0.02, 0.01])
    reason[(cam == "cam03") & (frame == 4)] = "not_recorded"
    df = pd.DataFrame({"camera": cam, "frame": frame, "id": tid, "u_px": 1.0, "v_px": 2.0, "area_px": 9.0,
                       "sigma_px": 0.03, "reason": reason})  # fmt: skip
    df.loc[df["reason"] != "", ["u_px", "v_px", "sigma_px"]] = np.nan
    return conform(df, TRACKS)


def _drawn(img: np.ndarray) -> None:
    """A BGR uint8 image with something drawn on it (not one colour)."""
    assert img.dtype == np.uint8 and img.ndim == 3 and img.shape[2] == 3
    packed = img.reshape(-1, 3).astype(np.int32) @ np.array([1 << 16, 1 << 8, 1], np.int32)
    assert img.min() < 100 and img.max() == 255 and len(np.unique(packed)) > 10


# --------------------------------------------------------------------------- chosen_frames


@pytest.mark.parametrize(
    ("frames", "n", "expected"),
    [
        (range(10), 4, [0, 3, 6, 9]),
        (range(100), 2, [0, 99]),
        ([5, 1, 3, 3], 5, [1, 3, 5]),  # fewer frames than n: all, sorted, once each
        ([7, 8, 9], 3, [7, 8, 9]),
        (range(10), 1, [9]),  # one: the last, most deformed
        (range(10), 0, []),
        ([], 3, []),
        ([4], 3, [4]),
    ],
)
def test_chosen_frames(frames, n, expected):
    assert chosen_frames(frames, n) == expected


def test_chosen_frames_spread():
    got = chosen_frames(range(0, 1000, 2), 6)
    assert got[0] == 0 and got[-1] == 998 and len(got) == 6
    gaps = np.diff(got)
    assert gaps.max() - gaps.min() <= 2


# --------------------------------------------------------------------------- charts


def test_line_chart_breaks_and_no_data():
    x = np.arange(20.0)
    y = np.sin(x)
    y[5:8] = np.nan
    img = line_chart([Series("sin", x, y, (0, 0, 255))], "t", "x", "y", size=(400, 250), hlines=[0])
    assert img.shape == (250, 400, 3)
    _drawn(img)
    assert (img == (0, 0, 255)).all(axis=2).any()  # the line's colour is there
    empty = line_chart([Series("nan", x, np.full_like(x, np.nan), (0, 0, 255))], size=(400, 250))
    assert empty.shape == (250, 400, 3) and not (empty == (0, 0, 255)).all(axis=2).any()


def test_bar_chart_long_labels_are_vertical():
    labels = [f"a-very-long-camera-name-{k}" for k in range(12)]
    img = bar_chart(labels, [("n", np.arange(12.0), (180, 119, 31))], "bars", "n", size=(500, 300))
    assert img.shape[1] == 500 and img.shape[0] > 300  # grown to fit the labels under the axis
    _drawn(img)


# --------------------------------------------------------------------------- figures


def test_volume_strain_plot(volume):
    img = volume_strain_plot(volume)
    assert img.shape == (680, 900, 3)
    _drawn(img)


def test_volume_strain_plot_without_optional_columns(volume):
    plain = volume[list(VOLUME.columns)]
    img = volume_strain_plot(plain)
    assert img.shape == (680, 900, 3)
    _drawn(img)
    orange = (14, 127, 255)  # the radial strain's colour: no such line now
    assert not (img == orange).all(axis=2).any()
    assert (volume_strain_plot(volume) == orange).all(axis=2).any()


def test_strain_map(strains):
    img = strain_map(strains, FRAMES - 1, "e_zz")
    _drawn(img)
    # e_zz = -0.05 (1 + 0.3 cos theta): most compressive (blue) at theta = 0, least at 180 deg
    left = img[60, 60].astype(int)  # near theta = 0 (the map starts at x = 52)
    mid = img[60, 52 + 160].astype(int)  # theta = 180 deg
    assert left[0] > left[2]  # blue
    assert np.abs(left - DIVERGING[127, 0]).sum() > np.abs(mid - DIVERGING[127, 0]).sum()
    assert strain_map(strains, 0, "e_tt", colorbar=False).shape[1] < img.shape[1]
    with pytest.raises(ValueError, match="frame 99"):
        strain_map(strains, 99)
    with pytest.raises(ValueError, match="e_xx"):
        strain_map(strains, 0, "e_xx")


def test_strain_map_missing_cells_are_grey(strains):
    last = strains[strains["frame"] == FRAMES - 1]
    img = strain_map(last[last["col"] != 32], FRAMES - 1, "e_tt")  # a whole column missing
    _drawn(img)


def test_strain_maps(strains):
    frames = chosen_frames(strains["frame"].unique(), 3)
    img = strain_maps(strains, frames)
    one = strain_map(strains, frames[0], colorbar=False)
    assert img.shape[0] == 28 + 2 * one.shape[0]  # title line, then e_zz and e_tt
    assert img.shape[1] > 3 * one.shape[1]
    _drawn(img)
    _drawn(strain_maps(strains, [123]))  # no such frame: a "no data" figure


def test_reprojection_plot():
    quality = {
        "mean_reprojection_px": 0.12,
        "per_camera": {
            f"cam{k:02d}": {
                "mean_reprojection_px": 0.05 + 0.01 * k,
                "observations_used": 3000 + k,
                "observations_dropped": k,
            }  # fmt: skip
            for k in range(1, 14)
        },
        "per_frame": [{"frame": f, "mean_reprojection_px": 0.1 + 0.01 * f} for f in range(FRAMES)],
    }
    img = reprojection_plot(quality)
    assert img.shape[1] == 900 and img.shape[0] == 360 + 300
    _drawn(img)
    # absent keys: no per_frame, a camera without counts, a NaN, no overall mean
    sparse = {
        "per_camera": {
            "cam01": {"mean_reprojection_px": 0.2},
            "cam02": {"mean_reprojection_px": float("nan")},
        }
    }
    img = reprojection_plot(sparse)
    assert img.shape == (360, 900, 3)
    _drawn(img)
    assert reprojection_plot({}).shape == (360, 900, 3)
    # the per-frame errors of quality.json's `frames` list (no `per_frame`); entries without one skipped
    frames = [{"frame": f, "time_s": f / FPS, "mean_reprojection_px": 0.1} for f in range(FRAMES)]
    assert reprojection_plot({**sparse, "frames": frames}).shape == (660, 900, 3)
    assert reprojection_plot({**sparse, "frames": [{"frame": 0, "targets_reconstructed": 9}]}).shape == (
        360,
        900,
        3,
    )


def test_tracking_plot(tracks):
    img = tracking_plot(tracks)
    assert img.shape == (300 + 300 + 340, 900, 3)
    _drawn(img)
    # the share reported is drawn, and the losses in their reasons' colours
    for colour in (REPORTED, REASON_COLOURS["lost"], REASON_COLOURS["jump"]):
        assert (img == colour).all(axis=2).any()
    all_found = tracks.assign(reason="")
    _drawn(tracking_plot(all_found))
    _drawn(tracking_plot(tracks.iloc[:0]))


def test_camera_quality_and_plot(tracks):
    """Per camera: targets labelled, tracked share (frames not recorded left out) and sigma."""
    from triaxtrack.camera_report import camera_quality, camera_quality_plot

    noisy = tracks.copy()
    cam02 = (noisy["camera"] == "cam02") & (noisy["reason"] == "")
    noisy.loc[cam02, "sigma_px"] = np.linspace(0.1, 0.3, int(cam02.sum()))  # poorer footage
    labels = pd.DataFrame({"camera": ["cam01"] * 3 + ["cam02"] * 2, "frame": [0, 0, 3, 0, 0],
                           "id": [1001, 1002, 1001, 1001, -1]})  # fmt: skip
    q = camera_quality(noisy, labels).set_index("camera")
    assert q.index.tolist() == ["cam01", "cam02", "cam03", "cam04"]
    t = tracks.set_index("camera")
    for cam in q.index:
        mine = t.loc[cam]
        recorded = mine[mine["reason"] != "not_recorded"]
        assert q.loc[cam, "target_frames"] == len(recorded)
        assert q.loc[cam, "tracked_share"] == pytest.approx((recorded["reason"] == "").mean())
    assert len(t.loc["cam03"]) > q.loc["cam03", "target_frames"]  # frame 4 not recorded
    assert q.loc["cam01", "sigma_median_px"] == pytest.approx(0.03)
    assert q.loc["cam02", "sigma_median_px"] == pytest.approx(0.2)
    assert 0.28 < q.loc["cam02", "sigma_p95_px"] < 0.3
    assert (q.loc["cam01", "labelled_frames"], q.loc["cam01", "labelled_median"]) == (2, 1.5)
    assert q.loc["cam02", "labelled_median"] == 1 and np.isnan(q.loc["cam03", "labelled_median"])
    assert np.isnan(camera_quality(tracks)["labelled_median"]).all()
    img = camera_quality_plot(q.reset_index())
    assert img.shape[1] == 900 and img.shape[0] >= 680
    _drawn(img)
    assert (img == REPORTED).all(axis=2).any()  # the tracked share's bars
    lost = tracks.assign(reason="lost", sigma_px=np.nan)  # nothing tracked: n/a, no sigma
    q_lost = camera_quality(lost)
    assert (q_lost["tracked_share"] == 0).all() and q_lost["sigma_median_px"].isna().all()
    _drawn(camera_quality_plot(q_lost))


def test_volume_plot_band_and_measured_fraction(volume):
    v0 = float(volume["volume_mm3"].iloc[0])
    extra = volume.assign(volume_sigma_mm3=0.002 * v0, measured_fraction=np.linspace(0.95, 0.8, FRAMES))
    img = volume_strain_plot(extra)
    assert img.shape == (680 + 260, 900, 3)
    _drawn(img)
    band = np.array(PALETTE[9])  # the +- 1 sigma lines (thin, antialiased: near their colour)

    def near(im: np.ndarray) -> int:
        return int((np.abs(im[:340].astype(int) - band).max(axis=2) < 40).sum())

    assert near(img) > 200 and near(volume_strain_plot(volume)) == 0
    no_sigma = volume_strain_plot(extra.assign(volume_sigma_mm3=np.nan))
    assert no_sigma.shape == img.shape and near(no_sigma) == 0


# --------------------------------------------------------------------------- movie


def test_specimen_frames_radial(points):
    frames = list(specimen_frames(points, height=301))
    assert len(frames) == FRAMES
    h, w = frames[0].shape[:2]
    assert h == 302 and h % 2 == 0 and w % 2 == 0
    assert all(f.shape == frames[0].shape and f.dtype == np.uint8 for f in frames)
    for f in frames:
        _drawn(f)
    # the first frame has no displacement: grey-ish membrane; the last bulges: red at mid-height
    centre = (h // 2, frames[0].shape[1] // 4)
    b0, g0, r0 = frames[0][centre].astype(int)
    b1, g1, r1 = frames[-1][centre].astype(int)
    assert abs(r0 - b0) < 20 and r1 - b1 > 40
    assert not np.array_equal(frames[0], frames[-1])


def test_specimen_frames_strain_and_choice(points, strains):
    frames = list(specimen_frames(points, strains, colour_by="e_tt", frames=[0, 4, 77], views_deg=(30.0,)))
    assert len(frames) == 2  # frame 77 is not in the table
    _drawn(frames[1])
    magnified = next(specimen_frames(points, frames=[FRAMES - 1], magnify=3.0))
    _drawn(magnified)
    with pytest.raises(ValueError, match="strains"):
        specimen_frames(points, None, colour_by="e_zz")
    with pytest.raises(ValueError, match="membrane"):
        specimen_frames(points[points["id"] < MEMBRANE_FIRST_ID])


def test_write_movie_decodes(points, tmp_path):
    path = tmp_path / "specimen.mp4"
    frames = list(specimen_frames(points, height=240))
    h, w = frames[0].shape[:2]
    n = write_movie(iter(frames), path, fps=FPS)
    assert n == FRAMES
    with av.open(str(path)) as container:
        stream = container.streams.video[0]
        assert stream.codec_context.name == "h264"
        decoded = [fr.to_ndarray(format="bgr24") for fr in container.decode(stream)]
    assert len(decoded) == FRAMES
    assert decoded[0].shape == (h, w, 3)
    assert np.abs(decoded[-1].astype(int) - frames[-1]).mean() < 6  # colours survive the encoding

    page = tmp_path / "specimen.html"
    write_movie_page(path, page, "demo")
    text = page.read_text()
    assert "<video" in text and "data:video/mp4;base64," in text and len(text) > path.stat().st_size


def test_write_movie_pads_odd_sizes_and_checks(tmp_path):
    rng = np.random.default_rng(0)
    frames = [rng.integers(0, 255, (31, 45, 3), dtype=np.uint8) for _ in range(3)]
    assert write_movie(frames, tmp_path / "odd.mp4", fps=10) == 3
    with av.open(str(tmp_path / "odd.mp4")) as container:
        ctx = container.streams.video[0].codec_context
        assert (ctx.width, ctx.height) == (46, 32)
    with pytest.raises(ValueError, match="no frames"):
        write_movie([], tmp_path / "none.mp4", fps=10)
    with pytest.raises(ValueError, match="shape"):
        write_movie([frames[0], frames[0][:20]], tmp_path / "bad.mp4", fps=10)
