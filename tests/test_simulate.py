"""The simulator: rendered dots sit where exact physics puts them; the test folder is complete."""

from __future__ import annotations

import json

import numpy as np
import pandas as pd
import pytest
import yaml

from triaxtrack.centroid import local_centroid
from triaxtrack.optics import Camera, project_air
from triaxtrack.raster import circle_polygon, packed_polygon_coverage
from triaxtrack.simulate import (
    CameraRenderer,
    SimulationConfig,
    check_simulation,
    gop_frames,
    load_scene,
    make_scene,
    render_chunk,
    render_segments,
)
from triaxtrack.tables import OBSERVATIONS, POINTS, VOLUME, read_table
from triaxtrack.video import concat_videos, keyframe_indices, probe_video


def test_flat_dot_head_on_centroid_within_0p02_px():
    """A flat 1.8 mm dot facing the camera: rendered centroid vs projected centre."""
    K = np.array([[794.0, 0, 639.5], [0, 794.0, 359.5], [0, 0, 1]])
    cam = Camera("c", 1280, 720, K, np.array([-0.3, 0.08, 0, 0, 0]), np.eye(3), np.zeros(3))
    rng = np.random.default_rng(2)
    errs = []
    for _ in range(50):
        c = np.r_[rng.uniform(-40, 40, 2), 260.0]
        ring = circle_polygon([0, 0], 0.9, 16)
        verts = project_air(cam, c + np.c_[ring, np.zeros(16)])
        cov = packed_polygon_coverage(verts, [16], 720, 1280)
        ys, xs = np.mgrid[:720, :1280]
        cen = np.array([(cov * xs).sum(), (cov * ys).sum()]) / cov.sum()
        errs.append(np.linalg.norm(cen - project_air(cam, c[None])[0]))
    assert max(errs) < 0.02


@pytest.fixture(scope="module")
def noiseless_frame(small_test):
    """Frame 0 of cam01 rendered without noise, and its exact observations."""
    scene = load_scene(small_test)
    scene.cfg = SimulationConfig(**{**scene.cfg.__dict__, "noise_sigma": 0.0})
    img, obs = CameraRenderer(scene, "cam01").render(0)
    return scene, img, obs


def test_rendered_centroids_match_exact_projection(noiseless_frame):
    """Rendered dot centroids vs exact images of their centres (air: cell wall; water: membrane).

    The remaining bias is physical (perspective and refraction across a dot of finite size,
    plus the nearest-blob centroid's own error); it is printed for the record.
    """
    scene, img, obs = noiseless_frame
    t = scene.table.set_index("id")
    obs = obs[t.loc[obs.id, "kind"].to_numpy() == "dot"]
    c = local_centroid(img, obs[["u_px", "v_px"]].to_numpy())
    d = c - obs[["u_px", "v_px"]].to_numpy()
    err = np.hypot(d[:, 0], d[:, 1])
    surf = t.loc[obs.id, "surface"].to_numpy()
    for name, limit in (("cell_outer", 0.05), ("membrane", 0.05)):
        sel = (surf == name) & np.isfinite(err)
        assert sel.sum() > 50
        med = np.median(err[sel])
        print(f"{name}: n={sel.sum()} median {med:.4f} px, p95 {np.quantile(err[sel], 0.95):.4f} px, "
              f"bias ({d[sel, 0].mean():+.4f}, {d[sel, 1].mean():+.4f}) px")  # fmt: skip
        assert med < limit


