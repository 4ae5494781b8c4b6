"""Tests for triaxtrack.report: figures (matplotlib) and the movie of the HTML report, on
synthetic tables built on a kit's membrane grid (the default kit's, and one of other counts)."""

from __future__ import annotations

import av
import cv2
import numpy as np
import pandas as pd
import pytest
from matplotlib import _pylab_helpers
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.collections import PolyCollection, QuadMesh
from matplotlib.figure import Figure

from triaxtrack.camera_report import camera_quality, camera_quality_figure
from triaxtrack.report import (
    DIVERGING,
    REASON_COLOURS,
    REPORTED,
    chosen_frames,
    figure_image,
    membrane_layout,
    reprojection_figure,
    save_figure,
    specimen_frames,
    strain_map_figure,
    strain_maps_figure,
    tracking_figure,
    volume_strain_figure,
    write_movie,
    write_movie_page,
)
from triaxtrack.report.layout import MembraneLayout
from triaxtrack.tables import POINTS, STRAINS, TRACKS, VOLUME, conform

MIN_PIXEL_STD = 10.0  # grey levels: a figure with axes, text and data, not a blank page

FRAMES = 6
FPS = 5.0
AXIAL = 0.05  # axial strain at the last frame, compression positive
BULGE_MM = 2.0  # radial bulge at mid-height at the last frame
PEDESTAL_IDS = np.arange(1, 33)  # coded targets on the two platens (not membrane dots)


def _progress(frame: int) -> float:
    return frame / (FRAMES - 1)


def volume_table(layout: MembraneLayout) -> pd.DataFrame:
    f = np.arange(FRAMES)
    s = f / (FRAMES - 1)
    v0 = np.pi * layout.radius_mm**2 * layout.height_mm
    df = pd.DataFrame({
        "frame": f, "time_s": f / FPS, "volume_mm3": v0 * (1 - 0.02 * s),
        "axial_strain": AXIAL * s, "volumetric_strain": 0.02 * s,
    })  # fmt: skip
    return conform(
        df.assign(
            height_mm=layout.height_mm * (1 - AXIAL * s),
            radial_strain=(0.02 * s - AXIAL * s) / 2,
            volume_change_mm3=-0.02 * s * v0,
        ),
        VOLUME,
    )


def strains_table(layout: MembraneLayout) -> pd.DataFrame:
    """Every cell of the kit's grid at every frame: e_zz compressive with a cos(theta) tilt,
    e_tt tensile, largest at mid-height (a bulge)."""
    row, col = np.meshgrid(np.arange(1, layout.rows), np.arange(1, layout.columns + 1), indexing="ij")
    theta = layout.col_theta_rad[col - 1] + np.pi / layout.columns
    z = (layout.row_z_mm[row - 1] + layout.row_z_mm[row]) / 2
    parts = []
    for f in range(FRAMES):
        s = _progress(f)
        parts.append(pd.DataFrame({
            "frame": f, "time_s": f / FPS, "row": row.ravel(), "col": col.ravel(),
            "theta_rad": theta.ravel(), "z_mm": z.ravel(),
            "e_zz": (-AXIAL * s * (1 + 0.3 * np.cos(theta))).ravel(),
            "e_tt": (BULGE_MM / layout.radius_mm * s * np.sin(np.pi * z / layout.height_mm)).ravel(),
            "e_tz": 0.0,
        }))  # fmt: skip
    return conform(pd.concat(parts, ignore_index=True), STRAINS)


