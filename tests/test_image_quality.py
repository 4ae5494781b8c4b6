"""Noise and blur measured from a frame, and touching blurred dots cut apart (triaxtrack.detect)."""

import cv2
import numpy as np
import pytest

from triaxtrack.detect import detect_blobs
from triaxtrack.image_quality import blur_sigma, noise_sigma

WHITE, INK = 200.0, 40.0


def _dots(centres, radius, shape=(160, 1280), blur=0.0, noise=0.0, seed=0, oversample=8):
    """A white frame (1280 wide: the local background is measured over 16 px) with dark discs
    at ``centres`` ((N, 2) u, v pixels, OpenCV convention), each of ``radius`` pixels, drawn
    with exact pixel coverage (oversampled), then blurred and noised."""
    h, w = shape
    s = oversample
    big = np.full((h * s, w * s), WHITE, np.float32)
    for u, v in centres:
        cv2.circle(big, (int(round((u + 0.5) * s - 0.5)), int(round((v + 0.5) * s - 0.5))),
                   int(round(radius * s)), INK, -1)  # fmt: skip
    img = cv2.resize(big, (w, h), interpolation=cv2.INTER_AREA)
    if blur > 0:
        img = cv2.GaussianBlur(img, (0, 0), blur)
    img = img + noise * np.random.default_rng(seed).standard_normal(img.shape)
    return np.clip(np.round(img), 0, 255).astype(np.uint8)


def test_noise_sigma_reads_white_noise_within_15_percent():
    for sigma in (2.0, 4.0, 6.0):
        img = _dots([(40.3, 50.6), (100.2, 60.1)], 6, noise=sigma, seed=int(sigma))
        assert noise_sigma(img) == pytest.approx(sigma, rel=0.15)


def test_blur_sigma_reads_the_lens_blur_from_large_dots():
    centres = [(30 + 40 * i + 0.3 * i, 30 + 50 * j + 0.2 * j) for i in range(3) for j in range(2)]
    sharp = blur_sigma(_dots(centres, 5), detect_blobs(_dots(centres, 5)))
    assert sharp < 0.5
    for blur in (1.0, 1.5):
        img = _dots(centres, 5, blur=blur, noise=2.0)
        assert blur_sigma(img, detect_blobs(img)) == pytest.approx(blur, abs=0.3)


def test_touching_blurred_dots_are_cut_apart_near_their_centres():
    # columns of dots 2.2 px radius, 6 px apart down a column: blurred by 1 px they touch
    rng = np.random.default_rng(3)
    centres = np.array([(20 + 12 * i + rng.uniform(), 14 + 6 * j + rng.uniform()) for i in range(10)
                        for j in range(16)])  # fmt: skip
    # large dots (radius 5) for the blur estimate
    big = np.array([(20 + 30 * i + 0.4, 112.3) for i in range(5)])
    img = _dots(np.r_[centres, big], 2.2, shape=(130, 1280), blur=1.0, noise=3.0)
    img = np.minimum(img, _dots(big, 5, shape=(130, 1280), blur=1.0))
    blobs = detect_blobs(img)
    assert blobs.blur.iloc[0] > 0.5
    uv = blobs[["u_px", "v_px"]].to_numpy()
    d = np.linalg.norm(uv[None, :, :] - centres[:, None, :], axis=2).min(axis=1)
    assert (d < 0.5).mean() >= 0.95  # found, one blob each, within half a pixel
    assert blobs.split.any()


