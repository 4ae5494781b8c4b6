"""How inter-coded video frames depart from keyframes, measured at keyframes and removed from the
tracks.

An H.264/H.265 encoder codes a predicted (P) frame as the previous decoded frame moved by
quarter-pixel motion vectors plus a quantised residual. A dot that moves by a fraction of a
pixel per frame is therefore shown a little behind where it is: the residual that would move
it is partly quantised away, and the shortfall carries over from frame to frame. A keyframe
(an intra-coded frame) is coded from the picture alone and shows the dot where it is. Seen in
the tracks, every P frame's centroids lag the motion by a common fraction ``lag`` of a frame
(the picture is effectively taken ``lag`` frames earlier), and the trajectory steps forward at
every keyframe: 0.02-0.03 frames on the simulator's H.264 at crf 14 (0.005 px at 0.28 px per
frame). P frames also render the dots a little differently from a keyframe, which moves their
centroids by a smooth field across the image: on the simulator's H.264 the membrane dots of a
P frame sit closer to the specimen's axis, a horizontal scale of -0.6e-4 to -1.2e-4 on top of
the keyframe's own. Together they put a step of 0.01-0.03 % of the specimen's volume at each
keyframe.

The lag is measured per camera at each keyframe ``K`` from the camera's own tracks: on each
side of ``K``, a quadratic in time is fitted to every dot's centroids in the nearest
``SIDE_FRAMES`` P frames (all from the same GOP, so with one common lag; fewer, at least
``SHORT_SIDE_FRAMES``, on a side too short to leave ``FAR_FRAMES`` beyond them: a quadratic
through few frames weighs the first P frame most, which x265 codes unlike the rest of its
GOP), and evaluated at
``K``; there it gives the dot's position ``lag`` frames late, ``x(K) - lag x'(K)``, while the
keyframe shows ``x(K)``. The difference over all the membrane dots is fitted by least squares
as the lag times each dot's velocity ``x'`` plus an affine field of the image coordinates per
axis (seven coefficients, with their standard errors; a coefficient within
``SIGNIFICANT_SIGMAS`` of zero is taken as zero). The velocity is a straight line's slope
over the next ``FAR_FRAMES`` P frames beyond those (a velocity fitted to the same frames as
the extrapolation shares its noise, and biases the ratio by as much as the lag itself at
0.015 px of centroid noise); the quadratic absorbs the motion's own acceleration. A dot at rest
carries no weight, so a static test gives no correction. A keyframe where the motion changes
(the RMS speeds on its two sides differ by more than ``MAX_SPEED_RATIO``: a hold, a reversal, a
new loading rate) is not measured: extrapolated across the change, the P frames would read as
lagging by many frames.

Each P frame's membrane dots are then moved forward by ``lag x'`` (``x'`` the dot's velocity
from its own P-frame centroids around that frame, pixels per frame) and by the field, the
coefficients interpolated linearly in time across the GOP, from those measured just after its
keyframe to those measured just before the next (frames before the first keyframe given, or
after the last, take the missing end from the neighbouring GOP). What is left: a departure that
grows within the
last few frames of a GOP (x264's rate control spends fewer bits on frames no later frame
refers to) is measured only as its mean over the ``SIDE_FRAMES`` before the keyframe.
Keyframes are left as they are.

The other targets (the CTs and dots of the cell wall and the pedestals) are few per camera and
lie on rigid bodies, so their P frames are measured per body (``bodies``: the kit's surfaces
other than the membrane, :func:`rigid_bodies`) as a common offset ``(u0_px, v0_px)`` only, the
keyframe's centroids minus the P frames' quadratic extrapolated to it. It is not a lag: on the
simulator's H.264 the top cap's CTs read 0.011 px lower than the keyframes in every P frame of a
test where the cap moves 0.3 px a frame (ahead of the motion), and 0.008 px higher (behind it),
reached after some 10 frames, where it moves 0.001 px a frame; uncorrected, that is 2-3
micrometres of the cap's height in every P frame. One keyframe's offset rests on a few targets,
so it is pooled (:func:`pooled_offsets`), per body and side, over every camera's keyframes where
the body moves at a similar speed (a hold pools with holds), and applied where the pooled offset
is at least ``SIGNIFICANT_SIGMAS`` standard errors from zero. Its standard error has two parts:
the spread over the targets, which averages down over every camera, and the frames' common
jitter (the body's targets jumping together from frame to frame, in every camera at once on a
realistic 720p render), which averages down only over distinct keyframes. Across the GOP the
offset moves from the value after its keyframe to the value before the next no faster than the
body moves (:func:`~triaxtrack.codec_lag.correct._coefficients` with ``rise``). What the
correction leaves is carried with each P-frame observation of a rigid body as ``codec_u_px,
codec_v_px``: the pooled offset's standard error where it is applied, and where it is not, the
offset itself as well (``sqrt(m^2 + se^2)``: on a clean 1080p test with two keyframes the top
cap's -0.014 px, alike in all 16 cameras, is too uncertain to take off and reads the cap 2.8
micrometres low), and in quadrature the P frame's own departure from the offset (the frames'
common jitter about the side's quadratic, ``jitter_u0_px, jitter_v0_px``: one offset corrects
every P frame); an error in every camera at once, which the triangulation turns into each
point's shift and the volume's uncertainty adds in full (:mod:`triaxtrack.influence`).

In the workflow, rule ``measure_codec_lag`` measures one camera at every keyframe of the test
over its chunks of tracks in order (:func:`estimate_lag_chunks`: a keyframe's two sides may lie
in different chunks, so a chunk shorter than the GOP is measured and corrected like any other)
and writes ``results/<test>/codec_lag/<camera>.json`` (:func:`write_lags`, :func:`read_lags`);
``triangulate_chunk`` corrects each chunk's tracks with every camera's file
(:func:`corrected_tracks`); :func:`run_measure_codec_lag` is that rule's stage. Frames are test
frames; pixels in OpenCV's convention.
"""

from triaxtrack.codec_lag.correct import correct_lag, corrected_tracks, lag_corrected, pooled_offsets
from triaxtrack.codec_lag.files import LagFile, read_lag_files, read_lags, run_measure_codec_lag, write_lags
from triaxtrack.codec_lag.measure import LAG_COLUMNS, estimate_lag, estimate_lag_chunks, rigid_bodies

__all__ = [
    "LAG_COLUMNS",
    "LagFile",
    "correct_lag",
    "corrected_tracks",
    "estimate_lag",
    "estimate_lag_chunks",
    "lag_corrected",
    "pooled_offsets",
    "read_lag_files",
    "read_lags",
    "rigid_bodies",
    "run_measure_codec_lag",
    "write_lags",
]
