"""Rendering one camera's frames (:class:`CameraRenderer`): the scene's surfaces and printed
shapes filled with exact area coverage, camera and recorder effects, and the truth
observations of the targets nothing hides."""

from __future__ import annotations

import cv2
import numpy as np
import pandas as pd

from triaxtrack import footage
from triaxtrack.kit import ShapeSet, surface_by_name
from triaxtrack.optics import project_air, project_water
from triaxtrack.raster import paint_into
from triaxtrack.simulate.scene import Scene, _surface_points, frame_progress, material_height, progress

# grey levels of the materials (8-bit, before lighting and noise)
GREY_BACKGROUND = 40.0
GREY_PEDESTAL_SIDE = 115.0
GREY_PEDESTAL_FACE = 95.0
GREY_MEMBRANE = 195.0
GREY_LABEL = 230.0
GREY_INK = 22.0
GREY_OCCLUDER = 70.0  # the dark-grey band of `occluder_z_mm` (a strap or a shadowing bar)
# tessellation of the untextured surfaces (their outlines only; dots are drawn exactly)
MEMBRANE_QUADS = (96, 48)  # (theta, Z)
PEDESTAL_QUADS = 72
OCCLUDER_QUADS = 192  # theta tessellation of the occluder band (chords: < 0.1 px from the exact edge)
OCCLUDER_ROW_MM = 3.0  # the band is drawn in rows of at most this height (follows the bulge)
EDGE_MARGIN_PX = 2.0  # a target is "seen" only if its whole image is this far inside the frame
OCCLUSION_TOL = 0.01  # coverage by a cell band above which a target behind it is hidden
SUBROWS_INK = 16  # y sampling of printed ink: keeps rendered centroids exact to < 0.005 px
SUBROWS_PLAIN = 4  # y sampling of outlines and white labels (no measurement relies on them)


