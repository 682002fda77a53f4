"""Render the clean irradiance image the camera sees (before sensor noise).

Method (why: geometry must be far more accurate than the vision targets):
1. Everything is projected with an ideal pinhole into an undistorted "ideal" canvas that is
   large enough to cover the distorted field of view.
2. The foreground (ORU, marker plate, circles, rod) is drawn with cv2.fillPoly at 4x
   supersampling with 8 sub-pixel bits, only inside its bounding box, then box-averaged
   (INTER_AREA = pixel integration). Circles are 128-gons of the exact projected 3-D circle,
   so the projected-centre (ellipse) bias of real optics is reproduced.
   The background wall is drawn at 1x with anti-aliased edges (its accuracy does not matter).
3. Lens distortion: cv2.remap from the ideal canvas with a map built by undistorting every
   output pixel (the forward Brown-Conrady model of the controller's camera file).
4. Defocus: thin-lens circle of confusion per depth layer (marker/ORU layer at the marker
   depth, wall layer at the wall depth) as a Gaussian of the disc's second moment (sigma =
   c/4) combined with the Airy diffraction blur; layers are composited with premultiplied
   alpha after blurring, so edges between depths blur like a real lens would (approximately).
5. Uneven lighting: Lambert shading per face, then a smooth image-space field (gradient + hot
   spot) and vignetting.
"""
from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache
from typing import Sequence

import cv2
import numpy as np

from spacearm.base.vision.camera import CameraModel
from spacearm.base.vision.config import Optics
from spacearm.firmware_sim.camera.scene import Scene

SS = 4            # supersampling factor of the foreground
SHIFT = 8         # fractional bits for cv2 drawing
ONE = 1 << SHIFT
NEAR = 1e-3       # m, polygons with a vertex nearer than this are not drawn
CIRCLE_SEGMENTS = 128
MAX_BLUR = 20.0   # px, largest Gaussian sigma of a defocused layer


@dataclass(frozen=True)
class FlatLayer:
    """A flat object drawn straight into the output (distorted) image, parallel to the wall:
    albedo premultiplied by coverage, coverage, and the depth (m) it is defocused at."""
    albedo: np.ndarray     # float32 (H, W)
    alpha: np.ndarray      # float32 (H, W)
    depth: float


@dataclass(frozen=True)
class IdealCanvas:
    """Undistorted pinhole canvas: ideal pixel = K * (x/z, y/z) + offset."""
    width: int
    height: int
    offset: tuple[int, int]
    map_x: np.ndarray      # float32 (H, W): for each output pixel, ideal-canvas x
    map_y: np.ndarray


@lru_cache(maxsize=4)
def _ideal_canvas(camera_key: tuple) -> IdealCanvas:
    camera = _CAMERAS[camera_key]
    w, h = camera.width, camera.height
    u, v = np.meshgrid(np.arange(w, dtype=np.float64), np.arange(h, dtype=np.float64))
    xy = camera.undistort_pixels(np.stack([u.ravel(), v.ravel()], 1))
    ideal = camera.normalized_to_pixels(xy, distort=False)
    margin = 8
    ox = int(np.ceil(max(0.0, -ideal[:, 0].min()))) + margin
    oy = int(np.ceil(max(0.0, -ideal[:, 1].min()))) + margin
    W = int(np.ceil(ideal[:, 0].max())) + ox + margin
    H = int(np.ceil(ideal[:, 1].max())) + oy + margin
    mx = (ideal[:, 0] + ox).reshape(h, w).astype(np.float32)
    my = (ideal[:, 1] + oy).reshape(h, w).astype(np.float32)
    return IdealCanvas(W, H, (ox, oy), mx, my)


_CAMERAS: dict[tuple, CameraModel] = {}


def ideal_canvas(camera: CameraModel) -> IdealCanvas:
    key = (camera.width, camera.height, tuple(camera.K.ravel()), tuple(camera.dist))
    _CAMERAS[key] = camera
    return _ideal_canvas(key)


def transform(T: np.ndarray, p: np.ndarray) -> np.ndarray:
    return p @ T[:3, :3].T + T[:3, 3]


def circle_points(centre: np.ndarray, radius: float, n: int = CIRCLE_SEGMENTS) -> np.ndarray:
    """Boundary of a circle in a z = const plane of the marker frame."""
    t = np.linspace(0, 2 * np.pi, n, endpoint=False)
    return np.column_stack([centre[0] + radius * np.cos(t), centre[1] + radius * np.sin(t),
                            np.full(n, centre[2])])


