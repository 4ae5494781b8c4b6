"""Cluster-robust uncertainty with the cameras as clusters (triaxtrack.influence) and the volume's
derivative by its points (triaxtrack.volume.uncertainty.volume_gradient).

Monte Carlo on a linear camera model with known truth: points seen by 4 of 12 cameras, each
observation's error a camera's shared part plus its own noise. The cluster estimate must match
the spread of the statistic over trials when the errors are independent, and stay within 30 %
of it when the cameras share an error, where the propagation that takes the observations as
independent falls far short.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pandas as pd
import pytest
from test_volume import (  # the deforming specimen's points, as the volume tests build them
    LOADED,
    frame_points,
)

from triaxtrack.influence import (
    CODEC_SHIFT_COLUMNS,
    INFLUENCE_COLUMNS,
    cluster_sigma,
    observation_influence,
    observation_shift,
    shared_sigma,
)
from triaxtrack.volume import top_cap, volume_series
from triaxtrack.volume.cap import TopCap
from triaxtrack.volume.grid import grid_ids, membrane_grid
from triaxtrack.volume.uncertainty import height_gradient, height_sigma_mm, volume_gradient

N_POINTS, N_CAMERAS, RAYS, TRIALS = 300, 12, 4, 400
NOISE_PX, SHARED_PX = 0.05, 0.03


def _scene(seed: int = 0):
    rng = np.random.default_rng(seed)
    proj = rng.normal(0.0, 2.0, (N_CAMERAS, 2, 3))  # px/mm, each camera's linear projection
    seen = np.array([rng.choice(N_CAMERAS, RAYS, replace=False) for _ in range(N_POINTS)])
    cam_of = seen.ravel()
    group = np.repeat(np.arange(N_POINTS), RAYS)
    jac = proj[cam_of]
    grad = rng.normal(1.0, 0.3, (N_POINTS, 3))  # coherent, as a volume's normals are
    return rng, jac, cam_of, group, grad


def _trial(rng, jac, cam_of, group, grad, shared_px: float):
    """One trial's statistic error, cluster sigma and independent sigma."""
    shared = rng.normal(0.0, shared_px, (N_CAMERAS, 2))  # one camera's error, in all its rays
    err = shared[cam_of] + rng.normal(0.0, NOISE_PX, (len(cam_of), 2))
    jtj = np.zeros((N_POINTS, 3, 3))
    np.add.at(jtj, group, np.einsum("nki,nkj->nij", jac, jac))
    cov = np.linalg.inv(jtj)
    jte = np.zeros((N_POINTS, 3))
    np.add.at(jte, group, np.einsum("nki,nk->ni", jac, err))
    dx = np.einsum("mij,mj->mi", cov, jte)  # the least-squares points' errors (truth 0)
    resid = np.einsum("nij,nj->ni", jac, dx[group]) - err  # reprojection minus observation
    psi = observation_influence(jac, cov, group, resid)
    influence = pd.DataFrame(psi, columns=list(INFLUENCE_COLUMNS)).assign(camera=cam_of, id=group)
    gradient = pd.DataFrame({"id": np.arange(N_POINTS), "gx": grad[:, 0], "gy": grad[:, 1], "gz": grad[:, 2]})
    sigma, n = cluster_sigma(influence, gradient)
    sig0 = np.sqrt(np.einsum("mi,mij,mj->", grad, cov, grad)) * np.sqrt(NOISE_PX**2 + shared_px**2)
    return float(np.sum(grad * dx)), sigma, n, sig0