def test_test_folder_is_complete(small_test):
    meta = yaml.safe_load((small_test / "test.yaml").read_text())
    assert meta["name"] == "small" and meta["fps"] == 15.0 and meta["cameras"] == ["cam01", "cam02", "cam03"]
    for cam in meta["cameras"]:
        info = probe_video(small_test / "videos" / f"{cam}.mp4")
        assert info["frames"] == 4 and (info["width"], info["height"]) == (960, 540)
        assert len(list((small_test / "calibration" / cam).glob("*.png"))) == 3
    pts = read_table(small_test / "truth" / "points.parquet", POINTS)
    assert len(pts) == 4352 * 4
    assert pts.n_rays.between(0, 3).all() and (pts.n_rays > 0).mean() > 0.3
    assert np.allclose(pts.time_s, pts.frame / 15.0)
    obs = read_table(small_test / "truth" / "observations.parquet", OBSERVATIONS)
    assert obs.u_px.between(0, 959).all() and obs.v_px.between(0, 539).all()
    counts = obs.groupby(["frame", "id"]).size()
    merged = pts.set_index(["frame", "id"]).n_rays
    assert (merged.reindex(counts.index) == counts).all()
    vol = read_table(small_test / "truth" / "volume.parquet", VOLUME)
    assert len(vol) == 4 and vol.volumetric_strain.iloc[0] == 0.0
    assert vol.axial_strain.iloc[-1] == pytest.approx(0.08)
    cams = json.loads((small_test / "truth" / "cameras.json").read_text())["cameras"]
    assert set(cams) == {"cam01", "cam02", "cam03"} and len(cams["cam01"]["dist"]) == 5


def test_top_cap_moves_with_axial_strain(small_test):
    pts = read_table(small_test / "truth" / "points.parquet", POINTS)
    top = pts[pts.id.between(1, 16)].groupby("frame").z_mm.mean()
    assert top.iloc[-1] - top.iloc[0] == pytest.approx(-0.08 * 142.2, abs=1e-9)
    bottom = pts[pts.id.between(17, 32)].groupby("id")[["x_mm", "y_mm", "z_mm"]].agg(np.ptp)
    assert bottom.to_numpy().max() < 1e-12  # the bottom pedestal does not move


def test_check_simulation_passes(small_test):
    rep = check_simulation(small_test)
    assert rep["ok"], rep
    assert rep["membrane_dots"]["median_px"] < 0.15 and rep["air_dots"]["median_px"] < 0.10


def test_unknown_setting_is_refused():
    with pytest.raises(ValueError, match="simulation: unknown key .camreas."):
        SimulationConfig.from_dict({"camreas": 13})


def test_observations_are_deterministic(small_test):
    a = pd.read_parquet(small_test / "truth" / "observations.parquet")
    scene = load_scene(small_test)
    _, obs = CameraRenderer(scene, "cam02").render(0)
    ref = a[(a.camera == "cam02") & (a.frame == 0)].sort_values("id")
    obs = obs.sort_values("id")
    assert list(ref.id) == list(obs.id)
    assert np.abs(ref.u_px.to_numpy() - obs.u_px.to_numpy()).max() < 1e-6


def test_small_membrane_dot_is_at_least_6_px_at_1080p(design):
    """Default cameras at 1920x1080: a small membrane dot facing a camera spans >= 6 px."""
    from triaxtrack.kit import _disc
    from triaxtrack.optics import cell_optics, project_water
    from triaxtrack.simulate import make_cameras

    cam = make_cameras(SimulationConfig(width=1920, height=1080))[0]
    theta = np.arctan2(cam.center[1], cam.center[0])
    r = design.specimen.diameter / 2 + design.specimen.membrane_thickness
    ring = _disc(design.membrane.small_dot_diameter / 2)
    pts = np.c_[r * np.cos(theta + ring[:, 0] / r), r * np.sin(theta + ring[:, 0] / r), 71.1 + ring[:, 1]]
    uv, _, _ = project_water(cam, pts, cell_optics(design))
    width, height = np.ptp(uv, axis=0)
    print(f"small membrane dot at 1920x1080: {width:.2f} x {height:.2f} px")
    assert min(width, height) >= 6.0


