"""Rule measure_volume: soil volume and strains of every processed frame, meshes of a few."""

from pathlib import Path

from triaxtrack.kit import load_kit_design, target_table
from triaxtrack.logs import log_to
from triaxtrack.report import chosen_frames
from triaxtrack.tables import POINTS, STRAINS, VOLUME_RESULT, read_table, write_table
from triaxtrack.volume import volume_meshes, volume_series

log_to(snakemake.log[0])

cfg = snakemake.params.volume
design = load_kit_design(snakemake.input.kit)
table = target_table(design)
points = read_table(snakemake.input.points, POINTS)
t0, model = cfg["membrane_thickness_mm"], cfg["thickness_model"]
share = cfg["max_missing_share"]
volume, strains = volume_series(
    points, table, design, t0=t0, max_missing_share=share, thickness_model=model,
    warn_missing_share=cfg["warn_missing_share"],
)  # fmt: skip
write_table(volume, snakemake.output.volume, VOLUME_RESULT)
write_table(strains, snakemake.output.strains, STRAINS)
good = volume.loc[volume["reason"] == "", "frame"].tolist()
out = Path(snakemake.output.meshes)
out.mkdir(parents=True, exist_ok=True)
chosen = chosen_frames(good, cfg["mesh_frames"])
reference = volume["reference_frame"].dropna()
meshes = volume_meshes(
    points, table, design, chosen, out, t0=t0, thickness_model=model, max_missing_share=share,
    reference_frame=int(reference.iloc[0]) if len(reference) else None,
)  # fmt: skip
for frame, path, reason in meshes:
    print(f"frame {frame}: {path or 'no mesh: ' + reason}")
print(volume.drop(columns=["warning", "reason"]).describe().T.to_string())
warned = volume[volume["warning"] != ""]
if len(warned):
    print(f"{len(warned)} frames with warnings:\n{warned[['frame', 'warning']].to_string(index=False)}")
failed = volume[volume["reason"] != ""]
if len(failed):
    print(f"{len(failed)} frames failed:\n{failed[['frame', 'reason']].to_string(index=False)}")
