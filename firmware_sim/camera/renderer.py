"""Render the clean irradiance image the camera sees (before sensor noise).

Method (why: geometry must be far more accurate than the vision targets):
1. Everything is projected with an ideal pinhole into an undistorted "ideal" canvas that is
   large enough to cover the distorted field of view.
2. The foreground (ORU, marker plate, circles, rod) is drawn with cv2.fillPoly with 8
   sub-pixel bits, only inside its bounding box; the circles and the rod at 4x supersampling,
   box-averaged (INTER_AREA = pixel integration). Circles are 128-gons of the exact projected 3-D circle,
   so the projected-centre (ellipse) bias of real optics is reproduced.
   The background wall is drawn at 1x with anti-aliased edges (its geometry's accuracy does not
   matter; its dots' contrast does: they are the detector's distractors).
3. Lens distortion: every outline is distorted itself (each vertex through the forward
   Brown-Conrady model of the controller's camera file, polygons cut to the ideal canvas first)
   and drawn straight into the output pixels; the foreground's edges are split into short
   pieces first so that they bend as real straight edges do (the wall's are not: they bend by
   well under a pixel over a wall polygon at this lens's distortion).
4. Defocus: thin-lens circle of confusion per depth layer (marker/ORU layer at the marker
   depth, wall layer at the wall depth) as a Gaussian of the disc's second moment (sigma =
   c/4) combined with the Airy diffraction blur; layers are composited with premultiplied
   alpha after blurring (the marker layer only over the pixels its blur reaches), so edges
   between depths blur like a real lens would (approximately).
5. Uneven lighting: Lambert shading per face, then a smooth image-space field (gradient + hot
   spot) and vignetting.

Cost (why: the render competes with the nodes and the daemon for a 2-core machine; 70 ms a frame
two versions ago, 30-50 ms of process CPU before this one): the wall's polygons are projected in
one call, only those in view drawn, and no full-frame remap is done (it cost more than the rest
of a frame); a blur of more than HALF_RES_SIGMA px (the wall always, the foreground away from
the focus) is done at half resolution (2x2 box down, Gaussian, bilinear up: symmetric and
aligned, so no edge or centre moves); the circles and the rod are supersampled each in its own
small box laid over the rest (ORU faces, plate), which drops to 2x supersampling when large and
to none when it fills the frame out of focus; supersampled planes are drawn and box-averaged one
16-bit channel at a time in 2x steps (OpenCV's fast path); the lighting is applied in the
wall's one float conversion; the illumination field is cached and an unchanged pose gives the
last image again. Since: the sensor's electrons-per-unit field rides in the lighting's pass
(render(gain=...)), the foreground is transparency planes composited in place, drawn straight
at half resolution when its blur halves it, a flat layer (the board) is blurred only over its
box, and the measured shapes' small groups share one supersampled box. Since (30-50% less): the
layers are composited a band of 128 rows at a time (the wall's and the foreground's upsampling,
a sharp foreground's and a flat layer's blur, the lighting), so that each band's planes stay in
the cache (the full-frame passes were memory-bound); a halved foreground is laid on the halved
wall and the sum upsampled once; the sensor's noise goes band by band as well; a flat layer is
a patch over the pixels it covers. Since (issue 32, same pixels): each band is exposed (the
sensor's noise and ADC) as soon as it is composited, so no full-frame electrons image is
written and read again; where an opaque layer (a board's inside, a sharp foreground's plate)
covers a band's columns in every row its blur reaches, it is written straight there: its
coverage is neither blurred nor multiplied there; the marker's polygons are made and lit once
per marker (only the culling is per pose). Since (issue 32, the board frame ~13% less CPU,
old and new alternating in one process): a flat layer is one uint8 label a pixel (a board's
coverage was 0 or 1 anyway), its albedo blurred by one separable filter on the labels (the
only change of pixels: float rounding, <= 1 DN in a few px of a board frame); the wall is
upsampled into one reused band buffer and not under an opaque board inside that spans the band
(with the buffer reused, the band stays in the cache for the board's writes).
bench/bench_realtime.py render prints the CPU per frame.
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

SS = 4            # supersampling factor of the foreground (a power of 2)
SHIFT = 8         # fractional bits for cv2 drawing
ONE = 1 << SHIFT
NEAR = 1e-3       # m, polygons with a vertex nearer than this are not drawn
CIRCLE_SEGMENTS = 128
MAX_BLUR = 20.0   # px, largest Gaussian sigma of a defocused layer
BODY_BUDGET = 1_000_000  # supersampled px of the body's box above which it is drawn at 2x (or 1x)
SS_BIG_BOX = 150 * 150   # px: a measured shape's box above this is supersampled 2x, not SS
BODY_HUGE_BOX = 500_000  # px: a body box this large and defocused by BODY_SHARP_SIGMA px or more
BODY_SHARP_SIGMA = 1.0   # is drawn without supersampling
HALF_RES_SIGMA = 1.05  # px: blurs from this sigma on may be done at half resolution (_blur)
EDGE_PX = 12.0    # ideal px: longest straight piece of a foreground outline before distortion
BAND_ROWS = 128   # rows per band of the compositing passes (the band's planes stay in the cache)


@dataclass(frozen=True)
class FlatLayer:
    """A flat object drawn straight into the output (distorted) image, parallel to the wall,
    with no partial coverage (a board: calibration_board.board_patch): a uint8 label per pixel
    and each label's albedo (label 0 covers nothing, every other one covers its pixel), and the
    depth (m) it is defocused at; the labels cover the image from `origin` (x, y) on (a patch
    inside the image; nothing around it), with `margin` px of label 0 inside the patch on every
    side not at the image's edge (Renderer.flat_margin(depth) of them: laid as it is, else
    grown first). Why labels, not albedo and coverage planes: one byte a pixel to draw and to
    read, not eight (the planes were ~2 ms of a board frame)."""
    labels: np.ndarray     # uint8 (h, w)
    levels: np.ndarray     # float32 (n,): albedo of label k
    depth: float
    origin: tuple[int, int] = (0, 0)
    margin: int = 0


@dataclass(frozen=True)
class IdealCanvas:
    """Undistorted pinhole canvas: ideal pixel = K * (x/z, y/z) + offset; it covers the ideal
    image of every output pixel (outlines are cut to it before they are distorted)."""
    width: int
    height: int
    offset: tuple[int, int]


@lru_cache(maxsize=4)
def _ideal_canvas(camera_key: tuple) -> IdealCanvas:
    camera = _CAMERAS[camera_key]
    w, h = camera.width, camera.height
    # the output's border is enough: the distortion maps the image's inside to the inside of
    # its border's image (it is one to one over the field of view)
    u, v = np.arange(w, dtype=np.float64), np.arange(h, dtype=np.float64)
    border = np.vstack([np.c_[u, np.zeros(w)], np.c_[u, np.full(w, h - 1.0)],
                        np.c_[np.zeros(h), v], np.c_[np.full(h, w - 1.0), v]])
    ideal = camera.normalized_to_pixels(camera.undistort_pixels(border), distort=False)
    margin = 8
    ox = int(np.ceil(max(0.0, -ideal[:, 0].min()))) + margin
    oy = int(np.ceil(max(0.0, -ideal[:, 1].min()))) + margin
    W = int(np.ceil(ideal[:, 0].max())) + ox + margin
    H = int(np.ceil(ideal[:, 1].max())) + oy + margin
    return IdealCanvas(W, H, (ox, oy))


_CAMERAS: dict[tuple, CameraModel] = {}


def ideal_canvas(camera: CameraModel) -> IdealCanvas:
    key = (camera.width, camera.height, tuple(camera.K.ravel()), tuple(camera.dist))
    _CAMERAS[key] = camera
    return _ideal_canvas(key)


def transform(T: np.ndarray, p: np.ndarray) -> np.ndarray:
    return p @ T[:3, :3].T + T[:3, 3]


@lru_cache(maxsize=8)
def _unit_circle(n: int) -> np.ndarray:
    t = np.linspace(0, 2 * np.pi, n, endpoint=False)
    return np.column_stack([np.cos(t), np.sin(t), np.zeros(n)])


def circle_points(centre: np.ndarray, radius: float, n: int = CIRCLE_SEGMENTS) -> np.ndarray:
    """Boundary of a circle in a z = const plane of the marker frame."""
    return _unit_circle(n) * (radius, radius, 0.0) + centre


def _blur(image: np.ndarray, sigma: float, may_halve: bool = False) -> np.ndarray:
    """Gaussian blur; below 0.1 px a no-op. `may_halve`: from HALF_RES_SIGMA px on (an image of
    even size) it blurs at half resolution, a quarter of the work: 2x2 box down (variance 1/3 px^2), Gaussian,
    bilinear 2x up (variance 2/3 px^2 averaged over the phases); the middle Gaussian makes the
    total variance sigma^2. Symmetric and aligned (pixel centres map to pixel centres), so it
    moves no edge or centroid; its kernel is a little less Gaussian than the direct blur's."""
    if sigma < 0.1:
        return image
    h, w = image.shape[:2]
    if not may_halve or not _may_halve(sigma, (w, h)):
        return cv2.GaussianBlur(image, (0, 0), sigma)
    return _blur_halved(cv2.resize(image, (w // 2, h // 2), interpolation=cv2.INTER_AREA), sigma)


def _may_halve(sigma: float, size: tuple[int, int]) -> bool:
    """Whether _blur blurs an image of `size` (w, h) by `sigma` px at half resolution."""
    return sigma >= HALF_RES_SIGMA and size[0] % 2 == 0 and size[1] % 2 == 0 and min(size) >= 32


def _blur_halved(small: np.ndarray, sigma: float) -> np.ndarray:
    """The rest of _blur's half-resolution blur from the 2x2 box average `small` on."""
    return _twice(_blur_small(small, sigma))


def _blur_small(small: np.ndarray, sigma: float) -> np.ndarray:
    """_blur's middle Gaussian on the 2x2 box average `small` (still at half resolution)."""
    return cv2.GaussianBlur(small, (0, 0), np.sqrt(sigma * sigma - 1.0) / 2.0)


def _twice(small: np.ndarray) -> np.ndarray:
    """_blur's last step: bilinear 2x up."""
    return cv2.resize(small, (small.shape[1] * 2, small.shape[0] * 2), interpolation=cv2.INTER_LINEAR)


def _twice_rows(small: np.ndarray, y0: int, y1: int, into: np.ndarray | None = None) -> np.ndarray:
    """Rows y0:y1 (even y0) of _twice(small), from the rows of `small` they reach: bilinear 2x up
    weighs the two source rows nearest to each output row with weights set by its position
    alone, so a band cut out of the source with a row to spare on each side gives the same
    pixels as the whole image's upsampling. `into`: a buffer of at least y1 - y0 + 6 rows to
    write them in (one reused band after band stays in the cache)."""
    a, b = max(y0 // 2 - 1, 0), min((y1 + 1) // 2 + 1, small.shape[0])
    size = (small.shape[1] * 2, (b - a) * 2)
    band = cv2.resize(small[a:b], size, dst=None if into is None else into[:size[1]], interpolation=cv2.INTER_LINEAR)
    return band[y0 - 2 * a:y1 - 2 * a]


def _twice_rows_beside(small: np.ndarray, y0: int, y1: int, into: np.ndarray, hidden: tuple[int, int]) -> np.ndarray:
    """_twice_rows(small, y0, y1, into) but for its columns hidden[0]:hidden[1] (even bounds, 2 px
    or more from the image's edges unless at them), which are left as `into` held them (what
    lies there is covered), all but their outer pixels: the columns beside them
    are upsampled from the source columns they reach with one to spare (as the rows), so they
    are the whole image's pixels."""
    a, b = max(y0 // 2 - 1, 0), min((y1 + 1) // 2 + 1, small.shape[0])
    rows, (xa, xb) = (b - a) * 2, hidden
    # each side written straight into `into` with its spare column's 2 px (inside the hidden span)
    if xa > 0:
        left = small[a:b, :xa // 2 + 1]
        cv2.resize(left, (left.shape[1] * 2, rows), dst=into[:rows, :left.shape[1] * 2], interpolation=cv2.INTER_LINEAR)
    if xb < small.shape[1] * 2:
        right = small[a:b, xb // 2 - 1:]
        cv2.resize(right, (right.shape[1] * 2, rows), dst=into[:rows, xb - 2:], interpolation=cv2.INTER_LINEAR)
    return into[y0 - 2 * a:y1 - 2 * a]


def _blur_rows(image: np.ndarray, y0: int, y1: int, sigma: float, into: np.ndarray | None = None) -> np.ndarray:
    """Rows y0:y1 of _blur(image, sigma) (no halving), from the rows the kernel reaches: OpenCV's
    float kernel reaches round(8 sigma + 1) // 2 rows, so a band cut with that many to spare on
    each side (the image's own border where it has none) gives the whole image's pixels. `into`:
    a buffer at least as wide as `image` and y1 - y0 + 2 (ceil(4 sigma) + 1) rows to write in."""
    if sigma < 0.1:
        return image[y0:y1]
    reach = int(np.ceil(4 * sigma)) + 1
    a, b = max(y0 - reach, 0), min(y1 + reach, image.shape[0])
    dst = None if into is None else into[:b - a, :image.shape[1]]
    return cv2.GaussianBlur(image[a:b], (0, 0), sigma, dst=dst)[y0 - a:y1 - a]


def _inside(opaque: np.ndarray, reach: int) -> tuple[int, int] | None:
    """(c0, c1): the columns a blur reaching `reach` px keeps opaque, given which columns of a
    block are opaque in every row it reaches (one run of them; else, or too few, None)."""
    run = np.flatnonzero(opaque)
    if len(run) == 0 or run[-1] - run[0] + 1 != len(run) or len(run) <= 4 * reach:
        return None
    return int(run[0]) + reach, int(run[-1]) + 1 - reach


def _scale_of(levels: np.ndarray) -> np.float32 | None:
    """The step s when a flat layer's albedo table is label * s (float32, as NumPy multiplies a
    uint8 label by it), else None. With a step its albedo is blurred straight from the labels,
    the step in the filter's kernel (half the float work of a looked-up plane and its blur;
    the sums' rounding differs, by a float's last bit); else looked up, then blurred."""
    levels = np.asarray(levels, np.float32)
    if len(levels) < 2 or levels[1] <= 0:
        return None
    step = levels[1]
    return step if np.array_equal(levels, np.arange(len(levels), dtype=np.float32) * step) else None


def _split_edges(polys: list[np.ndarray], longest: float) -> tuple[np.ndarray, np.ndarray]:
    """The closed polygons with every edge cut into pieces no longer than `longest`: all their
    vertices in one array and each polygon's vertex count (one NumPy pass for all of them:
    per polygon, the calls' overhead was most of the time)."""
    sizes = np.array([len(p) for p in polys])
    poly = np.vstack(polys)
    ends = np.cumsum(sizes)
    nxt_index = np.arange(len(poly)) + 1
    nxt_index[ends - 1] = ends - sizes                           # each polygon's last vertex -> its first
    nxt = poly[nxt_index]
    pieces = np.maximum(np.ceil(np.hypot(*(nxt - poly).T) / longest), 1).astype(int)
    if (pieces == 1).all():
        return poly, sizes
    first = np.repeat(np.cumsum(pieces) - pieces, pieces)       # each piece's edge's first piece
    t = (np.arange(pieces.sum()) - first) / np.repeat(pieces, pieces)
    start = np.repeat(poly, pieces, axis=0)
    owner = np.repeat(np.arange(len(polys)), sizes)
    return start + (np.repeat(nxt, pieces, axis=0) - start) * t[:, None], np.bincount(owner, pieces, len(polys)).astype(int)


def _supersampled(polys, origin: tuple[int, int], size: tuple[int, int], ss: int,
                  down: int = 1) -> tuple[np.ndarray, np.ndarray]:
    """(albedo premultiplied, transparency = 1 - coverage) float32 planes of `size` (w, h) px
    from `origin` of polygons in output pixels drawn in order at ss x ss supersampling (16 bit,
    so that the box average keeps sub-1/255 edge coverage) and box-averaged (pixel
    integration). Each plane is drawn and averaged alone: OpenCV's INTER_AREA is ~10x faster
    on one channel than on two. Transparency, not coverage: compositing multiplies by it
    (no 1 - coverage pass), and blurring it is blurring the coverage (the kernel sums to 1).
    `down` 2: the planes are box-averaged once more, to half resolution ((h/2, w/2), `size`
    even), in the 16-bit steps: what _blur would do first to them, for a quarter of the float work."""
    w, h = size
    allpts = np.round(((np.vstack([uv for uv, _ in polys]) - origin + 0.5) * ss - 0.5) * ONE).astype(np.int32)
    outlines = np.split(allpts.reshape(-1, 1, 2), np.cumsum([len(uv) for uv, _ in polys[:-1]]))
    planes = []
    if ss == 1 and down == 1:       # nothing to average: drawn straight into the float planes
        for levels, clear in (([min(value, 1.0) for _, value in polys], 0.0), ([0.0] * len(polys), 1.0)):
            buf = np.zeros((h, w), np.float32) if clear == 0.0 else np.ones((h, w), np.float32)
            for pts, level in zip(outlines, levels):
                cv2.fillPoly(buf, [pts], level, cv2.LINE_8, SHIFT)
            planes.append(buf)
        return planes[0], planes[1]
    # one 2x2 average (the body's usual case) keeps quarter coverages exact in 8 bits, for half
    # the memory traffic of 16 (its levels then move by < 1/510)
    dtype, full = (np.uint8, 255) if ss * down == 2 else (np.uint16, 65535)
    for levels, clear in (([int(round(min(value, 1.0) * full)) for _, value in polys], 0), ([0] * len(polys), full)):
        buf = np.zeros((h * ss, w * ss), dtype) if clear == 0 else np.full((h * ss, w * ss), clear, dtype)
        for pts, level in zip(outlines, levels):
            cv2.fillPoly(buf, [pts], level, cv2.LINE_8, SHIFT)
        for _ in range(int(np.log2(ss * down))):      # 2x steps: OpenCV's 2x box average is 4x faster than its 4x
            buf = cv2.resize(buf, (buf.shape[1] // 2, buf.shape[0] // 2), interpolation=cv2.INTER_AREA)
        planes.append(np.multiply(buf, np.float32(1.0 / full), dtype=np.float32))
    return planes[0], planes[1]


def _pixel_box(points: np.ndarray, margin: int, size: tuple[int, int]) -> tuple[int, int, int, int]:
    """(x0, y0, x1, y1): the pixels `points` (N, 2) touch grown by `margin` px (and one more
    on the far side), within an image of `size` (w, h)."""
    (lx, ly), (hx, hy) = np.floor(points.min(0)).tolist(), np.ceil(points.max(0)).tolist()
    w, h = size
    return (int(min(max(lx - margin, 0), w)), int(min(max(ly - margin, 0), h)),
            int(min(max(hx + margin + 1, 0), w)), int(min(max(hy + margin + 1, 0), h)))


def _merged(groups: list[list]) -> list[list]:
    """The measured shapes' groups, neighbours joined while their joint box stays within
    SS_BIG_BOX (so they keep SS x SS supersampling): far away the four small boxes cost more
    in per-call overhead than their pixels. Joining changes nothing drawn: the shapes do not
    overlap one another, so one layer over the body is each laid over it in turn."""
    out: list[list] = []
    box = None
    for group in groups:
        pts = np.vstack([uv for uv, _ in group])
        lo, hi = pts.min(0) - 3, pts.max(0) + 3
        if box is not None:
            jlo, jhi = np.minimum(box[0], lo), np.maximum(box[1], hi)
            if np.prod(jhi - jlo) <= SS_BIG_BOX:
                out[-1] = out[-1] + group
                box = (jlo, jhi)
                continue
        out.append(list(group))
        box = (lo, hi)
    return out


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
        self._clutter_cache: dict = {}
        self._marker_cache: tuple | None = None   # ((marker, ORU, lighting), their polygons)
        self._last: tuple | None = None      # (pose and scene key, image) of the last render

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
    def _foreground(self, scene: Scene, cam_T_m: np.ndarray, sigma: float):
        """Foreground in output pixels: (albedo*shade premultiplied, transparency) planes of the box
        it covers grown by the reach of its blur (`sigma` px), and the box's top-left pixel."""
        reach = int(np.ceil(4 * sigma))
        faces, circles, (rod_top, hull, rod_end) = self._marker_parts(scene)
        cam_pos_m = -cam_T_m[:3, :3].T @ cam_T_m[:3, 3]          # camera centre in marker frame
        # only faces turned to the camera are drawn (any vertex of a face tells)
        items = [(verts, value) for verts, n, value in faces if (verts[0] - cam_pos_m) @ n < 0]
        details = [[circle] for circle in circles] if cam_pos_m[2] > 0 else []   # the measured shapes, each group alone
        details.append([hull, *rod_end] if cam_pos_m[2] > rod_top else [hull])
        body, *groups = self._project([items, *details], cam_T_m)
        groups = [g for g in groups if g]
        if not body and not groups:
            return None
        allpts = np.vstack([uv for group in [body, *groups] for uv, _ in group])
        w, h = self.camera.width, self.camera.height
        x0, y0, x1, y1 = _pixel_box(allpts, reach + 2, (w, h))
        # on even pixels, so that the blur may halve it and a halved box lies on the halved
        # wall's pixels (_composite lays them together at half resolution)
        x0, y0, x1, y1 = x0 - x0 % 2, y0 - y0 % 2, x1 + x1 % 2, y1 + y1 % 2
        x1, y1 = x1 - 2 * (x1 > w), y1 - 2 * (y1 > h)
        if x1 <= x0 or y1 <= y0:
            return None
        # The body (ORU faces, plate): supersampled SS x SS while its box is small (far away: the
        # circles are then a few px from the plate's edge), 2x when large (nearer: tens of px),
        # and not at all when it fills most of the frame out of focus (nearest: its edges are
        # then over 50 px from the circles and their steps are smoothed by a blur of more than
        # a pixel; the measured shapes keep their own supersampling).
        area = (y1 - y0) * (x1 - x0)
        if area * SS * SS <= BODY_BUDGET:
            ss = SS
        else:
            ss = 1 if area >= BODY_HUGE_BOX and sigma >= BODY_SHARP_SIGMA else 2
        # blurred at half resolution anyway (_blur): drawn and laid over straight at it
        down = 2 if _may_halve(sigma, (x1 - x0, y1 - y0)) else 1
        # halved, SS x SS of the body is 2 SS x 2 SS of the half-resolution pixel it is averaged
        # to: 2 x 2 (4 x 4 there) keeps its edges' coverage to 1/16 for a quarter of the pixels
        ss = min(ss, 2) if down == 2 else ss
        albedo, clear = _supersampled(body, (x0, y0), (x1 - x0, y1 - y0), ss, down)
        for group in _merged(groups):      # the circles and the rod: supersampled, laid over the body
            self._lay_over(albedo, clear, group, (x0, y0), down)
        return albedo, clear, (x0, y0), down

    def _marker_parts(self, scene: Scene):
        """The foreground's polygons in the marker frame, lit (they do not move in it: made once
        per marker, ORU and lighting): the body's faces (vertices, outward normal, value), the
        circles (vertices, value) and the rod (its top's height, its silhouette's end discs
        (vertices, negative value: their convex hull), its top (disc, circle))."""
        key = (scene.marker, scene.oru, scene.lighting)
        cached = self._marker_cache
        if cached is not None and all(a is b for a, b in zip(cached[0], key)):
            return cached[1]
        m = scene.marker
        light = np.asarray(scene.lighting.sun, float)
        light /= np.linalg.norm(light)

        def shade(n: np.ndarray) -> float:
            return scene.lighting.ambient + (1 - scene.lighting.ambient) * max(0.0, float(n @ light))

        faces: list[tuple[np.ndarray, np.ndarray, float]] = []
        if scene.oru is not None:
            # seated ORU (scene frame: bottom face centre, z up) and its adapter on top (the
            # slot walls hide the sides in reality, the background wall stands in for the store
            # around it)
            R, c = m.marker_T_oru[:3, :3], m.marker_T_oru[:3, 3]
            size, adapter = np.asarray(scene.oru.size), np.asarray(scene.oru.adapter)
            boxes = [(np.array([-size[0] / 2, -size[1] / 2, 0.0]), np.array([size[0] / 2, size[1] / 2, size[2]])),
                     (np.array([-adapter[0] / 2, -adapter[1] / 2, size[2]]),
                      np.array([adapter[0] / 2, adapter[1] / 2, size[2] + adapter[2]]))]
            for lo, hi in boxes:
                for verts, n in box_faces(lo, hi):
                    faces.append((verts @ R.T + c, R @ n, m.oru_albedo * shade(R @ n)))
        px, py = m.plate_size[0] / 2, m.plate_size[1] / 2
        faces += [(verts, n, m.plate_albedo * shade(n))
                  for verts, n in box_faces(np.array([-px, -py, -m.plate_thickness]), np.array([px, py, 0.0]))]
        up = np.array([0.0, 0.0, 1.0])
        circles = [(circle_points(p, m.circle_radius), m.circle_albedo * shade(up)) for p in m.points[:3]]
        # rod: silhouette = convex hull of the projected end discs (exact for a cylinder)
        rod = m.points[m.rod_index]
        rod_base = np.array([rod[0], rod[1], 0.0])
        hull = (np.vstack([circle_points(rod_base, m.rod_radius, 64), circle_points(rod, m.rod_radius, 64)]),
                -m.plate_albedo * shade(np.array([1.0, 0, 0])))
        rod_end = [(circle_points(rod, m.rod_radius, 64), m.plate_albedo * shade(up)),
                   (circle_points(rod, m.circle_radius), m.circle_albedo * shade(up))]
        parts = faces, circles, (float(rod[2]), hull, rod_end)
        self._marker_cache = (key, parts)
        return parts

    def _project(self, groups, cam_T_m: np.ndarray) -> list[list[tuple[np.ndarray, float]]]:
        """Groups of marker-frame polygons (all convex) -> the same groups of output-pixel
        polygons, lens distortion included (a negative value: their convex hull), polygons
        behind the camera left out. Each is cut to the ideal canvas first (beyond the field of
        view the distortion polynomial folds back) and its edges split into pieces of at most
        EDGE_PX ideal px, so that the distorted outline follows the curved image of a straight
        edge. All vertices go through the camera model in two calls."""
        cv = self.canvas
        flat = [(g, verts, value) for g, items in enumerate(groups) for verts, value in items]
        if not flat:
            return [[] for _ in groups]
        pc = transform(cam_T_m, np.vstack([verts for _, verts, _ in flat]))
        in_front = pc[:, 2] >= NEAR
        uv_all = self._ideal(np.where(in_front[:, None], pc, 1.0))
        box = np.array([[0, 0], [cv.width, 0], [cv.width, cv.height], [0, cv.height]], np.float32)
        kept: list[tuple[int, np.ndarray, float]] = []
        ends = np.cumsum([len(verts) for _, verts, _ in flat])
        starts = ends - [len(verts) for _, verts, _ in flat]
        # each polygon's bounds in two calls (per polygon, the calls' overhead was most of the time)
        lo, hi = np.minimum.reduceat(uv_all, starts), np.maximum.reduceat(uv_all, starts)
        inside = ((lo.min(axis=1) >= 0) & (hi[:, 0] <= cv.width) & (hi[:, 1] <= cv.height)).tolist()
        for (g, verts, value), start, end, ok, within in zip(flat, starts.tolist(), ends.tolist(),
                                                             np.logical_and.reduceat(in_front, starts).tolist(), inside):
            if not ok:
                continue
            uv = uv_all[start:end]
            if value < 0:
                uv = cv2.convexHull(uv.astype(np.float32)).reshape(-1, 2).astype(np.float64)
                value = -value
                within = not (uv.min() < 0 or uv[:, 0].max() > cv.width or uv[:, 1].max() > cv.height)
            if not within:
                area, cut = cv2.intersectConvexConvex(np.ascontiguousarray(uv, np.float32), box)
                if cut is None or area <= 0:
                    continue
                uv = cut.reshape(-1, 2).astype(np.float64)
            kept.append((g, uv, value))
        out: list[list[tuple[np.ndarray, float]]] = [[] for _ in groups]
        if not kept:
            return out
        split, sizes = _split_edges([uv for _, uv, _ in kept], EDGE_PX)
        pixels = self._distort_ideal(split)
        start = 0
        for (g, _, value), n in zip(kept, sizes.tolist()):
            out[g].append((pixels[start:start + n], value))
            start += n
        return out

    def _distort_ideal(self, uv: np.ndarray) -> np.ndarray:
        """Ideal-canvas pixels (inside the canvas) -> output pixels, lens distortion included."""
        cv, K = self.canvas, self.camera.K
        xy = np.column_stack([(uv[:, 0] - cv.offset[0] - K[0, 2]) / K[0, 0],
                              (uv[:, 1] - cv.offset[1] - K[1, 2]) / K[1, 1]])
        return self.camera.normalized_to_pixels(xy, distort=True)

    @staticmethod
    def _lay_over(albedo: np.ndarray, clear: np.ndarray, group, origin: tuple[int, int], down: int = 1) -> None:
        """Draw `group`'s polygons in their own box supersampled, box-average (pixel
        integration) and composite them over the planes (premultiplied: over = group +
        transparency under; transparencies multiply). `down` 2: the planes are at half
        resolution (the group's box is then on even output pixels)."""
        h, w = albedo.shape[0] * down, albedo.shape[1] * down
        pts_all = np.vstack([uv for uv, _ in group]) - origin
        gx0, gy0, gx1, gy1 = _pixel_box(pts_all, 2, (w, h))
        gx0, gy0, gx1, gy1 = gx0 // down * down, gy0 // down * down, -(-gx1 // down) * down, -(-gy1 // down) * down
        if gx1 <= gx0 or gy1 <= gy0:
            return
        # a shape hundreds of px across integrates its outline's coverage over as many edge
        # pixels: 2x is then as exact for its centre as 4x is for a small one
        ss = SS if (gy1 - gy0) * (gx1 - gx0) <= SS_BIG_BOX else 2
        own_albedo, own_clear = _supersampled(group, (origin[0] + gx0, origin[1] + gy0), (gx1 - gx0, gy1 - gy0),
                                              ss, down)
        box = np.s_[gy0 // down:gy1 // down, gx0 // down:gx1 // down]
        under = albedo[box]
        under *= own_clear
        under += own_albedo
        clear[box] *= own_clear

    def _clutter(self, scene: Scene) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The wall's polygons as one vertex array, each polygon's first vertex, albedos."""
        key = id(scene.clutter)
        cached = self._clutter_cache.get(key)
        if cached is None:
            polys = scene.clutter
            vertices = np.vstack([p.vertices for p in polys]) if polys else np.zeros((0, 3))
            starts = np.cumsum([0] + [len(p.vertices) for p in polys[:-1]]).astype(np.intp)
            cached = (vertices, starts, np.array([p.albedo for p in polys], float))
            self._clutter_cache = {key: cached}
        return cached

    def _background(self, scene: Scene, cam_T_m: np.ndarray, sigma: float) -> tuple[np.ndarray, bool]:
        """The wall and its clutter, distorted and defocused by `sigma` px: (H, W) uint8, 255 =
        albedo 1 in full light, and whether it is at half resolution (H/2, W/2: the blurred
        half-resolution image whose _twice is the wall; the compositing upsamples it band by band). Its small bright dots are the vision's distractors at a
        distance: drawn at full resolution, as the detector's contrast ranking of them depends
        on it. The polygons' vertices are distorted and drawn straight into the output pixels
        (a full-frame remap cost more than the rest of the frame); their edges are not split:
        the wall's straight edges bend by well under a pixel over a polygon at this lens's
        distortion, and its geometry is not measured. The blur of a wall that far behind the
        focus (sigma >= 1.1 px) is done at half resolution."""
        cv = self.canvas
        shade = self._wall_shade(scene)
        img = np.full((self.camera.height, self.camera.width), int(scene.wall_albedo * 255 * shade), np.uint8)
        vertices, starts, albedos = self._clutter(scene)
        if len(vertices):
            pc = transform(cam_T_m, vertices)
            near = np.minimum.reduceat(pc[:, 2], starts) >= NEAR
            uv = self._ideal(np.where(pc[:, 2:3] >= NEAR, pc, 1.0))
            lo, hi = np.minimum.reduceat(uv, starts), np.maximum.reduceat(uv, starts)
            visible = near & (hi[:, 0] >= 0) & (hi[:, 1] >= 0) & (lo[:, 0] <= cv.width) & (lo[:, 1] <= cv.height)
            inside = (lo[:, 0] >= 0) & (lo[:, 1] >= 0) & (hi[:, 0] <= cv.width) & (hi[:, 1] <= cv.height)
            ends = np.append(starts[1:], len(uv))
            box = np.array([[0, 0], [cv.width, 0], [cv.width, cv.height], [0, cv.height]], np.float32)
            polys: list[np.ndarray] = []
            values: list[int] = []
            for i in np.flatnonzero(visible):
                poly = uv[starts[i]:ends[i]]
                if not inside[i]:        # beyond the canvas the distortion polynomial folds back
                    area, cut = cv2.intersectConvexConvex(np.ascontiguousarray(poly, np.float32), box)
                    if cut is None or area <= 0:
                        continue
                    poly = cut.reshape(-1, 2).astype(np.float64)
                polys.append(poly)
                values.append(int(albedos[i] * 255 * shade))
            if polys:
                pixels = np.round(self._distort_ideal(np.vstack(polys)) * 16).astype(np.int32)
                start = 0
                for poly, value in zip(polys, values):
                    cv2.fillPoly(img, [pixels[start:start + len(poly)].reshape(-1, 1, 2)], value, cv2.LINE_AA, 4)
                    start += len(poly)
        h, w = img.shape
        if not _may_halve(sigma, (w, h)):
            return _blur(img, sigma), False
        return _blur_small(cv2.resize(img, (w // 2, h // 2), interpolation=cv2.INTER_AREA), sigma), True

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

    def _illumination(self, scene: Scene, gain: np.ndarray | None = None) -> np.ndarray:
        """The lighting field, times `gain` (the sensor's electrons per unit irradiance) if given."""
        key = (id(scene.lighting), None if gain is None else id(gain))
        cached = self._lighting_cache.get(key)
        if cached is not None:
            return cached
        if gain is not None:
            field = cv2.multiply(self._illumination(scene), gain)
            self._lighting_cache[key] = field
            return field
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
        self._lighting_cache = {key: field}     # a new lighting: the fields of the old one go
        return field

    def flat_margin(self, depth: float) -> int:
        """Px of zero coverage a FlatLayer at `depth` (m) needs around what it draws to be laid
        without growing its planes: its blur's reach (OpenCV's Gaussian kernel for float images
        reaches 4 sigma) and 2."""
        return int(np.ceil(4 * min(self.coc_sigma_px(max(depth, 0.01)), MAX_BLUR))) + 2

    def _flat_box(self, flat: FlatLayer, shape: tuple[int, int], shade: float):
        """(labels, albedo and coverage tables, sigma, reach, shade, (x0, y0, x1, y1)): `flat`'s
        labels over the box they are laid over (grown by label 0 to its blur's reach unless its
        margin has it: beyond the patch nothing is covered, so the box's border reflects zeros
        as the whole frame's blur would see them), 256-entry float32 tables of each label's
        albedo and coverage (cv2.LUT makes a band's planes from them), its blur (sigma px) and
        the wall's `shade` (parallel to the wall: lit alike); None for an empty patch."""
        sigma = min(self.coc_sigma_px(max(flat.depth, 0.01)), MAX_BLUR)
        (x, y), (h, w) = flat.origin, flat.labels.shape
        if w == 0 or h == 0:
            return None
        albedo, coverage = np.zeros(256, np.float32), np.ones(256, np.float32)
        albedo[:len(flat.levels)] = flat.levels
        albedo[0] = coverage[0] = 0.0
        reach = self.flat_margin(flat.depth)
        labels, box = flat.labels, (x, y, x + w, y + h)
        if flat.margin < reach:
            H, W = shape
            box = x0, y0, x1, y1 = max(x - reach, 0), max(y - reach, 0), min(x + w + reach, W), min(y + h + reach, H)
            labels = cv2.copyMakeBorder(labels, y - y0, y1 - y - h, x - x0, x1 - x - w, cv2.BORDER_CONSTANT, value=0)
        # a band's looked-up albedo and its blur written into the same two buffers band after
        # band (they stay in the cache: new ones each band were as much again as the work)
        scratch = [np.empty((BAND_ROWS + 2 * reach, labels.shape[1]), np.float32) for _ in range(2)]
        return labels, (albedo, coverage, scratch, _scale_of(flat.levels)), sigma, reach, shade, box

    @staticmethod
    def _flat_rows(laid, b0: int, b1: int):
        """The rows of a flat layer (Renderer._flat_box) in the image's rows b0:b1: (r0, r1) the
        rows it covers there, (g0, g1) the rows its blur reaches for them, and (c0, c1) the image's
        columns where its blurred coverage is 1 in all of them (the inside of an opaque board:
        what lies under it does not show), or None; None for no rows."""
        labels, tables, sigma, reach, shade, (x0, y0, x1, y1) = laid
        r0, r1 = max(b0, y0), min(b1, y1)
        if r1 <= r0:
            return None
        g0, g1 = max(r0 - reach, y0), min(r1 + reach, y1)
        covered = _inside(labels[g0 - y0:g1 - y0].min(axis=0) > 0, reach)    # (a row-wise reduction: fast)
        return (r0, r1), (g0, g1), None if covered is None else (x0 + covered[0], x0 + covered[1])

    @staticmethod
    def _lay_flat_band(band: np.ndarray, b0: int, b1: int, laid, rows) -> None:
        """Lay the rows b0:b1 (the image's) of a flat layer (Renderer._flat_box; `rows` its
        Renderer._flat_rows there) over `band` (those rows of the image, unlit) in place: the
        rows the band's blur reaches are blurred from its labels (the albedo straight from them
        when its table is a scale, _scale_of; else looked up first; the coverage looked up) and
        laid while in the cache: band * (1 - blurred coverage) + shade * blurred albedo. Where
        the blurred coverage is 1 (the covered columns) that is shade * blurred albedo, whatever
        the band held there (it need not hold the wall), and the coverage is looked up and
        blurred only beside them."""
        if rows is None:
            return
        labels, (albedo, coverage, (looked_up, blurred), step), sigma, reach, shade, (x0, y0, x1, y1) = laid
        (r0, r1), (g0, g1), covered = rows
        keep = np.s_[r0 - g0:r1 - g0]
        region = band[r0 - b0:r1 - b0, x0:x1]
        labels = labels[g0 - y0:g1 - y0]
        if step is not None and sigma >= 0.1:       # (_blur's no-op below 0.1 px)
            kernel = cv2.getGaussianKernel(int(round(sigma * 8 + 1)) | 1, sigma, cv2.CV_32F)   # GaussianBlur's
            lit = cv2.sepFilter2D(labels, cv2.CV_32F, kernel, kernel * step, dst=blurred[:g1 - g0],
                                  borderType=cv2.BORDER_REFLECT_101)
        else:
            lit = cv2.LUT(labels, albedo, dst=looked_up[:g1 - g0])
            if sigma >= 0.1:
                lit = cv2.GaussianBlur(lit, (0, 0), sigma, dst=blurred[:g1 - g0])
        lit = lit[keep]
        if covered is None:
            parts = [(np.s_[:], _blur(cv2.LUT(labels, coverage), sigma)[keep])]
        else:
            c0, c1 = covered[0] - x0, covered[1] - x0
            np.multiply(lit[:, c0:c1], np.float32(shade), out=region[:, c0:c1])
            parts = [(np.s_[:, :c0], _blur(cv2.LUT(labels[:, :c0 + reach], coverage), sigma)[keep][:, :c0]),
                     (np.s_[:, c1:], _blur(cv2.LUT(labels[:, c1 - reach:], coverage), sigma)[keep][:, reach:])]
        for part, cover in parts:
            under = region[part]
            cv2.subtract(under, cv2.multiply(under, cover), dst=under)     # in place, into the view
            cv2.scaleAdd(lit[part], shade, under, dst=under)

    @staticmethod
    def _composite(background: tuple[np.ndarray, bool], light: np.ndarray, layer, flats=(),
                   finish=None) -> np.ndarray | None:
        """The lit wall (the lighting applied in its one float conversion), the flat layers
        (Renderer._flat_box) and the foreground `layer` ((albedo, transparency), origin, down,
        sigma) over it, or None, a band of rows at a time: the half-resolution planes are
        upsampled band by band and every pass of a band works on planes still in the cache
        (full-frame passes were memory-bound). A wall and a foreground both at half resolution
        (and nothing between) are laid together there and upsampled once (the upsampling of a
        product then stands for the product of upsamplings: they differ only where both the
        wall and the foreground's coverage change within a pixel pair, i.e. at the foreground's
        outline against the wall's dots, by a fraction of the contrast).
        `finish(band, y)`: given each band of the image (rows y:y+len(band)) as it is made,
        while in the cache (the sensor's exposure): then no image is kept and None returned."""
        wall, halved = background
        height, width = light.shape
        img = np.empty((BAND_ROWS, width) if finish else light.shape, np.float32)
        out = (lambda y0, y1: img[:y1 - y0]) if finish else (lambda y0, y1: img[y0:y1])
        if layer is None and not flats:
            for y in range(0, height, BAND_ROWS):
                y1 = min(y + BAND_ROWS, height)
                cv2.multiply(_twice_rows(wall, y, y1) if halved else wall[y:y1], light[y:y1],
                             dst=out(y, y1), scale=1.0 / 255.0, dtype=cv2.CV_32F)
                if finish:
                    finish(out(y, y1), y)
            return None if finish else img
        wall = np.multiply(wall, np.float32(1.0 / 255.0), dtype=np.float32)
        if layer is not None:
            (albedo, clear), (x0, y0), down, sigma = layer
            h, w = albedo.shape[0] * down, albedo.shape[1] * down
            if halved and down == 2 and not flats:
                region = wall[y0 // 2:(y0 + h) // 2, x0 // 2:(x0 + w) // 2]
                cv2.multiply(region, _blur_small(clear, sigma), dst=region)
                cv2.add(region, _blur_small(albedo, sigma), dst=region)
                layer = None
            elif down == 2:
                albedo, clear = _blur_small(albedo, sigma), _blur_small(clear, sigma)
        reach = int(np.ceil(4 * sigma)) + 1 if layer is not None and down == 1 else 0    # _blur_rows's
        upsampled = np.empty((BAND_ROWS + 6, width), np.float32) if halved else None
        fg_upsampled = [np.empty((BAND_ROWS + 6, w), np.float32) for _ in range(2)] \
            if layer is not None and down == 2 else (None, None)
        fg_blurred = [np.empty((BAND_ROWS + 2 * reach, w), np.float32) for _ in range(2)] \
            if layer is not None and down == 1 else (None, None)
        for y in range(0, height, BAND_ROWS):
            y1 = min(y + BAND_ROWS, height)
            rows = [Renderer._flat_rows(laid, y, y1) for laid in flats]
            # the wall is not upsampled under the first flat layer's opaque inside where it
            # covers every row of the band (its laying writes there whatever the band held)
            hidden = bool(rows) and rows[0] is not None and rows[0][0] == (y, y1) and rows[0][2]
            if hidden and halved and hidden[1] - hidden[0] > 64:
                even = (hidden[0] + hidden[0] % 2, hidden[1] - hidden[1] % 2)
                band = _twice_rows_beside(wall, y, y1, upsampled, even)
            else:
                band = _twice_rows(wall, y, y1, upsampled) if halved else wall[y:y1]
            for laid, at in zip(flats, rows):
                Renderer._lay_flat_band(band, y, y1, laid, at)
            f0, f1 = (max(y, y0) - y0, min(y1, y0 + h) - y0) if layer is not None else (0, 0)   # the foreground's rows
            if f1 > f0:
                region = band[y0 + f0 - y:y0 + f1 - y, x0:x0 + w]
                if down == 2:
                    parts = [(np.s_[:], _twice_rows(albedo, f0, f1, fg_upsampled[0]),
                              _twice_rows(clear, f0, f1, fg_upsampled[1]))]
                else:       # its inside, where its blurred transparency is 0
                    opaque = _inside(clear[max(f0 - reach, 0):f1 + reach].max(axis=0) <= 0.0, reach)
                    parts = Renderer._foreground_parts(albedo, clear, f0, f1, sigma, reach, opaque, region, fg_blurred)
                for part, a, c in parts:
                    under = region[part]
                    cv2.multiply(under, c, dst=under)        # OpenCV writes into the view, in place
                    cv2.add(under, a, dst=under)
            cv2.multiply(band, light[y:y1], dst=out(y, y1))
            if finish:
                finish(out(y, y1), y)
        return None if finish else img

    @staticmethod
    def _foreground_parts(albedo, clear, f0: int, f1: int, sigma: float, reach: int, opaque, region,
                          into=(None, None)) -> list:
        """The foreground's rows f0:f1 blurred, as (columns, albedo, transparency) to lay over
        `region` (those rows of the image under it); with an opaque inside (c0, c1) (its
        columns, _inside) that is written into `region` straight (the blurred albedo: what was
        under it does not show, whatever it was) and the transparency is blurred only beside it.
        `into`: two buffers (_blur_rows's) for the albedo's and the transparency's blur."""
        a = _blur_rows(albedo, f0, f1, sigma, into[0])
        if opaque is None:
            return [(np.s_[:], a, _blur_rows(clear, f0, f1, sigma, into[1]))]
        c0, c1 = opaque
        np.copyto(region[:, c0:c1], a[:, c0:c1])
        return [(np.s_[:, :c0], a[:, :c0], _blur_rows(clear[:, :c0 + reach], f0, f1, sigma)[:, :c0]),
                (np.s_[:, c1:], a[:, c1:], _blur_rows(clear[:, c1 - reach:], f0, f1, sigma)[:, reach:])]

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
               flat_layers: Sequence[FlatLayer] = (), gain: np.ndarray | None = None,
               exposure=None) -> np.ndarray | None:
        """Relative irradiance image (H, W) float32 in [0, 1] for the given true pose.
        `gain` (H, W): a per-pixel factor (the sensor's electrons per unit irradiance) applied in
        the lighting's pass, which every layer gets anyway: the sensor's own full-frame multiply
        is then saved (SensorModel.expose_electrons).
        `flat_layers` (e.g. a calibration board) lie in front of the wall and behind the
        marker/ORU; none (the default) renders the marker scene alone. A new pose's image is the
        caller's to overwrite (the sensor adds its noise in place); the same pose, scene and flat
        layers (the same FlatLayer objects: a caller keeps a still board's) as the last call (an
        arm at rest) render once more and from then on give that image again, read-only: only
        the noise moves. `exposure` (SensorModel.exposure, with `gain` its electrons_per_unit):
        a new pose's image is exposed a band at a time as it is made, while in the cache, and
        None returned (the frame is the exposure's); an image to keep is returned whole, for
        the caller to expose (Exposure.whole)."""
        key = (np.asarray(camera_T_marker, float).tobytes(), id(scene), scene.oru, id(scene.lighting),
               id(scene.marker), id(scene.clutter), scene.wall_depth, scene.wall_albedo,
               None if gain is None else id(gain), tuple(id(flat) for flat in flat_layers))
        # (the flat layers' ids are the same layers': _last holds them, so no new one can take an id)
        again = self._last is not None and self._last[0] == key
        if again and self._last[1] is not None:
            return self._last[1]
        marker_depth = float(camera_T_marker[2, 3])
        wall_depth = self._wall_axis_depth(scene, camera_T_marker)
        # Depths behind the camera or at grazing incidence give absurd blur circles (and a
        # Gaussian kernel of thousands of px takes minutes): beyond MAX_BLUR px the layer is a
        # smear anyway.
        sb = min(self.coc_sigma_px(max(wall_depth, 0.01)), MAX_BLUR)
        sf = min(self.coc_sigma_px(max(marker_depth, 0.01)), MAX_BLUR)
        # the lighting multiplies every layer: applied to each as it is laid down, the wall's
        # 8-bit levels become irradiance in the same full-frame pass
        light = self._illumination(scene, gain)
        layer = (self._foreground(scene, camera_T_marker, sf)
                 if self._marker_near_view(camera_T_marker) else None)
        if layer is not None:
            albedo, clear, origin, down = layer
            layer = (albedo, clear), origin, down, sf
        flats = [laid for laid in (self._flat_box(flat, light.shape, self._wall_shade(scene)) for flat in flat_layers)
                 if laid is not None]
        if exposure is not None and not again:     # not kept: each band exposed as it is made
            self._composite(self._background(scene, camera_T_marker, sb), light, layer, flats, exposure.band)
            self._last = (key, None, tuple(flat_layers))
            return None
        img = self._composite(self._background(scene, camera_T_marker, sb), light, layer, flats)
        if again:             # at rest: kept, read-only, from the second frame of the pose on
            img.flags.writeable = False
        self._last = (key, img if again else None, tuple(flat_layers))
        return img