def test_cell_wall_dots_land_where_opencv_projects_them(noiseless_frame):
    """Rendered cell-wall dot centroids vs cv2.projectPoints of their design positions."""
    import cv2

    scene, img, _ = noiseless_frame
    cam = scene.cameras["cam01"]
    t = scene.table
    dots = t[(t.surface == "cell_outer") & (t.kind == "dot")]
    r = scene.design.cell.outer_radius
    xyz = np.c_[r * np.cos(dots.theta_rad), r * np.sin(dots.theta_rad), dots.z_mm]
    facing = (xyz[:, :2] * (cam.center[:2] - xyz[:, :2])).sum(axis=1) > 0.8 * r * np.linalg.norm(
        cam.center[:2] - xyz[:, :2], axis=1
    )
    uv, _ = cv2.projectPoints(xyz[facing], cv2.Rodrigues(cam.R)[0], cam.t, cam.K, cam.dist)
    uv = uv.reshape(-1, 2)
    inside = (uv[:, 0] > 10) & (uv[:, 0] < cam.width - 10) & (uv[:, 1] > 10) & (uv[:, 1] < cam.height - 10)
    err = np.linalg.norm(local_centroid(img, uv[inside]) - uv[inside], axis=1)
    err = err[np.isfinite(err)]
    assert len(err) > 30
    assert np.median(err) < 0.03


def test_camera_above_the_final_top_cap_is_refused(kit_dir, tmp_path):
    from triaxtrack.simulate import make_scene

    cfg = SimulationConfig(cameras=3, frames=3, camera_height_mm=138.0, axial_strain=0.05)
    with pytest.raises(ValueError, match="between the pedestal faces"):
        make_scene(cfg, kit_dir, tmp_path / "t", "t")


# ---------------------------------------------------------------- camera and recorder effects
def _render(test_dir, camera: str = "cam01", frame: int = 0, **changes):
    """One frame of a simulated test with some settings changed (no preset expansion)."""
    import dataclasses

    scene = load_scene(test_dir)
    scene.cfg = dataclasses.replace(scene.cfg, **changes)
    return scene, *CameraRenderer(scene, camera).render(frame)


def test_new_settings_default_to_todays_render(small_test, monkeypatch):
    """At their defaults the new keys are no-ops: the image is exactly the one of the effects
    as they were before the keys existed (constant vignetting 0.22, blur, noise), the truth is
    the small test's own, and the cameras do not move."""
    import zlib

    from triaxtrack.simulate import VIGNETTING

    cfg = SimulationConfig()
    assert (cfg.vignetting, cfg.light_gradient, cfg.exposure_drift) == (VIGNETTING, 0.0, 0.0) == (0.22, 0, 0)
    assert (cfg.timestamp_overlay, cfg.camera_tilt_deg, cfg.occluder_z_mm) == (False, 0.0, None)
    scene, img, obs = _render(small_test, "cam02", 1)
    captured = {}
    monkeypatch.setattr(CameraRenderer, "_camera_effects", lambda self, im, k: captured.setdefault("x", im))
    CameraRenderer(scene, "cam02").render(1)
    raw = captured["x"]
    cam = scene.cameras["cam02"]
    h, w = raw.shape
    yy, xx = np.mgrid[0:h, 0:w]
    r2 = ((xx - cam.K[0, 2]) ** 2 + (yy - cam.K[1, 2]) ** 2) / ((w / 2) ** 2 + (h / 2) ** 2)
    before = raw * (1 - 0.22 * r2)  # the effects as they were (no blur in this test)
    rng = np.random.default_rng([scene.cfg.seed, zlib.crc32(b"cam02"), 1])
    noise = rng.standard_normal(before.shape, dtype=np.float32)
    before = before + scene.cfg.noise_sigma * noise * np.sqrt(np.maximum(before, 1) / 128)
    assert np.array_equal(img, np.clip(np.round(before), 0, 255).astype(np.uint8))