def box_faces(lo: np.ndarray, hi: np.ndarray) -> list[tuple[np.ndarray, np.ndarray]]:
    """Six (4x3 vertices, outward normal) faces of an axis-aligned box in the marker frame."""
    x0, y0, z0 = lo
    x1, y1, z1 = hi
    c = np.array([[x0, y0, z0], [x1, y0, z0], [x1, y1, z0], [x0, y1, z0],
                  [x0, y0, z1], [x1, y0, z1], [x1, y1, z1], [x0, y1, z1]])
    idx = [([4, 5, 6, 7], (0, 0, 1)), ([0, 3, 2, 1], (0, 0, -1)), ([0, 1, 5, 4], (0, -1, 0)),
           ([2, 3, 7, 6], (0, 1, 0)), ([1, 2, 6, 5], (1, 0, 0)), ([3, 0, 4, 7], (-1, 0, 0))]
    return [(c[i], np.array(n, float)) for i, n in idx]


class Renderer:
    def __init__(self, camera: CameraModel, optics: Optics):
        self.camera = camera
        self.optics = optics
        self.canvas = ideal_canvas(camera)
        self._lighting_cache: dict = {}

    # ------------------------------------------------------------------ geometry helpers
    def _ideal(self, p_cam: np.ndarray) -> np.ndarray:
        """Camera-frame points -> ideal-canvas pixel coordinates."""
        uv = self.camera.project(p_cam, distort=False)
        return uv + np.asarray(self.canvas.offset, float)

    def coc_sigma_px(self, depth: float) -> float:
        """Gaussian sigma (px) of defocus (thin lens) + diffraction for an object at depth m."""
        o, f = self.optics, self.optics.focal_length
        aperture = f / o.f_number
        c = aperture * f / (o.focus_distance - f) * abs(depth - o.focus_distance) / max(depth, 1e-3)
        sigma_defocus = c / self.camera.pixel_size / 4.0
        sigma_airy = 0.42 * o.wavelength * o.f_number / self.camera.pixel_size
        return float(np.hypot(sigma_defocus, sigma_airy))

    # ------------------------------------------------------------------ layers
    def _foreground(self, scene: Scene, cam_T_m: np.ndarray):
        """Supersampled foreground (albedo*shade premultiplied, alpha) on the ideal canvas."""
        m = scene.marker
        light = np.asarray(scene.lighting.sun, float)
        light /= np.linalg.norm(light)
        cam_pos_m = -cam_T_m[:3, :3].T @ cam_T_m[:3, 3]          # camera centre in marker frame

        def shade(n: np.ndarray) -> float:
            return scene.lighting.ambient + (1 - scene.lighting.ambient) * max(0.0, float(n @ light))

        items: list[tuple[np.ndarray, float]] = []                # (marker-frame polygon, value)

        def add_box(lo, hi, albedo):
            for verts, n in box_faces(np.asarray(lo), np.asarray(hi)):
                if (verts.mean(0) - cam_pos_m) @ n < 0:            # front-facing
                    items.append((verts, albedo * shade(n)))

        if scene.oru is not None:
            # seated ORU (scene frame: bottom face centre, z up) and its adapter on top; only
            # faces turned to the camera are drawn (the slot walls hide the sides in reality,
            # the background wall stands in for the store around it)
            R, c = m.marker_T_oru[:3, :3], m.marker_T_oru[:3, 3]
            size, adapter = np.asarray(scene.oru.size), np.asarray(scene.oru.adapter)
            boxes = [(np.array([-size[0] / 2, -size[1] / 2, 0.0]), np.array([size[0] / 2, size[1] / 2, size[2]])),
                     (np.array([-adapter[0] / 2, -adapter[1] / 2, size[2]]),
                      np.array([adapter[0] / 2, adapter[1] / 2, size[2] + adapter[2]]))]
            for lo, hi in boxes:
                for verts, n in box_faces(lo, hi):
                    verts_m = verts @ R.T + c
                    n_m = R @ n
                    if (verts_m.mean(0) - cam_pos_m) @ n_m < 0:
                        items.append((verts_m, m.oru_albedo * shade(n_m)))
        up = np.array([0.0, 0.0, 1.0])
        px, py = m.plate_size[0] / 2, m.plate_size[1] / 2
        add_box((-px, -py, -m.plate_thickness), (px, py, 0.0), m.plate_albedo)
        front = cam_pos_m[2] > 0
        rod = m.points[m.rod_index]
        for p in m.points[:3]:
            if front:
                items.append((circle_points(p, m.circle_radius), m.circle_albedo * shade(up)))
        # rod: silhouette = convex hull of the projected end discs (exact for a cylinder)
        rod_base = np.array([rod[0], rod[1], 0.0])
        hull_pts = np.vstack([circle_points(rod_base, m.rod_radius, 64), circle_points(rod, m.rod_radius, 64)])
        items.append((hull_pts, -m.plate_albedo * shade(np.array([1.0, 0, 0]))))  # negative: hull
        if cam_pos_m[2] > rod[2]:
            items.append((circle_points(rod, m.rod_radius, 64), m.plate_albedo * shade(up)))
            items.append((circle_points(rod, m.circle_radius), m.circle_albedo * shade(up)))

        projected = []
        for verts, value in items:
            pc = transform(cam_T_m, verts)
            if (pc[:, 2] < NEAR).any():
                continue
            uv = self._ideal(pc)
            if value < 0:
                uv = cv2.convexHull(uv.astype(np.float32)).reshape(-1, 2).astype(np.float64)
                value = -value
            projected.append((uv, value))
        if not projected:
            return None
        allpts = np.vstack([uv for uv, _ in projected])
        W, H = self.canvas.width, self.canvas.height
        x0 = int(np.clip(np.floor(allpts[:, 0].min()) - 2, 0, W))
        y0 = int(np.clip(np.floor(allpts[:, 1].min()) - 2, 0, H))
        x1 = int(np.clip(np.ceil(allpts[:, 0].max()) + 3, 0, W))
        y1 = int(np.clip(np.ceil(allpts[:, 1].max()) + 3, 0, H))
        if x1 <= x0 or y1 <= y0:
            return None
        # 16-bit so that the 4x4 box average keeps sub-1/255 edge coverage
        albedo = np.zeros(((y1 - y0) * SS, (x1 - x0) * SS), np.uint16)
        alpha = np.zeros_like(albedo)
        for uv, value in projected:
            # ideal px u -> supersampled (u + 0.5) * SS - 0.5, relative to the box
            pts = ((uv - (x0, y0) + 0.5) * SS - 0.5) * ONE
            pts = np.round(pts).astype(np.int32).reshape(-1, 1, 2)
            cv2.fillPoly(albedo, [pts], int(round(min(value, 1.0) * 65535)), cv2.LINE_8, SHIFT)
            cv2.fillPoly(alpha, [pts], 65535, cv2.LINE_8, SHIFT)
        size = (x1 - x0, y1 - y0)
        fg = cv2.resize(albedo, size, interpolation=cv2.INTER_AREA).astype(np.float32) / 65535.0
        al = cv2.resize(alpha, size, interpolation=cv2.INTER_AREA).astype(np.float32) / 65535.0
        return fg, al, (x0, y0)

    def _background(self, scene: Scene, cam_T_m: np.ndarray) -> np.ndarray:
        W, H = self.canvas.width, self.canvas.height
        img = np.full((H, W), int(scene.wall_albedo * 255 * self._wall_shade(scene)), np.uint8)
        s = self._wall_shade(scene)
        for poly in scene.clutter:
            pc = transform(cam_T_m, poly.vertices)
            if (pc[:, 2] < NEAR).any():
                continue
            uv = self._ideal(pc)
            if uv[:, 0].max() < 0 or uv[:, 1].max() < 0 or uv[:, 0].min() > W or uv[:, 1].min() > H:
                continue
            pts = np.round((uv) * 16).astype(np.int32).reshape(-1, 1, 2)
            cv2.fillPoly(img, [pts], int(poly.albedo * 255 * s), cv2.LINE_AA, 4)
        return img.astype(np.float32) / 255.0

    @staticmethod
    def _wall_axis_depth(scene: Scene, cam_T_m: np.ndarray) -> float:
        """Distance along the optical axis to the wall (the depth the wall layer is blurred at)."""
        R, t = cam_T_m[:3, :3], cam_T_m[:3, 3]
        c = -R.T @ t
        d = R.T @ np.array([0.0, 0.0, 1.0])
        if d[2] < -1e-6:
            hit = (-scene.wall_depth - c[2]) / d[2]
            if hit > 0:
                return float(hit)
        return float(t[2] + scene.wall_depth)

    @staticmethod
    def _wall_shade(scene: Scene) -> float:
        sun = np.asarray(scene.lighting.sun, float)
        sun /= np.linalg.norm(sun)
        return scene.lighting.ambient + (1 - scene.lighting.ambient) * max(0.0, sun[2])

    def _illumination(self, scene: Scene) -> np.ndarray:
        key = id(scene.lighting)
        cached = self._lighting_cache.get(key)
        if cached is not None:
            return cached
        L = scene.lighting
        w, h = self.camera.width, self.camera.height
        u = (np.arange(w, dtype=np.float32) / w)[None, :]
        v = (np.arange(h, dtype=np.float32) / w)[:, None]
        field = 1 + L.gradient * ((u - 0.5) * np.cos(L.direction) + (v - 0.5 * h / w) * np.sin(L.direction))
        d2 = (u - L.spot_centre[0]) ** 2 + (v - L.spot_centre[1] * h / w) ** 2
        field = field * (1 + L.spot_gain * np.exp(-d2 / (2 * L.spot_sigma ** 2)))
        cx, cy = self.camera.K[0, 2], self.camera.K[1, 2]
        uu = np.arange(w, dtype=np.float32)[None, :] - cx
        vv = np.arange(h, dtype=np.float32)[:, None] - cy
        r2 = (uu ** 2 + vv ** 2) / ((w / 2) ** 2 + (h / 2) ** 2)
        field = field * (1 - self.optics.vignetting * r2)
        field = (L.level * field / field.max()).astype(np.float32)
        self._lighting_cache = {key: field}
        return field

    def _marker_near_view(self, cam_T_m: np.ndarray) -> bool:
        """Skip the (supersampled) foreground when the marker is far outside the field of view
        or behind the camera: a grazing marker would cover the whole 4x canvas for nothing."""
        p = cam_T_m[:3, 3]
        if not (0.03 < p[2] < 5.0):
            return False
        half_w = (self.camera.width / 2) / self.camera.K[0, 0]
        half_h = (self.camera.height / 2) / self.camera.K[1, 1]
        margin = 0.15 / p[2]                       # the ORU/marker extent around the origin
        return abs(p[0] / p[2]) < half_w + margin and abs(p[1] / p[2]) < half_h + margin

    # ------------------------------------------------------------------ public
    def render(self, scene: Scene, camera_T_marker: np.ndarray,
               flat_layers: Sequence[FlatLayer] = ()) -> np.ndarray:
        """Relative irradiance image (H, W) float32 in [0, 1] for the given true pose.
        `flat_layers` (e.g. a calibration board) lie in front of the wall and behind the
        marker/ORU; none (the default) renders the marker scene exactly as before."""
        cv = self.canvas
        bg = self._background(scene, camera_T_marker)
        fg_ideal = np.zeros((cv.height, cv.width), np.float32)
        al_ideal = np.zeros_like(fg_ideal)
        layer = self._foreground(scene, camera_T_marker) if self._marker_near_view(camera_T_marker) else None
        if layer is not None:
            fg, al, (x0, y0) = layer
            fg_ideal[y0:y0 + fg.shape[0], x0:x0 + fg.shape[1]] = fg
            al_ideal[y0:y0 + al.shape[0], x0:x0 + al.shape[1]] = al
        remap = lambda img: cv2.remap(img, cv.map_x, cv.map_y, cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)
        bg_d, fg_d, al_d = remap(bg), remap(fg_ideal), remap(al_ideal)
        marker_depth = float(camera_T_marker[2, 3])
        wall_depth = self._wall_axis_depth(scene, camera_T_marker)
        # Depths behind the camera or at grazing incidence give absurd blur circles (and a
        # Gaussian kernel of thousands of px takes minutes): beyond MAX_BLUR px the layer is a
        # smear anyway.
        sb = min(self.coc_sigma_px(max(wall_depth, 0.01)), MAX_BLUR)
        sf = min(self.coc_sigma_px(max(marker_depth, 0.01)), MAX_BLUR)
        bg_d = cv2.GaussianBlur(bg_d, (0, 0), sb)
        for flat in flat_layers:
            sl = min(self.coc_sigma_px(max(flat.depth, 0.01)), MAX_BLUR)
            shaded = flat.albedo * self._wall_shade(scene)     # parallel to the wall: lit alike
            bg_d = cv2.GaussianBlur(shaded, (0, 0), sl) + (1.0 - cv2.GaussianBlur(flat.alpha, (0, 0), sl)) * bg_d
        if layer is not None:
            fg_d = cv2.GaussianBlur(fg_d, (0, 0), sf)
            al_d = cv2.GaussianBlur(al_d, (0, 0), sf)
        img = fg_d + (1.0 - al_d) * bg_d
        return img * self._illumination(scene)
