"""Benchmarks that print figures (they assert nothing): ``python -m triaxtrack.bench``.

``simulate``: seconds per camera-frame to render and encode a simulated test at a given size.
``identify``: seconds to detect and label every target of one frame (one core), per size, with
the number of targets labelled (frames rendered by the simulator, exact truth cameras).
"""

from __future__ import annotations

import argparse
import tempfile
import time
import tracemalloc
from pathlib import Path


def bench_simulate(width: int, height: int, frames: int, cameras: int = 2) -> dict:
    from triaxtrack.kit import export_kit, load_design
    from triaxtrack.simulate import CameraRenderer, SimulationConfig, load_scene, make_scene
    from triaxtrack.video import VideoWriter

    design = Path(__file__).resolve().parents[2] / "config" / "kit.yaml"
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        export_kit(load_design(design), tmp / "kit")
        cfg = SimulationConfig(cameras=cameras, frames=frames, width=width, height=height)
        make_scene(cfg, tmp / "kit", tmp / "t", "bench")
        scene = load_scene(tmp / "t")
        render_s = encode_s = 0.0
        tracemalloc.start()
        for cam in list(scene.cameras)[:cameras]:
            rend = CameraRenderer(scene, cam)
            with VideoWriter(tmp / f"{cam}.mp4", width, height, cfg.fps) as vw:
                for k in range(frames):
                    t0 = time.perf_counter()
                    img, _ = rend.render(k)
                    t1 = time.perf_counter()
                    vw.write(img)
                    encode_s += time.perf_counter() - t1
                    render_s += t1 - t0
        peak = tracemalloc.get_traced_memory()[1]
        tracemalloc.stop()
    n = cameras * frames
    return {"size": f"{width}x{height}", "camera_frames": n, "render_s_per_frame": render_s / n,
            "encode_s_per_frame": encode_s / n, "peak_python_mb": peak / 2**20}  # fmt: skip


def bench_identify(width: int, height: int, repeat: int = 3) -> dict:
    import cv2

    from triaxtrack.identify import label_frame
    from triaxtrack.kit import ct_codes, export_kit, load_design, load_kit_design, target_table
    from triaxtrack.simulate import CameraRenderer, SimulationConfig, load_scene, make_scene

    cv2.setNumThreads(1)
    design = Path(__file__).resolve().parents[2] / "config" / "kit.yaml"
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        export_kit(load_design(design), tmp / "kit")
        cfg = SimulationConfig(cameras=2, frames=2, width=width, height=height, seed=3)
        make_scene(cfg, tmp / "kit", tmp / "t", "bench")
        scene = load_scene(tmp / "t")
        kit = load_kit_design(tmp / "kit")
        codes = ct_codes(kit, target_table(kit))
        name = next(iter(scene.cameras))
        img, _ = CameraRenderer(scene, name).render(0)
        times, labelled = [], 0
        for _ in range(repeat):
            t0 = time.perf_counter()
            labels = label_frame(img, scene.cameras[name], kit, codes)
            times.append(time.perf_counter() - t0)
            labelled = int((labels.id > 0).sum())
    return {"size": f"{width}x{height}", "seconds": min(times), "labelled": labelled}


def main(argv: list[str] | None = None) -> None:
    p = argparse.ArgumentParser(description=__doc__)
    p.add_argument("what", nargs="*", default=["simulate", "identify"], choices=["simulate", "identify"])
    p.add_argument("--sizes", default="1280x720,1920x1080,3840x2160")
    p.add_argument("--frames", type=int, default=10)
    args = p.parse_args(argv)
    sizes = [tuple(int(x) for x in size.split("x")) for size in args.sizes.split(",")]
    for w, h in sizes if "identify" in args.what else []:
        r = bench_identify(w, h)
        print(
            f"identify {r['size']:>9}: {r['seconds']:.3f} s to detect and label one frame on one core "
            f"({r['labelled']} targets labelled; best of 3)"
        )
    for w, h in sizes if "simulate" in args.what else []:
        r = bench_simulate(w, h, args.frames)
        print(f"simulate {r['size']:>9}: render {r['render_s_per_frame']:.3f} s/frame, encode "
              f"{r['encode_s_per_frame']:.3f} s/frame ({r['camera_frames']} camera-frames, "
              f"peak Python memory {r['peak_python_mb']:.0f} MB)")  # fmt: skip


if __name__ == "__main__":
    main()