def test_nvr_preset_and_explicit_keys():
    cfg = SimulationConfig.from_dict({"preset": "nvr", "crf": 30})
    assert (cfg.codec, cfg.crf, cfg.noise_sigma, cfg.light_gradient, cfg.vignetting) == (
        "h265",
        30,
        4.0,
        0.3,
        0.35,
    )
    assert cfg.timestamp_overlay and cfg.exposure_drift == 0.03
    assert cfg.blur_sigma_px == 1.0  # a soft fixed-focus lens, at any size (the realistic footage)
    assert SimulationConfig.from_dict({"preset": "nvr", "width": 3840, "height": 2160}).blur_sigma_px == 1.0
    assert SimulationConfig.from_dict({"preset": "clean"}) == SimulationConfig()
    for bad, key in (
        ({"preset": "4k"}, "preset"),
        ({"light_gradient": 1.5}, "light_gradient"),
        ({"vignetting": -0.1}, "vignetting"),
        ({"exposure_drift": "x"}, "exposure_drift"),
        ({"exposure": 0}, "exposure"),
        ({"exposure": 3.0}, "exposure"),
        ({"timestamp_overlay": "yes"}, "timestamp_overlay"),
        ({"camera_tilt_deg": -2}, "camera_tilt_deg"),
        ({"occluder_z_mm": [10]}, "occluder_z_mm"),
        ({"occluder_z_mm": [20, 10]}, "occluder_z_mm"),
    ):
        with pytest.raises(ValueError, match=key):
            SimulationConfig.from_dict(bad)


def test_timestamp_overlay_is_bright_text_and_hides_its_targets(small_test, monkeypatch):
    """The overlay's box holds white text (1 s of test time per change) and no truth target
    touches it; a box moved over the specimen removes exactly the targets under it."""
    from triaxtrack import footage

    assert footage.timestamp_text(0, 15.0) == "2026-11-25 14:03:27"
    assert footage.timestamp_text(14, 15.0) == "2026-11-25 14:03:27"
    assert footage.timestamp_text(15, 15.0) == "2026-11-25 14:03:28"
    _, plain, obs_plain = _render(small_test, noise_sigma=0.0)
    _, img, obs = _render(small_test, noise_sigma=0.0, timestamp_overlay=True)
    x0, y0, x1, y1 = footage.overlay_box(960, 540)
    assert x0 < 30 and y0 < 30 and 150 < x1 - x0 < 400 and 10 < y1 - y0 < 40  # top-left, scaled
    inside = img[y0 : y1 + 1, x0 : x1 + 1]
    assert (inside >= 240).sum() > 0.1 * inside.size and (plain[y0 : y1 + 1, x0 : x1 + 1] < 60).all()
    outside = np.ones(img.shape, bool)
    outside[y0 : y1 + 1, x0 : x1 + 1] = False
    assert np.array_equal(img[outside], plain[outside])  # drawn in the box only
    ring, text = footage._overlay_masks(960, 540, footage.timestamp_text(0, 15.0))
    assert (ring >= text).all() and (ring > 0.5).sum() > 1.5 * (text > 0.5).sum()  # a dark outline
    # the truth rule, with the box moved over the middle of the picture
    box = (400, 200, 560, 330)
    monkeypatch.setattr(footage, "overlay_box", lambda w, h: box)
    _, _, moved = _render(small_test, noise_sigma=0.0, timestamp_overlay=True)
    gone = obs_plain[~obs_plain.id.isin(moved.id)]
    assert len(gone) > 50 and set(moved.id) <= set(obs_plain.id)
    assert (
        gone.u_px.between(box[0] - 12, box[2] + 12).all()
        and gone.v_px.between(box[1] - 12, box[3] + 12).all()
    )
    deep = obs_plain.u_px.between(box[0], box[2]) & obs_plain.v_px.between(box[1], box[3])
    assert obs_plain[deep].id.isin(gone.id).all()


def test_light_gradient_darkens_one_side_by_the_set_amount(small_test):
    from triaxtrack import footage

    field = footage.gradient_field(640, 360, 0.3, 0.0)  # lamp on the left
    assert field[:, 0] == pytest.approx(1.0) and field[:, -1] == pytest.approx(0.7)
    left, right = field[:, :320].mean(), field[:, 320:].mean()
    assert left - right == pytest.approx(0.3 * 320 / 639, rel=1e-6)  # half-images: half the ramp
    _, flat, _ = _render(small_test, "cam03", noise_sigma=0.0, vignetting=0.0)
    scene, lit, _ = _render(small_test, "cam03", noise_sigma=0.0, vignetting=0.0, light_gradient=0.3)
    direction = footage.gradient_direction(scene.cfg.seed, "cam03")
    expected = footage.gradient_field(960, 540, 0.3, direction)
    bright = flat > 100
    ratio = lit[bright] / flat[bright]
    assert np.abs(ratio - expected[bright]).max() < 0.01  # rounding to grey levels only
    span = np.ptp(expected[bright])
    print(f"cam03: dark side at {np.rad2deg(direction):.0f} deg, ratio {ratio.min():.3f}..{ratio.max():.3f}")
    assert np.ptp(ratio) == pytest.approx(span, abs=0.02) and span > 0.05  # rounding of both images