@pytest.mark.parametrize("shared_px", [0.0, SHARED_PX])
def test_cluster_sigma_matches_the_spread_over_trials(shared_px):
    rng, jac, cam_of, group, grad = _scene()
    runs = np.array([_trial(rng, jac, cam_of, group, grad, shared_px)[:4] for _ in range(TRIALS)])
    spread = runs[:, 0].std()
    cluster = np.sqrt(np.mean(runs[:, 1] ** 2))
    independent = np.mean(runs[:, 3])
    print(
        f"\nshared {shared_px} px: spread {spread:.4f}, cluster {cluster:.4f}, independent {independent:.4f}"
    )
    assert set(runs[:, 2]) == {N_CAMERAS}
    if shared_px:
        # a point follows 1/4 of each of its 4 cameras' shared errors, which no residual shows
        assert 0.7 * spread < cluster < 1.1 * spread
        assert independent < 0.6 * spread  # the shared part is what the independent model misses
    else:
        assert cluster == pytest.approx(spread, rel=0.1)
        assert independent == pytest.approx(spread, rel=0.1)


def test_influence_is_nan_without_a_point_and_cluster_sigma_without_overlap():
    jac = np.ones((2, 2, 3))
    cov = np.stack([np.eye(3), np.full((3, 3), np.nan)])
    psi = observation_influence(jac, cov, np.array([0, 1]), np.zeros((2, 2)))
    assert np.isfinite(psi[0]).all() and np.isnan(psi[1]).all()
    influence = pd.DataFrame(psi, columns=list(INFLUENCE_COLUMNS)).assign(camera="cam01", id=[1, 2])
    sigma, n = cluster_sigma(influence, pd.DataFrame({"id": [7], "gx": [1.0], "gy": [0.0], "gz": [0.0]}))
    assert np.isnan(sigma) and n == 0


def test_volume_gradient_is_the_volumes_derivative(design, table):
    """Moving the membrane dots out by a few micrometres each (varying from dot to dot) and the
    top cap up changes the measured volume by the gradient's dot product with the shifts (within
    2 %)."""
    pts = frame_points(design, table, LOADED, 0.5)
    rng = np.random.default_rng(3)
    xyz = pts[["x_mm", "y_mm", "z_mm"]].to_numpy()
    out = np.c_[xyz[:, :2] / np.hypot(xyz[:, 0], xyz[:, 1])[:, None], np.zeros(len(xyz))]
    on_membrane = pts["id"].isin(table.loc[table["surface"] == "membrane", "id"]).to_numpy()
    shift = np.where(on_membrane[:, None], out * rng.uniform(0.0, 0.008, (len(xyz), 1)), [0.0, 0.0, 0.01])
    moved = pts.assign(
        x_mm=pts["x_mm"] + shift[:, 0], y_mm=pts["y_mm"] + shift[:, 1], z_mm=pts["z_mm"] + shift[:, 2]
    )
    frames = pd.concat([pts.assign(frame=0), moved.assign(frame=1)]).assign(time_s=0.0)
    vol, _ = volume_series(frames, table, design, check=False)
    v0 = float(vol["volume_mm3"].iloc[0])
    cap = top_cap(pts, table, design)
    on_cap = table.loc[table["surface"] == "pedestal_top", "id"].to_numpy()
    grad = volume_gradient(membrane_grid(pts, table), grid_ids(table), cap, on_cap, v0).set_index("id")
    predicted = float(np.sum(grad.loc[pts["id"]].to_numpy() * shift))
    change = float(vol["volume_mm3"].iloc[1]) - v0
    print(f"\nvolume change {change:.3f} mm3, predicted {predicted:.3f} mm3")
    assert predicted > 100.0
    assert change == pytest.approx(predicted, rel=0.02)


def test_the_volume_stage_reads_only_the_used_influences(tmp_path):
    """``observation_influences`` reads the influence columns of the used observations with a
    finite influence; an older observations.parquet without them gives None (the independent
    model)."""
    from triaxtrack.tables import OBSERVATIONS, write_table
    from triaxtrack.volume.series import observation_influences

    obs = pd.DataFrame({
        "camera": ["cam01", "cam01", "cam02", "cam02"], "frame": [0, 0, 0, 1], "id": [1001, 1002, 1001, 1001],
        "u_px": 1.0, "v_px": 2.0, "used": [True, False, True, True],
        "ix_mm": [0.1, np.nan, 0.2, np.nan], "iy_mm": 0.0, "iz_mm": 0.0,
    })  # fmt: skip
    write_table(obs, tmp_path / "with.parquet", OBSERVATIONS)
    got = observation_influences(tmp_path / "with.parquet")
    assert got is not None
    assert list(got.columns) == ["camera", "frame", "id", *INFLUENCE_COLUMNS]
    assert got[["camera", "id"]].astype(str).values.tolist() == [["cam01", "1001"], ["cam02", "1001"]]
    write_table(obs.drop(columns=list(INFLUENCE_COLUMNS)), tmp_path / "without.parquet", OBSERVATIONS)
    assert observation_influences(tmp_path / "without.parquet") is None