def test_a_long_column_of_touching_dots_is_cut_however_long_but_a_dark_area_is_not():
    # most dots (radius 2.2 px) stand apart, 12 px each way; two columns of 30 dots 5 px apart touch once
    # blurred: each is one component far larger than SPLIT_MAX_AREA_FACTOR x the median dot, but
    # one dot thick. The rim of a dark square (a silhouette's background) is not cut.
    rng = np.random.default_rng(5)
    apart = [(20 + 12 * i + rng.uniform(), 14 + 12 * j + rng.uniform()) for i in range(40) for j in range(14)]
    jitter = rng.uniform(0, 0.3, (60, 2))
    column = [(520 + 14 * (k // 30) + jitter[k, 0], 14 + 5 * (k % 30) + jitter[k, 1]) for k in range(60)]
    centres = np.array(apart + column)
    big = np.array([(700 + 30 * i + 0.4, 100.3) for i in range(5)])
    img = _dots(np.r_[centres, big], 2.2, shape=(180, 1280), blur=1.0, noise=3.0)
    img = np.minimum(img, _dots(big, 5, shape=(180, 1280), blur=1.0))
    img[40:120, 900:1000] = INK
    blobs = detect_blobs(img)
    uv = blobs[["u_px", "v_px"]].to_numpy()
    d = np.linalg.norm(uv[None, :, :] - np.array(column)[:, None, :], axis=2).min(axis=1)
    assert (d < 0.5).mean() >= 0.9  # each touching dot found on its own, within half a pixel
    in_square = (uv[:, 0] > 895) & (uv[:, 0] < 1005) & (uv[:, 1] > 35) & (uv[:, 1] < 125)
    assert in_square.any() and not blobs.split.to_numpy()[in_square].any()


@pytest.mark.parametrize("seed", [3, 4])
def test_soft_dots_are_centred_on_the_raw_pixels_in_their_own_windows(seed):
    # dots 2.2 px radius, 12 px apart across and 7-8 px down, blurred by 1 px (soft: the mask is
    # thresholded smoothed) with noise 4: the smoothed mask's own centroids came 0.084-0.090 px
    # from the true centres at the median and 0.146-0.152 px at the 90th percentile
    rng = np.random.default_rng(seed)
    for pitch in (7.0, 8.0):
        centres = np.array([(20 + 12 * i + rng.uniform(), 14 + pitch * j + rng.uniform())
                            for i in range(40) for j in range(int(96 / pitch))])  # fmt: skip
        big = np.array([(20 + 30 * i + 0.4, 112.3) for i in range(5)])
        img = _dots(np.r_[centres, big], 2.2, shape=(130, 1280), blur=1.0, noise=4.0, seed=seed)
        img = np.minimum(img, _dots(big, 5, shape=(130, 1280), blur=1.0))
        blobs = detect_blobs(img)
        assert blobs.blur.iloc[0] > 0.5
        uv = blobs[["u_px", "v_px"]].to_numpy()
        d = np.linalg.norm(uv[None, :, :] - centres[:, None, :], axis=2).min(axis=1)
        assert np.median(d) <= 0.08, (pitch, np.median(d))
        assert np.quantile(d, 0.9) <= 0.145, (pitch, np.quantile(d, 0.9))


def test_an_under_exposed_frame_is_detected_as_the_same_frame_exposed_normally():
    from triaxtrack.detect import DetectParams, dot_mask, exposure_params

    rng = np.random.default_rng(8)
    grid = [(20 + 14 * i, 14 + 14 * j) for i in range(60) for j in range(8)]
    centres = np.array(grid) + rng.uniform(0, 1, (len(grid), 2))
    img = _dots(centres, 2.5, shape=(130, 1280), blur=0.6, noise=2.0)
    assert exposure_params(img) == DetectParams()  # a normal exposure: unchanged
    noise = np.random.default_rng(9).normal(0, 1.0, img.shape)
    dim = np.round(img * 0.15 + noise).clip(0, 255).astype(np.uint8)  # white 30, the dots 24 darker

    def found(frame, params):
        blobs = detect_blobs(frame, params)
        uv = blobs[["u_px", "v_px"]].to_numpy()[dot_mask(blobs, params)]
        d = np.linalg.norm(uv[None, :, :] - centres[:, None, :], axis=2)
        return (d.min(axis=1) < 0.5).mean(), len(uv)

    assert found(img, None) == (1.0, len(centres))
    assert found(dim, None)[0] < 0.5  # contrast 24 grey levels: under the fixed floor of 25
    assert found(dim, exposure_params(dim)) == (1.0, len(centres))  # every dot, and nothing else
