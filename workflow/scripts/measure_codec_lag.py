"""Rule measure_codec_lag: how one camera's P frames depart from its keyframes."""

from triaxtrack.codec_lag import estimate_lag_chunks, write_lags
from triaxtrack.frames import keyframe_test_frames
from triaxtrack.logs import log_to
from triaxtrack.tables import FRAME_MAP, TRACKS, read_table

log_to(snakemake.log[0])

camera = snakemake.wildcards.camera
fmap = read_table(snakemake.input.frames, FRAME_MAP)
keys = keyframe_test_frames(snakemake.input.video, fmap, 0, len(fmap))
lags = estimate_lag_chunks((read_table(path, TRACKS) for path in snakemake.input.tracks), keys)
note = "" if len(lags) else "not measured: no keyframe with enough P frames on either side"
write_lags(snakemake.output.lags, camera, keys, lags, note)
print(f"{camera}: P frames against keyframes {keys.tolist()} (triaxtrack.codec_lag):")
print(note or lags.to_string(index=False))