def points_table(layout: MembraneLayout) -> pd.DataFrame:
    """The kit's membrane dots on a specimen shortening and bulging, and 32 pedestal coded
    targets on the two platens; the first membrane dot is missing at frame 2."""
    ids = layout.ids.ravel()
    theta = np.broadcast_to(layout.col_theta_rad, layout.ids.shape).ravel()
    z0 = np.broadcast_to(layout.row_z_mm[:, None], layout.ids.shape).ravel()
    height, radius = layout.height_mm, layout.radius_mm
    ct = np.arange(len(PEDESTAL_IDS))
    parts = []
    for f in range(FRAMES):
        s = _progress(f)
        r = radius + BULGE_MM * s * np.sin(np.pi * z0 / height)
        top = height * (1 - AXIAL * s) + 5
        parts.append(pd.DataFrame({
            "frame": f, "time_s": f / FPS, "id": ids, "x_mm": r * np.cos(theta), "y_mm": r * np.sin(theta),
            "z_mm": z0 * (1 - AXIAL * s), "n_rays": 4, "rms_px": 0.1,
        }))  # fmt: skip
        a = ct % 16 / 16 * 2 * np.pi
        parts.append(pd.DataFrame({
            "frame": f, "time_s": f / FPS, "id": PEDESTAL_IDS, "x_mm": (radius + 10) * np.cos(a),
            "y_mm": (radius + 10) * np.sin(a), "z_mm": np.where(ct < 16, -5.0, top), "n_rays": 3,
            "rms_px": 0.1,
        }))  # fmt: skip
    df = pd.concat(parts, ignore_index=True)
    df = df[~((df["frame"] == 2) & (df["id"] == layout.first_id))]
    return conform(df, POINTS)


def tracks_table(layout: MembraneLayout) -> pd.DataFrame:
    """4 cameras following 200 of the kit's membrane dots and the pedestal targets, losing some
    (seeded); cam03 did not record frame 4."""
    rng = np.random.default_rng(3)
    cams = [f"cam{k:02d}" for k in range(1, 5)]
    ids = np.concatenate([layout.ids.ravel()[:200], PEDESTAL_IDS])
    cam, frame, tid = (a.ravel() for a in np.meshgrid(cams, np.arange(FRAMES), ids, indexing="ij"))
    reasons = np.array(["", "lost", "edge", "merged", "jump"], dtype=object)  # object: room for longer ones
    reason = rng.choice(reasons, size=cam.size, p=[0.9, 0.04, 0.03, 0.02, 0.01])
    reason[(cam == "cam03") & (frame == 4)] = "not_recorded"
    df = pd.DataFrame({"camera": cam, "frame": frame, "id": tid, "u_px": 1.0, "v_px": 2.0, "area_px": 9.0,
                       "sigma_px": 0.03, "reason": reason})  # fmt: skip
    df.loc[df["reason"] != "", ["u_px", "v_px", "sigma_px"]] = np.nan
    return conform(df, TRACKS)


@pytest.fixture(scope="module")
def layout(design):
    return membrane_layout(design)


@pytest.fixture(scope="module")
def volume(layout) -> pd.DataFrame:
    return volume_table(layout)


@pytest.fixture(scope="module")
def strains(layout) -> pd.DataFrame:
    return strains_table(layout)


@pytest.fixture(scope="module")
def points(layout) -> pd.DataFrame:
    return points_table(layout)


@pytest.fixture(scope="module")
def tracks(layout) -> pd.DataFrame:
    return tracks_table(layout)


@pytest.fixture(scope="module")
def quality() -> dict:
    per_camera = {
        f"cam{k:02d}": {"mean_reprojection_px": 0.05 + 0.01 * k, "observations_used": 3000 + k,
                        "observations_dropped": k}
        for k in range(1, 14)
    }  # fmt: skip
    per_frame = [{"frame": f, "mean_reprojection_px": 0.1 + 0.01 * f} for f in range(FRAMES)]
    return {"mean_reprojection_px": 0.12, "per_camera": per_camera, "per_frame": per_frame}