def _strip_polygons(a: np.ndarray, b: np.ndarray, front: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Outline polygons of the runs of front-facing quads in a closed strip.

    ``a`` and ``b`` are the (n + 1, 2) image points of the strip's two edges (the last equal to
    the first), ``front`` the (n,) facing of quad k between points k and k + 1. Each cyclic run
    of facing quads becomes one polygon; quads with non-finite corners end a run.
    """
    n = len(front)
    ok = (
        front
        & np.isfinite(a[:-1]).all(1)
        & np.isfinite(a[1:]).all(1)
        & np.isfinite(b[:-1]).all(1)
        & np.isfinite(b[1:]).all(1)
    )
    if not ok.any():
        return np.zeros((0, 2)), np.zeros(0, np.int64)
    if ok.all():
        runs = [(0, n)]
    else:
        first_off = int(np.argmin(ok))
        order = [(first_off + k) % n for k in range(n)]
        runs, start = [], None
        for j, k in enumerate(order):
            if ok[k] and start is None:
                start = j
            if not ok[k] and start is not None:
                runs.append((order[start], j - start))
                start = None
        if start is not None:
            runs.append((order[start], n - start))
    verts, counts = [], []
    for k0, length in runs:
        idx = (k0 + np.arange(length + 1)) % n
        verts.append(np.vstack([a[idx], b[idx[::-1]]]))
        counts.append(2 * (length + 1))
    return np.vstack(verts), np.array(counts, np.int64)


class CameraRenderer:
    """Renders the frames of one camera in order, keeping last frame's ray solutions."""

    def __init__(self, scene: Scene, camera: str):
        self.scene = scene
        self.cam = scene.cameras[camera]
        self._xy: dict[str, np.ndarray] = {}
        self._xy_prev: dict[str, np.ndarray] = {}
        self._pinv: dict[str, np.ndarray] = {}
        h, w = self.cam.height, self.cam.width
        cfg = scene.cfg
        self._light = footage.vignetting_field(w, h, self.cam.K[0, 2], self.cam.K[1, 2], cfg.vignetting)
        if cfg.light_gradient > 0:
            direction = footage.gradient_direction(cfg.seed, camera)
            self._light = self._light * footage.gradient_field(w, h, cfg.light_gradient, direction)
        if cfg.exposure != 1:
            self._light = self._light * np.float32(cfg.exposure)
        s = scene.deformation
        nt, nz = MEMBRANE_QUADS
        th, zz = np.meshgrid(2 * np.pi * np.arange(nt + 1) / nt, np.linspace(0, s.height, nz + 1))
        self._mgrid = np.c_[th.ravel(), zz.ravel()]
        self._mgrid_shape = (nz + 1, nt + 1)

    # -- projection with warm starts
    def _project(self, key: str, pts: np.ndarray, in_water: bool, sel: np.ndarray | None = None):
        """Pixels (N, 2) and water ray directions (N, 3) of points; ``sel`` picks which to solve."""
        n = len(pts)
        uv = np.full((n, 2), np.nan)
        d2 = np.full((n, 3), np.nan)
        sel = np.arange(n) if sel is None else np.flatnonzero(sel)
        if not in_water:
            uv[sel] = project_air(self.cam, pts[sel])
            return uv, d2
        cache = self._xy.get(key)
        if cache is None or len(cache) != n:
            cache = np.full((n, 2), np.nan)
        prev = self._xy_prev.get(key)
        xy0 = cache[sel]
        if prev is not None and len(prev) == n:  # frames are rendered in order: extrapolate
            lin = 2 * cache[sel] - prev[sel]
            xy0 = np.where(np.isfinite(lin), lin, xy0)
        pinv = self._pinv.get(key)
        pinv = np.full((n, 2, 3), np.nan) if pinv is None or len(pinv) != n else pinv
        uv[sel], d2[sel], sol = project_water(self.cam, pts[sel], self.scene.cell, xy0, pinv[sel])
        self._xy_prev[key] = cache
        cache = cache.copy()
        cache[sel] = sol.xy
        self._xy[key] = cache
        pinv = pinv.copy()
        pinv[sel] = sol.pinv
        self._pinv[key] = pinv
        return uv, d2

    def _facing(self, pts, nrm, d2, in_water):
        """Cosine between the outward normal and the direction back towards the camera."""
        if in_water:
            return -np.einsum("ij,ij->i", nrm, d2)
        v = self.cam.center - pts
        return np.einsum("ij,ij->i", nrm, v) / np.linalg.norm(v, axis=1)

    def _shape_layer(self, shapes: ShapeSet, p: float):
        """Projected polygons of a shape set, culled; plus the per-polygon centre data."""
        sc = self.scene
        in_water = surface_by_name(sc.design)[shapes.surface]["medium_outside"] == "water"
        cpts, cnrm = _surface_points(sc, shapes.surface, shapes.center, p)
        cuv, cd2 = self._project(f"{shapes.surface}/{shapes.layer}/c", cpts, in_water)
        cos = self._facing(cpts, cnrm, cd2, in_water)
        keep = cos > 0
        vsel = np.repeat(keep, shapes.counts)
        vpts = np.full((len(shapes.theta_z), 3), np.nan)
        vpts[vsel] = _surface_points(sc, shapes.surface, shapes.theta_z[vsel], p)[0]
        vuv, _ = self._project(f"{shapes.surface}/{shapes.layer}/v", vpts, in_water, vsel)
        return vuv[vsel], shapes.counts[keep], keep, cuv, cos

    def _base_layers(self, p: float) -> list[tuple[np.ndarray, np.ndarray, float]]:
        """Untextured surfaces as strips of front-facing quads: pedestal sides and visible end
        faces, then the membrane (their outlines only; the printed shapes are drawn exactly)."""
        sc = self.scene
        out = []
        ped = sc.design.pedestal
        h0 = sc.design.specimen.height
        n = PEDESTAL_QUADS
        t = 2 * np.pi * np.arange(n + 1) / n
        r_m = sc.deformation.radius + sc.deformation.membrane_thickness
        for name, z0, z1, face_z, face_sign in (
            ("pedestal_bottom", -ped.height, 0.0, 0.0, 1.0),
            ("pedestal_top", h0, h0 + ped.height, h0, -1.0),
        ):
            shift = sc.deformation.top_displacement(p) if name == "pedestal_top" else np.zeros(3)
            rad = ped.radius

            def ring(r, z, shift=shift):
                return np.c_[r * np.cos(t), r * np.sin(t), np.full_like(t, z)] + shift

            side_n = np.c_[np.cos(t), np.sin(t), 0 * t]
            face_n = np.c_[0 * t, 0 * t, face_sign + 0 * t]
            for (ra, za), (rb, zb), nrm, grey, kind in (
                ((rad, z0), (rad, z1), side_n, GREY_PEDESTAL_SIDE, "side"),
                ((r_m, face_z), (rad, face_z), face_n, GREY_PEDESTAL_FACE, "face"),
            ):
                pts = np.vstack([ring(ra, za), ring(rb, zb)])
                uv, d2 = self._project(f"{name}/{kind}", pts, True)
                cos = -((nrm[:n] + nrm[1:]) * (d2[:n] + d2[1 : n + 1])).sum(axis=1)
                verts, counts = _strip_polygons(uv[: n + 1], uv[n + 1 :], cos > 0)
                out.append((verts, counts, grey))
        # membrane: one strip per row of quads
        pts, nrm = sc.deformation.outer_surface(self._mgrid[:, 0], self._mgrid[:, 1], p)
        c = self.cam.center
        rough = np.einsum("ij,ij->i", nrm, c - pts) > -0.5 * np.linalg.norm(c - pts, axis=1)
        uv, d2 = self._project("membrane/grid", pts, True, rough)
        nz, nt = self._mgrid_shape
        uv = uv.reshape(nz, nt, 2)
        cos = (-np.einsum("ij,ij->i", nrm, d2)).reshape(nz, nt)
        qcos = cos[:-1, :-1] + cos[:-1, 1:] + cos[1:, 1:] + cos[1:, :-1]
        vs, cs = [], []
        for i in range(nz - 1):
            v, cnt = _strip_polygons(uv[i], uv[i + 1], qcos[i] > 0)
            vs.append(v)
            cs.append(cnt)
        out.append((np.vstack(vs), np.concatenate(cs), GREY_MEMBRANE))
        return out

    def _occluder_polygons(self, p: float) -> tuple[np.ndarray, np.ndarray]:
        """Image polygons (packed vertices, counts) of the front-facing membrane surface
        between cell-frame heights ``occluder_z_mm`` at progress p (the occluder band).

        The band's edges are the printed surface's points at those heights (z in the cell frame,
        so the material slides under a fixed band as the specimen compresses), clipped to the
        membrane (0 .. the current height); empty if the band misses the membrane.
        """
        sc = self.scene
        s = sc.deformation
        z0, z1 = np.clip(np.asarray(sc.cfg.occluder_z_mm, float), 0.0, s.current_height(p))
        if z1 <= z0:
            return np.zeros((0, 2)), np.zeros(0, np.int64)
        nt = OCCLUDER_QUADS
        nz = int(np.ceil((z1 - z0) / OCCLUDER_ROW_MM))
        th = 2 * np.pi * np.arange(nt + 1) / nt
        T, ZC = np.meshgrid(th, np.linspace(z0, z1, nz + 1))
        Z = material_height(s, ZC.ravel(), T.ravel(), p)
        pts, nrm = s.outer_surface(T.ravel(), Z, p)
        c = self.cam.center
        rough = np.einsum("ij,ij->i", nrm, c - pts) > -0.5 * np.linalg.norm(c - pts, axis=1)
        uv, d2 = self._project("occluder", pts, True, rough)
        uv = uv.reshape(nz + 1, nt + 1, 2)
        cos = (-np.einsum("ij,ij->i", nrm, d2)).reshape(nz + 1, nt + 1)
        qcos = cos[:-1, :-1] + cos[:-1, 1:] + cos[1:, 1:] + cos[1:, :-1]
        vs, cs = [], []
        for i in range(nz):
            v, cnt = _strip_polygons(uv[i], uv[i + 1], qcos[i] > 0)
            vs.append(v)
            cs.append(cnt)
        return np.vstack(vs), np.concatenate(cs)

    def render(self, frame: int) -> tuple[np.ndarray, pd.DataFrame]:
        """The camera's uint8 grey image at ``frame`` and the exact observations it holds."""
        sc, cam = self.scene, self.cam
        p = frame_progress(frame, sc.cfg)
        h, w = cam.height, cam.width
        img = np.full((h, w), GREY_BACKGROUND)
        layers = self._base_layers(p)
        for verts, counts, grey in layers[:4]:  # pedestals
            paint_into(img, verts, counts, grey, SUBROWS_PLAIN)
        obs = []
        band_cov = None
        occluder_cov = None
        order: list = [s for s in sc.shapes if s.surface.startswith("pedestal")]
        order += [None]  # the membrane outline goes here
        order += [s for s in sc.shapes if s.surface == "membrane"]
        order += ["occluder"] if sc.cfg.occluder_z_mm is not None else []
        order += [s for s in sc.shapes if s.surface == "cell_outer"]
        pending = []
        for shapes in order:
            if shapes is None:
                verts, counts, grey = layers[4]
                paint_into(img, verts, counts, grey, SUBROWS_PLAIN)
                continue
            if isinstance(shapes, str):  # the occluder band, over the membrane and its dots
                verts, counts = self._occluder_polygons(p)
                r0, cov = paint_into(img, verts, counts, GREY_OCCLUDER, SUBROWS_PLAIN)
                occluder_cov = np.zeros((h, w))
                occluder_cov[r0 : r0 + len(cov)] = cov
                continue
            vuv, counts, keep, cuv, cos = self._shape_layer(shapes, p)
            ink = shapes.layer == "ink"
            grey = GREY_INK if ink else GREY_LABEL
            r0, cov = paint_into(img, vuv, counts, grey, SUBROWS_INK if ink else SUBROWS_PLAIN)
            if shapes.surface == "cell_outer" and shapes.layer == "label":
                band_cov = np.zeros((h, w)) if band_cov is None else band_cov
                np.maximum(band_cov[r0 : r0 + len(cov)], cov, out=band_cov[r0 : r0 + len(cov)])
            if shapes.layer == "ink":
                pending.append((shapes, vuv, counts, keep, cuv, cos))
        for shapes, vuv, counts, keep, cuv, cos in pending:
            obs.append(self._observations(shapes, vuv, counts, keep, cuv, cos, band_cov, occluder_cov, frame))
        img = self._camera_effects(img, frame)
        return img, pd.concat(obs, ignore_index=True)

    def _observations(
        self, shapes, vuv, counts, keep, cuv, cos, band_cov, occluder_cov, frame
    ) -> pd.DataFrame:
        """The targets a user could see in this image: the truth observations.

        A target is seen when its whole image is ``EDGE_MARGIN_PX`` inside the frame, it faces
        the camera (``min_view_cos``), and nothing hides any of it: a white band of the cell
        wall (``band_cov``: coverage above ``OCCLUSION_TOL`` anywhere in the target's image box),
        the occluder band (``occluder_cov``, same rule; targets of the cell wall are in front of
        it) or the timestamp overlay (``footage.overlay_box``: the target's image box comes within
        ``EDGE_MARGIN_PX`` of it). ``triaxtrack score`` counts coverage as labelled / seen here.
        """
        cam = self.cam
        ids_kept = shapes.ids[keep]
        starts = np.concatenate([[0], np.cumsum(counts)[:-1]])
        lo = np.minimum.reduceat(vuv, starts) if len(counts) else np.zeros((0, 2))
        hi = np.maximum.reduceat(vuv, starts) if len(counts) else np.zeros((0, 2))
        # a target may have several ink polygons (a CT): combine by ID
        df = pd.DataFrame({"id": ids_kept, "u0": lo[:, 0], "v0": lo[:, 1], "u1": hi[:, 0], "v1": hi[:, 1]})
        box = df.groupby("id").agg(u0=("u0", "min"), v0=("v0", "min"), u1=("u1", "max"), v1=("v1", "max"))
        m = EDGE_MARGIN_PX
        inside = (
            (box.u0 >= m) & (box.v0 >= m) & (box.u1 <= cam.width - 1 - m) & (box.v1 <= cam.height - 1 - m)
        )
        box = box[inside & np.isfinite(box).all(axis=1)]
        centre = pd.DataFrame({"id": shapes.ids, "u_px": cuv[:, 0], "v_px": cuv[:, 1], "cos": cos})
        centre = centre.drop_duplicates("id").set_index("id").loc[box.index]
        centre = centre[centre.cos >= self.scene.cfg.min_view_cos]
        for cov in (band_cov, occluder_cov):
            if shapes.surface != "cell_outer" and cov is not None and len(centre):
                centre = centre[~_covered(cov, box.loc[centre.index])]
        if self.scene.cfg.timestamp_overlay and len(centre):
            b = box.loc[centre.index, ["u0", "v0", "u1", "v1"]].to_numpy()
            centre = centre[~footage.boxes_overlap(b, footage.overlay_box(cam.width, cam.height), m)]
        return pd.DataFrame({
            "camera": cam.name,
            "frame": np.int64(frame),
            "id": centre.index.to_numpy(np.int64),
            "u_px": centre.u_px.to_numpy(),
            "v_px": centre.v_px.to_numpy(),
        })  # fmt: skip

    def _camera_effects(self, img: np.ndarray, frame: int) -> np.ndarray:
        """Camera and recorder effects, in the order they happen (:mod:`triaxtrack.footage`):
        light (vignetting, light gradient, exposure and its drift), optional blur, the timestamp
        overlay, sensor noise (seeded per camera and frame), rounding to 8 bits."""
        cfg, cam = self.scene.cfg, self.cam
        img = img * self._light
        if cfg.exposure_drift > 0:
            gain = footage.exposure_gain(progress(frame, cfg.frames), cfg.exposure_drift, cfg.seed, cam.name)
            img = img * gain
        if cfg.blur_sigma_px > 0:
            img = cv2.GaussianBlur(img, (0, 0), cfg.blur_sigma_px)
        if cfg.timestamp_overlay:
            img = footage.draw_timestamp(img, footage.timestamp_text(frame, cfg.fps))
        rng = footage.camera_rng(cfg.seed, cam.name, (frame,))
        noise = rng.standard_normal(img.shape, dtype=np.float32)
        img = img + cfg.noise_sigma * noise * np.sqrt(np.maximum(img, 1) / 128)  # shot-noise-like
        return np.clip(np.round(img), 0, 255).astype(np.uint8)


def _covered(cov: np.ndarray, boxes: pd.DataFrame) -> np.ndarray:
    """Per image box (rows with ``u0, v0, u1, v1``, pixels): is the (h, w) coverage ``cov``
    above ``OCCLUSION_TOL`` anywhere in the pixels the box touches?"""
    hit = [
        cov[int(np.floor(r.v0)) : int(np.ceil(r.v1)) + 1, int(np.floor(r.u0)) : int(np.ceil(r.u1)) + 1].max()
        > OCCLUSION_TOL
        for r in boxes.itertuples()
    ]
    return np.array(hit, bool)