def test_exposure_drift_is_slow_and_bounded():
    from triaxtrack import footage

    p = np.linspace(0, 1, 101)
    for cam in ("cam01", "cam02", "cam07"):
        g = np.array([footage.exposure_gain(q, 0.05, 3, cam) for q in p])
        assert g[0] == 1.0 and np.abs(g - 1).max() <= 0.05 + 1e-12 and np.abs(g - 1).max() > 0.02
        assert np.abs(np.diff(g)).max() < 0.05 * np.pi / 100 + 1e-12  # smooth: no jumps


def test_occluder_hides_exactly_the_membrane_in_its_z_range(small_test):
    """A band at z 60..70 mm: the targets removed from the truth are the membrane dots whose
    image reaches the band's pixels (centre within a dot radius and a pixel of it), every dot
    centred in it is removed and every dot clear of it is kept."""
    from triaxtrack.simulate import GREY_OCCLUDER, target_positions

    z0, z1 = 60.0, 70.0
    _, plain, obs_plain = _render(small_test, "cam01", 3, noise_sigma=0.0)
    scene, img, obs = _render(small_test, "cam01", 3, noise_sigma=0.0, occluder_z_mm=(z0, z1))
    t = scene.table.set_index("id")
    z = target_positions(scene, 3).set_index("id").z_mm
    gone = obs_plain[~obs_plain.id.isin(obs.id)].id
    assert set(obs.id) <= set(obs_plain.id) and len(gone) > 30
    assert (t.loc[gone, "surface"] == "membrane").all()
    # half a dot, plus the pixel its image box is widened by (about 0.5 mm here: 960 px wide)
    reach = t.diameter_mm / 2 + 0.8
    assert (z[gone] > z0 - reach[gone]).all() and (z[gone] < z1 + reach[gone]).all()
    on_membrane = (t.loc[obs_plain.id, "surface"] == "membrane").to_numpy()
    centred = obs_plain.id[z.loc[obs_plain.id].between(z0, z1).to_numpy() & on_membrane]
    assert centred.isin(gone).all()
    zs, rs = z.loc[obs_plain.id].to_numpy(), reach.loc[obs_plain.id].to_numpy()
    clear = obs_plain.id[(zs < z0 - rs - 0.4) | (zs > z1 + rs + 0.4)]
    assert clear.isin(obs.id).all()
    darker = (plain.astype(int) - img) > 20
    assert darker.sum() > 1000 and np.median(img[darker]) <= GREY_OCCLUDER  # (vignetting)


def test_camera_tilt_stays_within_bounds():
    """Each camera is pitched about its own x axis by its seeded angle, within +- the setting;
    nothing else about it changes (the tilt has a generator of its own)."""
    from triaxtrack.simulate import camera_pitch_deg, make_cameras

    cfg = SimulationConfig(cameras=16, camera_tilt_deg=4.0)
    level, tilted = make_cameras(SimulationConfig(cameras=16)), make_cameras(cfg)
    pitches = []
    for a, b in zip(level, tilted, strict=True):
        assert np.array_equal(a.K, b.K) and np.array_equal(a.dist, b.dist)
        assert np.allclose(a.center, b.center, atol=1e-9)
        P = b.R @ a.R.T  # a rotation about the camera's x axis
        assert np.allclose(P[0], [1, 0, 0], atol=1e-12) and np.allclose(P[:, 0], [1, 0, 0], atol=1e-12)
        pitch = np.rad2deg(np.arctan2(-P[2, 1], P[1, 1]))
        assert pitch == pytest.approx(camera_pitch_deg(cfg, b.name), abs=1e-9)
        up = np.rad2deg(np.arcsin(b.R[2, 2]) - np.arcsin(a.R[2, 2]))  # line of sight turns up
        assert up == pytest.approx(pitch, abs=0.05)
        pitches.append(pitch)
    assert max(np.abs(pitches)) <= 4.0 and np.ptp(pitches) > 4.0