def _drawn(img: np.ndarray) -> None:
    """A BGR uint8 image with something drawn on it: many colours, dark and white pixels, and
    a spread of grey levels well above a blank page's."""
    assert img.dtype == np.uint8 and img.ndim == 3 and img.shape[2] == 3
    packed = img.reshape(-1, 3).astype(np.int32) @ np.array([1 << 16, 1 << 8, 1], np.int32)
    assert img.min() < 100 and img.max() == 255 and len(np.unique(packed)) > 10
    assert img.astype(float).std() > MIN_PIXEL_STD


def _texts(fig: Figure) -> str:
    """Every text the figure shows after drawing (titles, labels, tick labels, legends)."""
    figure_image(fig)
    return "\n".join(t.get_text() for t in fig.findobj(lambda a: hasattr(a, "get_text")) if t.get_text())


def _near(img: np.ndarray, colour_hex: str, tol: int = 12) -> int:
    """Pixels of ``img`` (BGR) within ``tol`` of a matplotlib hex colour."""
    rgb = np.array([int(colour_hex[k : k + 2], 16) for k in (1, 3, 5)])
    return int((np.abs(img.astype(int) - rgb[::-1]).max(axis=2) <= tol).sum())


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


# --------------------------------------------------------------------------- every figure


@pytest.fixture(scope="module")
def every_figure(volume, strains, tracks, quality, layout) -> dict:
    """Each report figure (the workflow's five PNGs, and a single strain map), unrasterised."""
    cams = camera_quality(tracks)
    return {
        "volume_strain": lambda: volume_strain_figure(volume),
        "strain_maps": lambda: strain_maps_figure(strains, layout, chosen_frames(range(FRAMES), 4)),
        "strain_map": lambda: strain_map_figure(strains, layout, FRAMES - 1, "e_tt"),
        "reprojection": lambda: reprojection_figure(quality),
        "tracking": lambda: tracking_figure(tracks, layout),
        "cameras": lambda: camera_quality_figure(cams),
    }


@pytest.mark.parametrize("name", ["volume_strain", "strain_maps", "strain_map", "reprojection", "tracking",
                                  "cameras"])  # fmt: skip
def test_figures_come_from_matplotlib_and_are_not_blank(every_figure, name, tmp_path):
    managers = _pylab_helpers.Gcf.get_num_fig_managers()
    fig = every_figure[name]()
    assert isinstance(fig, Figure) and isinstance(fig.canvas, FigureCanvasAgg)
    img = figure_image(fig)
    w, h = fig.canvas.get_width_height()
    assert img.shape == (h, w, 3)
    _drawn(img)
    for ax in fig.axes:  # every data panel is labelled (colour bars and secondary axes have one label)
        if ax.get_label() != "<colorbar>" and ax.get_xlabel() and ax.has_data():
            assert ax.get_ylabel(), f"{name}: panel {ax.get_title()!r} has no y label"
    path = tmp_path / f"{name}.png"
    save_figure(every_figure[name](), path)  # a fresh figure: a layout engine may move things on a redraw
    assert "matplotlib" in path.read_bytes()[:4096].decode("latin-1").lower()  # the PNG's Software tag
    on_disk = cv2.imread(str(path))
    assert on_disk.shape == img.shape and np.abs(on_disk.astype(int) - img).mean() < 1.0
    assert _pylab_helpers.Gcf.get_num_fig_managers() == managers  # pyplot never involved


def test_save_figure_names_the_file(every_figure, tmp_path):
    with pytest.raises(OSError, match="no_such_dir"):
        save_figure(every_figure["reprojection"](), tmp_path / "no_such_dir" / "a.png")


# --------------------------------------------------------------------------- volume and strain


def test_volume_strain_figure(volume):
    fig = volume_strain_figure(volume)
    vol, strain = fig.axes[:2]
    assert "mm³" in vol.get_ylabel() and strain.get_ylabel() == "strain (%)"
    assert vol.get_xlabel() == strain.get_xlabel() == "time (s)"
    assert "compression positive" in strain.get_title()
    assert [t.get_text() for t in strain.get_legend().get_texts()] == ["axial", "radial", "volumetric"]
    axial = strain.get_lines()[1]  # after the zero line
    np.testing.assert_allclose(axial.get_ydata(), 100 * volume["axial_strain"].to_numpy())
    img = figure_image(volume_strain_figure(volume))
    assert img.shape == (680, 900, 3)
    _drawn(img)


