"""Command line: ``triaxtrack kit | simulate | check-sim | score``."""

from __future__ import annotations

import argparse
import json
import sys
import time
from dataclasses import fields
from pathlib import Path

DEFAULT_DESIGN = Path(__file__).resolve().parents[2] / "config" / "kit.yaml"

SCORE_HELP = """\
Score whatever RESULTS_DIR holds against TRUTH_DIR (a simulated test folder or its truth/).
One row per metric and item (a camera, camera@frame, all@frame, worst@frame, failed frames);
a row without a tolerance is reported only. Tolerances: the config's `score` section.

calibration/<camera>.json, cameras.json
  focal_rel_error, principal_point_error (px), undistortion_map_error (px; reported:
  ray_direction_error), camera_center_error (mm), camera_rotation_error (deg);
  camera_left_out: a true camera the workflow left out, and said why in quality.json (reported)
  camera_missing / camera_unknown: a true camera absent from the results / a result camera
  the truth lacks (fail); image_size_mismatch: calibrated at another image size (fails)
labels.parquet (per camera@frame)
  wrong_ids: labels farther than wrong_id_px from their target's exact projection;
  coverage: share of the targets the truth says the camera sees that are labelled;
  coverage_frontal (reported): the same among those facing the camera within 60 degrees;
  cell_centroid_median, cell_centroid_p95: centroid errors of the cell-wall dots (px)
quality.json
  mean_reprojection (px), all cameras and each
points.parquet (per frame)
  membrane_rms_error (mm; reported: membrane_max_error, pedestal_rms_error, cell_wall_rms_error),
  membrane_3_rays: share of the membrane dots from 3+ rays; membrane_kept: share of the membrane
  dots seen at the first frame still reconstructed at the last
observations.parquet (with tracking.parquet)
  id_swaps: observations farther than wrong_id_px from their own target's true projection;
  observation_max_error, observation_median_error (px, reported);
  observations_without_truth (reported): observations (camera, frame, id) the truth has no
  projection for, so they cannot be checked for swaps: the simulator does not count the target
  as seen there (partly outside the image, facing away, or partly hidden by a cell-wall band,
  an occluder or the timestamp), or the camera did not record that frame
tracking.parquet (per camera, reported)
  centroid_sigma_median, centroid_sigma_p95 (px), tracked_share
volume.parquet (per frame)
  volume_error, volume_change_error, axial_strain_error; frames_measured: share of frames with
  a volume (must be 1); reported: volume_error_sigmas, measured_fraction_min
Per-frame metrics show the first and last frame, the worst (worst@<frame>) and the number of
frames that failed (item `failed frames`, must be 0). Then "N of M within tolerance" and one line
per camera: coverage min/median, sigma_px median/p95, tracked %.

Exit status: 0 every row within tolerance; 1 a tolerance missed; 2 unusable input, or nothing
to score (the results folder holds none of the files above).
"""


def _kit(args: argparse.Namespace) -> int:
    from triaxtrack.kit import export_kit, load_design

    export_kit(load_design(args.design), args.out)
    print(f"kit written to {args.out}")
    return 0


def _simulate(args: argparse.Namespace) -> int:
    from triaxtrack.kit import export_kit, load_design
    from triaxtrack.layout import TEST_FOLDER
    from triaxtrack.simulate import SimulationConfig, simulate_test
    from triaxtrack.simulate.scene import FOLLOWABLE_ROWS, largest_step_rows

    opts = {
        f.name: getattr(args, f.name)
        for f in fields(SimulationConfig)
        if getattr(args, f.name, None) is not None
    }
    if args.preset is not None:
        opts["preset"] = args.preset  # the keys given on the command line override it
    cfg = SimulationConfig.from_dict(opts)
    out = Path(args.out)
    kit_dir = out / TEST_FOLDER.kit
    t0 = time.perf_counter()
    export_kit(load_design(args.design), kit_dir)
    simulate_test(cfg, kit_dir, out, args.name or out.name, args.chunk_size)
    dt = time.perf_counter() - t0
    print(f"simulated {cfg.cameras} cameras x {cfg.frames} frames ({cfg.width}x{cfg.height}) in {dt:.1f} s "
          f"({dt / (cfg.cameras * cfg.frames):.3f} s per camera-frame) -> {out}")  # fmt: skip
    step = largest_step_rows(cfg, load_design(args.design))
    if step > FOLLOWABLE_ROWS:
        warning = (f"warning: membrane dots move up to {step:.2f} of a dot row between frames (over "
                   f"{FOLLOWABLE_ROWS}): from a chunk's first frame the tracker reads such a grid one "
                   "row over; render more frames, or less axial_strain or axial_nonuniformity")  # fmt: skip
        print(warning, file=sys.stderr)
    return 0