def test_shared_sigma_is_the_statistics_move_when_every_camera_errs_alike():
    """An error of every observation alike moves the least-squares points by the sum of their
    rays' pulls (:func:`observation_shift`), and the statistic by exactly ``shared_sigma`` per
    axis (a linear model: to rounding)."""
    _, jac, cam_of, group, grad = _scene(3)
    jtj = np.zeros((N_POINTS, 3, 3))
    np.add.at(jtj, group, np.einsum("nki,nkj->nij", jac, jac))
    cov = np.linalg.inv(jtj)
    gradient = pd.DataFrame({"id": np.arange(N_POINTS), "gx": grad[:, 0], "gy": grad[:, 1], "gz": grad[:, 2]})
    moves, shifts = [], np.zeros((N_POINTS, 6))
    for a, size in ((0, 0.02), (1, 0.05)):
        err = np.zeros((len(cam_of), 2))
        err[:, a] = size
        np.add.at(shifts[:, 3 * a : 3 * a + 3], group, observation_shift(jac, cov, group, err))
        jte = np.zeros((N_POINTS, 3))
        np.add.at(jte, group, np.einsum("nki,nk->ni", jac, err))
        moves.append(np.sum(grad * np.einsum("mij,mj->mi", cov, jte)))  # the points re-solved
    table = pd.DataFrame(shifts, columns=list(CODEC_SHIFT_COLUMNS)).assign(id=np.arange(N_POINTS))
    assert shared_sigma(table, gradient) == pytest.approx(np.hypot(*moves), rel=1e-9)
    assert abs(moves[1]) > 0.1 * abs(moves[0]) > 0  # both axes count
    assert shared_sigma(table.assign(id=table["id"] + N_POINTS), gradient) == 0.0  # no point meets it


def test_the_heights_uncertainty_counts_the_caps_fit_its_cameras_and_the_codec():
    """The top face from 6 coded targets: alone, the fit's residual over sqrt(3n - 6); a codec
    shift of 2 micrometres up in every target moves the face by 2 micrometres, in full; each
    camera's influences on the targets count per camera; a cap from the membrane's rows has no
    targets' gradient."""
    cap = TopCap(np.eye(3), np.zeros(3), np.array([0, 0, 142.0]), np.array([0, 0, 1.0]), 142.0, 6, 0.003)
    ids = np.arange(1, 7)
    alone = 0.003 / np.sqrt(12)
    assert height_sigma_mm(cap) == pytest.approx(alone)
    grad = height_gradient(cap, ids)
    shifts = pd.DataFrame(0.0, index=range(6), columns=list(CODEC_SHIFT_COLUMNS)).assign(id=ids)
    shifts["codec_vz_mm"] = 0.002
    assert height_sigma_mm(cap, None, grad, shifts) == pytest.approx(np.hypot(alone, 0.002))
    infl = pd.DataFrame({"camera": ["a"] * 6 + ["b"] * 6, "id": np.r_[ids, ids], "ix_mm": 0.0, "iy_mm": 0.0,
                         "iz_mm": np.r_[np.full(6, 0.004), np.full(6, -0.001)]})  # fmt: skip
    assert height_sigma_mm(cap, infl, grad) == pytest.approx(np.hypot(0.004, 0.001))  # above the fit's
    membrane = dataclasses.replace(cap, source="membrane top rows")
    assert height_gradient(membrane, ids).empty