def test_volume_strain_figure_without_optional_columns(volume):
    plain = volume[list(VOLUME.columns)]
    fig = volume_strain_figure(plain)
    strain = fig.axes[1]
    assert [t.get_text() for t in strain.get_legend().get_texts()] == ["axial", "volumetric"]
    assert "no radial strain" in strain.get_title()
    assert not fig.axes[0].collections  # no uncertainty band without volume_sigma_mm3
    _drawn(figure_image(fig))


def test_volume_figure_band_and_measured_fraction(volume):
    v0 = float(volume["volume_mm3"].iloc[0])
    sigma = 0.002 * v0
    extra = volume.assign(volume_sigma_mm3=sigma, measured_fraction=np.linspace(0.95, 0.8, FRAMES))
    fig = volume_strain_figure(extra)
    assert len(fig.axes) == 3 and fig.axes[2].get_ylabel() == "measured (%)"
    bands = [c for c in fig.axes[0].collections if isinstance(c, PolyCollection)]
    assert len(bands) == 1
    ys = bands[0].get_paths()[0].vertices[:, 1]
    dv = extra["volume_change_mm3"].to_numpy()
    assert ys.max() == pytest.approx(dv.max() + sigma) and ys.min() == pytest.approx(dv.min() - sigma)
    assert any("uncertainty" in t.get_text() for t in fig.axes[0].get_legend().get_texts())
    img = figure_image(fig)
    assert img.shape == (940, 900, 3)
    band_colour = bands[0].get_facecolor()[0]
    assert band_colour[3] < 1  # translucent: the line shows through
    no_sigma = volume_strain_figure(extra.assign(volume_sigma_mm3=np.nan))
    assert not no_sigma.axes[0].collections


# --------------------------------------------------------------------------- strain maps


def _mesh(ax) -> QuadMesh:
    return next(c for c in ax.collections if isinstance(c, QuadMesh))


def test_strain_map(strains, layout):
    fig = strain_map_figure(strains, layout, FRAMES - 1, "e_zz")
    ax = fig.axes[0]
    assert ax.get_xlabel() == "theta (deg)" and "z (mm" in ax.get_ylabel()
    values = np.ma.filled(_mesh(ax).get_array(), np.nan).reshape(layout.rows - 1, layout.columns)
    # e_zz = -5 % (1 + 0.3 cos theta): most compressive at theta = 0, least at 180 deg
    half = layout.columns // 2
    assert values[:, 0].mean() < values[:, half].mean() < 0
    assert np.nanmin(values) == pytest.approx(-5 * 1.3, rel=0.01)
    bars = [a for a in fig.axes if a.get_label() == "<colorbar>"]
    assert len(bars) == 1 and bars[0].get_ylabel() == "e_zz (%)"
    img = figure_image(fig)
    _drawn(img)
    assert _near(img, "#3b4cc0", 40) > 100  # the blue end of the diverging scale is drawn
    assert figure_image(strain_map_figure(strains, layout, 0, "e_tt", colorbar=False)).shape[1] < img.shape[1]
    with pytest.raises(ValueError, match="frame 99"):
        strain_map_figure(strains, layout, 99)
    with pytest.raises(ValueError, match="e_xx"):
        strain_map_figure(strains, layout, 0, "e_xx")


def test_strain_map_missing_cells(strains, layout):
    last = strains[strains["frame"] == FRAMES - 1]
    fig = strain_map_figure(last[last["col"] != 32], layout, FRAMES - 1, "e_tt")  # a column missing
    values = _mesh(fig.axes[0]).get_array()
    assert np.ma.count_masked(values) == layout.rows - 1  # one cell per row, drawn hatched grey
    _drawn(figure_image(fig))