def test_render_segments_start_on_the_gop_grid():
    assert render_segments(100, 50, 30) == [(0, 60), (60, 100)]
    assert render_segments(10, 4, 30) == [(0, 10)]
    assert render_segments(90, 30, 30) == [(0, 30), (30, 60), (60, 90)]
    assert render_segments(13, 3, 4) == [(0, 4), (4, 8), (8, 12), (12, 13)]
    assert gop_frames(SimulationConfig(fps=15.0, gop_s=2.0)) == 30
    assert gop_frames(SimulationConfig(fps=25.0, gop_s=0.01)) == 1
    with pytest.raises(ValueError, match="gop_s"):
        SimulationConfig.from_dict({"gop_s": 0})


def test_small_test_videos_have_keyframes_on_the_gop_grid(small_test):
    """Two joined segments of 2 frames, GOP 2: keyframes at 0 and 2 only."""
    for camera in ("cam01", "cam03"):
        assert keyframe_indices(small_test / "videos" / f"{camera}.mp4").tolist() == [0, 2]


@pytest.mark.parametrize("chunk_size", [3, 5, 8])
def test_gop_grid_whatever_the_chunk_size(kit_dir, tmp_path, chunk_size):
    """A recorder's keyframes: every round(gop_s x fps) = 4 frames from frame 0, and nowhere
    else, whether the chunks are shorter than a GOP, not a multiple of it, or two GOPs."""
    cfg = SimulationConfig(cameras=1, frames=14, width=320, height=180, gop_s=4 / 15, calibration_images=1)
    make_scene(cfg, kit_dir, tmp_path / "t", "gop")
    segments = []
    for i, (start, stop) in enumerate(render_segments(cfg.frames, chunk_size, gop_frames(cfg))):
        segments.append(tmp_path / f"{i}.mp4")
        render_chunk(tmp_path / "t", "cam01", start, stop, segments[-1], tmp_path / f"{i}.parquet")
    n = concat_videos(segments, tmp_path / "cam01.mp4")
    assert n == 14
    assert keyframe_indices(tmp_path / "cam01.mp4").tolist() == [0, 4, 8, 12]


def test_exposure_scales_the_picture_before_the_noise(small_test):
    _, lit, _ = _render(small_test, "cam03", noise_sigma=0.0, vignetting=0.0)
    _, dim, _ = _render(small_test, "cam03", noise_sigma=0.0, vignetting=0.0, exposure=0.3)
    bright = lit > 100
    assert np.abs(dim[bright] - 0.3 * lit[bright]).max() <= 1.0  # rounding to grey levels only


def test_a_render_that_moves_the_membrane_over_half_a_row_a_frame_is_told(design):
    """Mid-height moves k H0 / 4 over the test with ``axial_nonuniformity`` k on top of the
    strain: at k = 0.3 and 2 % strain over 8 frames, 12 mm, about 0.74 of a 2.37 mm dot row a
    frame (the tracker read such a grid one row over); over 100 frames at 1 %, 0.05."""
    from triaxtrack.simulate.scene import FOLLOWABLE_ROWS, largest_step_rows

    fast = largest_step_rows(SimulationConfig.from_dict({"frames": 8, "axial_strain": 0.02}), design)
    slow = largest_step_rows(SimulationConfig.from_dict({"frames": 100, "axial_strain": 0.01}), design)
    assert fast == pytest.approx(0.74, abs=0.02) and fast > FOLLOWABLE_ROWS
    assert slow == pytest.approx(0.049, abs=0.005)