def _check_sim(args: argparse.Namespace) -> int:
    from triaxtrack.simulate import check_simulation

    rep = check_simulation(args.test_dir, args.json)
    for key in ("air_dots", "membrane_dots"):
        s = rep[key]
        print(f"{key:<14} n={s['n']:<6} median {s['median_px']:.4f} px  p95 {s['p95_px']:.4f} px  "
              f"bias ({s['bias_u_px']:+.4f}, {s['bias_v_px']:+.4f}) px")  # fmt: skip
    print("ok" if rep["ok"] else "NOT OK")
    return 0 if rep["ok"] else 1


def _score(args: argparse.Namespace) -> int:
    import yaml

    from triaxtrack.camera_report import camera_summary, format_camera_summary
    from triaxtrack.score import ScoreTolerances, format_table, score

    tol = ScoreTolerances()
    if args.config:
        try:  # an unknown key in its `score` section is an error naming the file and the key
            tol = ScoreTolerances.from_dict(yaml.safe_load(Path(args.config).read_text()).get("score"))
        except ValueError as err:
            print(f"triaxtrack score: {args.config}: {err}", file=sys.stderr)
            return 2
    try:
        df = score(args.results_dir, args.truth_dir, tol)
    except ValueError as err:
        print(f"triaxtrack score: {err}", file=sys.stderr)
        return 2
    if df.empty:
        print(f"triaxtrack score: {args.results_dir}: {format_table(df)}", file=sys.stderr)
        return 2
    print(format_table(df))
    summary = format_camera_summary(camera_summary(df))
    if summary:
        print(f"\n{summary}")
    if args.json:
        Path(args.json).write_text(json.dumps(df.to_dict(orient="records"), indent=2, default=float))
    return 0 if df.passed.all() else 1


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="triaxtrack", description=__doc__)
    sub = p.add_subparsers(dest="command", required=True)

    k = sub.add_parser("kit", help="export the target kit (kit.json, targets.csv, textures, sheets, board)")
    k.add_argument("out")
    k.add_argument("--design", default=str(DEFAULT_DESIGN), help="kit design YAML (default: config/kit.yaml)")
    k.set_defaults(func=_kit)

    s = sub.add_parser("simulate", help="simulate a triaxial test into a test folder")
    s.add_argument("out")
    s.add_argument("--design", default=str(DEFAULT_DESIGN))
    s.add_argument("--name", default=None, help="test name (default: the folder name)")
    s.add_argument("--chunk-size", type=int, default=50)
    from triaxtrack.simulate import PRESETS, SimulationConfig

    s.add_argument("--preset", choices=sorted(PRESETS), default=None,
                   help="named settings (nvr: realistic NVR footage); other options override it")  # fmt: skip
    for f in fields(SimulationConfig):
        type_name = f.type if isinstance(f.type, str) else f.type.__name__
        flag = f"--{f.name.replace('_', '-')}"
        if type_name == "bool":
            s.add_argument(flag, dest=f.name, action=argparse.BooleanOptionalAction, default=None,
                           help=f"default {f.default}")  # fmt: skip
            continue
        if type_name == "tuple[float, float] | None":
            s.add_argument(flag, dest=f.name, type=float, nargs=2, metavar=("LOW", "HIGH"), default=None,
                           help=f"default {f.default}")  # fmt: skip
            continue
        typ = {"int": int, "float": float, "str": str}.get(type_name)
        if typ is None:
            continue  # per-camera mappings (start_offset_s, dropped_frames): config files only
        s.add_argument(flag, dest=f.name, type=typ, default=None, help=f"default {f.default}")
    s.set_defaults(func=_simulate)

    c = sub.add_parser("check-sim", help="measure a simulated test's rendered dots against its truth")
    c.add_argument("test_dir")
    c.add_argument("--json", default=None)
    c.set_defaults(func=_check_sim)

    sc = sub.add_parser("score", help="compare a results folder with a truth folder", description=SCORE_HELP,
                        formatter_class=argparse.RawDescriptionHelpFormatter)  # fmt: skip
    sc.add_argument("results_dir")
    sc.add_argument("truth_dir")
    sc.add_argument("--config", default=None, help="config YAML with a `score` section of tolerances")
    sc.add_argument("--json", default=None)
    sc.set_defaults(func=_score)
    return p


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    return args.func(args)


if __name__ == "__main__":
    sys.exit(main())