def test_strain_maps(strains, layout):
    frames = chosen_frames(strains["frame"].unique(), 3)
    fig = strain_maps_figure(strains, layout, frames)
    maps = [
        ax
        for ax in fig.axes
        if ax.get_label() != "<colorbar>" and any(isinstance(c, QuadMesh) for c in ax.collections)
    ]
    assert len(maps) == 2 * len(frames)
    bars = [a for a in fig.axes if a.get_label() == "<colorbar>"]
    assert [b.get_ylabel() for b in bars] == ["e_zz (%)", "e_tt (%)"]
    # one colour range per component, shared by its row
    limits = [_mesh(ax).get_clim() for ax in maps]
    assert len(set(limits[: len(frames)])) == 1 and len(set(limits[len(frames) :])) == 1
    img = figure_image(strain_maps_figure(strains, layout, frames))
    assert img.shape[1] > img.shape[0]
    _drawn(img)
    empty = strain_maps_figure(strains, layout, [123])  # no such frame: a "no strain data" figure
    assert "no strain data" in _texts(empty)


# --------------------------------------------------------------------------- reconstruction quality


def test_reprojection_figure(quality):
    fig = reprojection_figure(quality)
    bars, per_frame = fig.axes
    assert bars.get_ylabel() == "reprojection error (px)" and per_frame.get_xlabel() == "frame"
    assert len(bars.patches) == 13
    texts = _texts(fig)
    assert "cam13\n3013/13" in texts and "0.180" in texts and "mean, all cameras" in texts
    assert figure_image(reprojection_figure(quality)).shape == (660, 900, 3)


def test_reprojection_figure_sparse():
    sparse = {
        "per_camera": {
            "cam01": {"mean_reprojection_px": 0.2},
            "cam02": {"mean_reprojection_px": float("nan")},
        }
    }
    fig = reprojection_figure(sparse)
    assert len(fig.axes) == 1 and "n/a" in _texts(fig)
    _drawn(figure_image(fig))
    assert figure_image(reprojection_figure({})).shape == (360, 900, 3)
    # the per-frame errors of quality.json's `frames` list (no `per_frame`); entries without one skipped
    frames = [{"frame": f, "time_s": f / FPS, "mean_reprojection_px": 0.1} for f in range(FRAMES)]
    assert len(reprojection_figure({**sparse, "frames": frames}).axes) == 2
    no_errors = [{"frame": 0, "targets_reconstructed": 9}]
    assert len(reprojection_figure({**sparse, "frames": no_errors}).axes) == 1


# --------------------------------------------------------------------------- tracking


def test_tracking_figure(tracks, layout):
    fig = tracking_figure(tracks, layout)
    share, losses, per_cam = fig.axes[:3]
    assert layout.describe() in share.get_title()
    labels = [t.get_text() for t in share.get_legend().get_texts()]
    assert labels[0].startswith("membrane dots") and labels[1].startswith("other targets")
    assert [t.get_text() for t in losses.get_legend().get_texts()] == ["lost", "edge", "merged", "jump",
                                                                       "not_recorded"]  # fmt: skip
    img = figure_image(tracking_figure(tracks, layout))
    assert img.shape == (300 + 300 + 340, 900, 3)
    _drawn(img)
    for colour in (REPORTED, REASON_COLOURS["lost"], REASON_COLOURS["not_recorded"]):
        assert _near(img, colour, 2) > 30  # the lines and bars in their colours
    assert "every target reported" in _texts(tracking_figure(tracks.assign(reason=""), layout))
    assert "no tracking data" in _texts(tracking_figure(tracks.iloc[:0], layout))


def test_camera_quality_and_figure(tracks):
    """Per camera: targets labelled, tracked share (frames not recorded left out) and sigma."""
    noisy = tracks.copy()
    cam02 = (noisy["camera"] == "cam02") & (noisy["reason"] == "")
    noisy.loc[cam02, "sigma_px"] = np.linspace(0.1, 0.3, int(cam02.sum()))  # poorer footage
    first = int(tracks["id"].max())
    labels = pd.DataFrame({"camera": ["cam01"] * 3 + ["cam02"] * 2, "frame": [0, 0, 3, 0, 0],
                           "id": [first, first - 1, first, first, -1]})  # fmt: skip
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
    fig = camera_quality_figure(q.reset_index())
    top, bottom = fig.axes[:2]
    assert top.get_ylabel() == "tracked (%)" and bottom.get_ylabel() == "sigma_px (px)"
    assert "cam01\n2" in _texts(fig)  # under cam01: the median targets labelled, 1.5 rounded
    img = figure_image(camera_quality_figure(q.reset_index()))
    assert img.shape == (680, 900, 3)
    _drawn(img)
    assert _near(img, REPORTED, 2) > 1000  # the tracked share's bars
    lost = tracks.assign(reason="lost", sigma_px=np.nan)  # nothing tracked: n/a, no sigma
    q_lost = camera_quality(lost)
    assert (q_lost["tracked_share"] == 0).all() and q_lost["sigma_median_px"].isna().all()
    assert "n/a" in _texts(camera_quality_figure(q_lost))


# --------------------------------------------------------------------------- movie


def test_specimen_frames_radial(points, layout):
    frames = list(specimen_frames(points, layout, height=301))
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
    # the colour bar on the right is matplotlib's diverging scale: its red and blue ends
    bar = frames[-1][:, -100:]
    for end in (DIVERGING[255, 0], DIVERGING[0, 0]):
        assert (np.abs(bar.astype(int) - end).max(axis=2) < 12).sum() > 50


def test_specimen_frames_strain_and_choice(points, strains, layout):
    frames = list(
        specimen_frames(points, layout, strains, colour_by="e_tt", frames=[0, 4, 77], views_deg=(30.0,))
    )
    assert len(frames) == 2  # frame 77 is not in the table
    _drawn(frames[1])
    magnified = next(specimen_frames(points, layout, frames=[FRAMES - 1], magnify=3.0))
    _drawn(magnified)
    with pytest.raises(ValueError, match="strains"):
        specimen_frames(points, layout, None, colour_by="e_zz")
    with pytest.raises(ValueError, match="membrane"):
        specimen_frames(points[~layout.is_membrane(points["id"].to_numpy())], layout)


def test_write_movie_decodes(points, layout, tmp_path):
    path = tmp_path / "specimen.mp4"
    frames = list(specimen_frames(points, layout, height=240))
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


# --------------------------------------------------------------------------- reconstruction picture


def test_reconstruction_picture(design, table):
    """The reconstruction picture (rule trace_specimen) is a matplotlib figure of three views."""
    from triaxtrack.kit import design_points
    from triaxtrack.optics import cell_optics
    from triaxtrack.plots import PANEL_PX, TITLE_PX, draw_reconstruction
    from triaxtrack.simulate import SimulationConfig, make_cameras

    cameras = {c.name: c for c in make_cameras(SimulationConfig(cameras=3))}
    points = design_points(design, table)
    point = points[["x_mm", "y_mm", "z_mm"]].to_numpy(float)[-1]
    centres = [c.center for c in cameras.values()]
    rays = [np.vstack([c, (c + point) / 2, (c + 9 * point) / 10]) for c in centres]  # stand-in wall crossings
    img = draw_reconstruction(cameras, points, cell_optics(design), rays, point, "three cameras")
    assert img.shape == (PANEL_PX + TITLE_PX, 3 * PANEL_PX, 3)
    _drawn(img)
    assert _near(img, "#ff9f00", 30) > 50  # the rays
