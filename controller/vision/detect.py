"""Characteristic-circle candidates in a frame (ORU paper, Section 4.2, Figure 13).

Search at reduced resolution (speed), refinement at full resolution (accuracy):
1. Gaussian denoising of the down-sampled frame.
2. Local adaptive threshold T = B + s*sigma: B is the local mean of the background (from a
   grey opening, which removes bright features narrower than the window), sigma the
   local RMS of the random noise of the denoised image, estimated robustly per tile from
   neighbour differences (median absolute deviation), so edges of clutter do not inflate it.
   A floor of `min_contrast` DN keeps 8-bit quantisation (sigma ~ 0) from passing flat areas.
3. Connected components of I >= T, filtered by size, fill ratio and aspect.
4. The characteristic circles are white on a black plate: the surround (a ring around the
   blob) must stay below `dark_surround_ratio` of the blob peak.
5. Full-resolution refinement in a small ROI: Canny outline of the blob (the paper's edge
   step; its bounding-box centre is the paper's circle centre, kept for comparison) and the
   background-subtracted, intensity-weighted centroid of the thresholded blob, which is the
   centre of the (blurred) projected ellipse without pixel quantisation.
"""
from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from spacearm.base.vision.config import PipelineConfig

TILE = 32                                # px (search scale) tiles of the noise estimate
NOISE_FLOOR = 0.5                        # DN, 8-bit quantisation noise is 0.29 DN
# Labelling with statistics: OpenCV's default (Spaghetti) took 2 ms on the 680 x 512 search
# image here, BBDT 0.5 ms (single thread); the labels are the same.
CCL = cv2.CCL_BBDT
DUPLICATE_PX = 1.0                       # full-res px: refined centres this close are one circle


@dataclass(frozen=True)
class Candidate:
    centre: np.ndarray                   # (2,) full-res px, weighted centroid
    centre_bbox: np.ndarray              # (2,) full-res px, Canny-outline bounding-box centre (paper)
    diameter: float                      # px, equivalent diameter of the thresholded blob
    peak: float                          # DN above local background
    surround_ratio: float                # surround level / peak (both above black)
    touches_border: bool


@dataclass(frozen=True)
class Detection:
    candidates: list[Candidate]          # plate-like, in-range, sorted by contrast (best first)
    n_blobs: int                         # components that passed the threshold and size tests
    n_too_small: int                     # plate-like blobs below min_diameter_px
    noise_sigma: float                   # DN, median local noise of the denoised search image


def local_noise_sigma(img: np.ndarray) -> tuple[np.ndarray, float]:
    """Per-tile robust RMS of the pixel noise of img (float32 map at the size of img) and its
    median over the tiles."""
    h, w = img.shape
    th, tw = h // TILE, (w - 1) // TILE
    # every other row and column of each tile: 256 samples per tile are plenty for a median
    # and keep this step near 1 ms on a 680 x 512 image
    sub = img[: th * TILE: 2, : tw * TILE + 1].astype(np.int16)
    d = np.abs(sub[:, 1::2] - sub[:, 0:-1:2])
    half = TILE // 2
    tiles = d[:, : tw * half].reshape(th, half, tw, half).transpose(0, 2, 1, 3).reshape(th, tw, -1)
    # MAD of a difference of two pixels: sigma = 1.4826 * median|d| / sqrt(2). Quantised 8-bit
    # data make the median 0 on very dark flat areas; the mean of |d| (x sqrt(pi)/2) is the
    # fallback there (still robust enough: a tile gives 256 samples).
    k = tiles.shape[2] // 2          # exact median of an even count, by one partial sort of uint8
    part = np.partition(tiles.astype(np.uint8), (k - 1, k), axis=2)
    med = (part[..., k - 1].astype(np.float32) + part[..., k]) * np.float32(0.5 * 1.4826 / np.sqrt(2))
    mean = tiles.mean(axis=2) * (np.sqrt(np.pi) / 2 / np.sqrt(2))
    sig = np.where(med > 0, med, mean).astype(np.float32)
    return cv2.resize(sig, (w, h), interpolation=cv2.INTER_LINEAR), float(np.median(sig))


class CircleDetector:
    def __init__(self, cfg: PipelineConfig):
        self.cfg = cfg
        s = cfg.gaussian_sigma
        # noise of a Gaussian-filtered white-noise image: sigma / (2 sqrt(pi) s)
        self.smoothing_gain = 1.0 / (2 * np.sqrt(np.pi) * s) if s > 0.3 else 1.0

    def detect(self, image: np.ndarray, roi: tuple[int, int, int, int] | None = None,
               scale: int | None = None) -> Detection:
        """Candidates in the whole image or in roi = (x0, y0, x1, y1) (full-res px)."""
        cfg = self.cfg
        full = image if image.dtype == np.uint8 else np.clip(image, 0, 255).astype(np.uint8)
        H, W = full.shape
        x0, y0, x1, y1 = roi if roi is not None else (0, 0, W, H)
        k = cfg.search_scale if scale is None else scale
        x1 = x0 + (x1 - x0) // k * k
        y1 = y0 + (y1 - y0) // k * k
        crop = full[y0:y1, x0:x1]
        small = cv2.resize(crop, ((x1 - x0) // k, (y1 - y0) // k), interpolation=cv2.INTER_AREA) if k > 1 else crop
        g8 = cv2.GaussianBlur(small, (0, 0), cfg.gaussian_sigma) if cfg.gaussian_sigma > 0 else small
        g = g8.astype(np.float32)
        win = min(cfg.background_window, (min(small.shape) // 2) * 2 - 1)
        # B = local level of the *background*: a grey opening removes every bright feature
        # narrower than the window (circles, dots) and keeps edges where they are; its box mean
        # over a third of the window is the local mean of the background. A plain box mean of the image missed circles at
        # 1.5 m: a bright ORU face beside the black plate lifted T above them. The max with
        # the (barely smoothed) opening keeps the bright side of an edge below T, which
        # otherwise rose above T and merged with a corner circle.
        kernel = cv2.getStructuringElement(cv2.MORPH_RECT, (win, win))
        opened = cv2.morphologyEx(g8, cv2.MORPH_OPEN, kernel)
        mean_win = max(3, win // 3)
        B = cv2.max(cv2.blur(opened, (mean_win, mean_win), borderType=cv2.BORDER_REFLECT),
                    cv2.blur(opened, (5, 5))).astype(np.float32)
        if min(small.shape) >= 2 * TILE:
            raw, raw_median = local_noise_sigma(small)
            noise = max(raw_median * self.smoothing_gain, NOISE_FLOOR)
            # T = B + max(s * sigma, min_contrast), sigma floored at the quantisation noise
            margin = cv2.max(raw * np.float32(cfg.threshold_s * self.smoothing_gain),
                             float(max(cfg.min_contrast, cfg.threshold_s * NOISE_FLOOR)))
        else:
            noise = NOISE_FLOOR
            margin = np.full_like(g, max(cfg.min_contrast, cfg.threshold_s * NOISE_FLOOR))
        binary = cv2.compare(g, cv2.add(B, margin), cv2.CMP_GE)
        n, labels, stats, _ = cv2.connectedComponentsWithStatsWithAlgorithm(binary, 8, cv2.CV_32S, CCL)
        if n <= 1:
            return Detection([], 0, 0, noise)
        st = stats[1:].astype(np.float64)
        bw, bh, area = st[:, 2], st[:, 3], st[:, 4]
        d_small = np.sqrt(4 * area / np.pi)
        d_full = d_small * k
        shape_ok = (np.maximum(bw, bh) <= 3 * np.minimum(bw, bh)) & (area >= 0.45 * bw * bh)
        size_ok = d_full <= cfg.max_diameter_px
        idx = np.nonzero(shape_ok & size_ok & (area >= 1))[0]
        n_blobs = len(idx)
        # dark surround: mean of g over a ring of width ~ one blob diameter (integral image)
        ii = cv2.integral(g8, sdepth=cv2.CV_32S)     # g = g8 exactly; int32 sums are exact and 10x faster than float64
        hs, ws = g.shape
        cands: list[tuple[float, Candidate]] = []
        n_small = 0
        for i in idx:
            bx, by, bwi, bhi = (int(v) for v in st[i, :4])
            pad = max(2, int(round(max(bwi, bhi) * 0.75)))
            inner = _box_sum(ii, bx - 1, by - 1, bx + bwi + 1, by + bhi + 1, ws, hs)
            ox0, oy0, ox1, oy1 = bx - pad - 1, by - pad - 1, bx + bwi + pad + 1, by + bhi + pad + 1
            outer = _box_sum(ii, ox0, oy0, ox1, oy1, ws, hs)
            ring_area = outer[1] - inner[1]
            if ring_area <= 0:
                continue
            surround = (outer[0] - inner[0]) / ring_area
            peak = float(g8[by:by + bhi, bx:bx + bwi].max())
            contrast = peak - surround
            if contrast < cfg.min_contrast or surround > cfg.dark_surround_ratio * peak:
                continue
            if d_full[i] < cfg.min_diameter_px:
                n_small += 1
                continue
            touches = bx <= 0 or by <= 0 or bx + bwi >= ws or by + bhi >= hs
            cands.append((contrast, (bx, by, bwi, bhi, surround / peak, touches, d_full[i])))
        cands.sort(key=lambda c: -c[0])
        out: list[Candidate] = []
        for contrast, (bx, by, bwi, bhi, ratio, touches, diam) in cands[: cfg.max_candidates]:
            c = self._refine(full, x0 + bx * k, y0 + by * k, bwi * k, bhi * k, touches)
            # two search-scale blobs (a circle split by the threshold) can refine to the same
            # full-res component; a duplicate would make every labelling with it ambiguous
            if c is not None and not any(np.hypot(*(c[0] - o.centre)) < DUPLICATE_PX for o in out):
                out.append(Candidate(c[0], c[1], float(diam), float(contrast), float(ratio),
                                     touches or c[2]))
        return Detection(out, n_blobs, n_small, noise)

    def refine_at(self, image: np.ndarray, centre: np.ndarray, radius: float) -> Candidate | None:
        """Tracking: the circle predicted at `centre` (full-res px) with `radius` px, measured
        directly at full resolution without the search stage. None unless a bright blob on a
        dark surround is found there (contrast and surround ratio as in the search)."""
        full = image if image.dtype == np.uint8 else np.clip(image, 0, 255).astype(np.uint8)
        r = max(2.0, float(radius))
        half = int(np.ceil(r + 3.0))
        bx, by = int(round(centre[0])) - half, int(round(centre[1])) - half
        H, W = full.shape
        if bx < 0 or by < 0 or bx + 2 * half >= W or by + 2 * half >= H:
            return None
        got = self._refine(full, bx, by, 2 * half, 2 * half, False, with_levels=True)
        if got is None:
            return None
        # Second pass on a window centred on the circle and sized by it, as the search's blob
        # box gives: the centre then no longer depends on how far off the prediction was.
        w, h = got[6]
        bx, by = int(round(got[0][0] - w / 2)), int(round(got[0][1] - h / 2))
        if bx < 0 or by < 0 or bx + w >= W or by + h >= H:
            return None
        got = self._refine(full, bx, by, w, h, False, with_levels=True)
        if got is None:
            return None
        c, bbox_c, at_border, peak, background, diameter, _ = got
        contrast = peak - background
        if contrast < self.cfg.min_contrast or background > self.cfg.dark_surround_ratio * peak:
            return None
        return Candidate(c, bbox_c, diameter, contrast, background / max(peak, 1e-9), at_border)

    def _refine(self, full: np.ndarray, bx: int, by: int, bw: int, bh: int, touches: bool, with_levels: bool = False):
        """Full-res centre of the blob whose search-scale box (in full-res px) is given."""
        H, W = full.shape
        m = max(4, int(round(0.8 * max(bw, bh))))
        x0, y0 = max(0, bx - m), max(0, by - m)
        x1, y1 = min(W, bx + bw + m), min(H, by + bh + m)
        raw = full[y0:y1, x0:x1]
        roi = raw.astype(np.float32)
        border = np.concatenate([raw[0], raw[-1], raw[:, 0], raw[:, -1]])
        # the circle's own background is the darkest part of the window's rim (black plate);
        # a bright ORU edge or clutter in one corner of the window must not set it
        b = _quartile(border)
        peak = float(cv2.GaussianBlur(roi, (0, 0), 1.0).max())
        # Core = the level set {I >= t} of the blob (centrally symmetric for a blurred ellipse,
        # so its centroid is unbiased); weights I - t taper to 0 at the core's edge so that noise
        # flipping edge pixels in or out hardly moves the centre. t above the plate level keeps
        # the plate edge and the rod out.
        t = b + 0.35 * (peak - b)
        mask = (roi >= t).astype(np.uint8)
        n, lab, stats, cents = cv2.connectedComponentsWithStatsWithAlgorithm(mask, 8, cv2.CV_32S, CCL)
        if n <= 1:
            return None
        # the component at (or nearest to) the blob found by the search, not the largest one:
        # an ORU edge inside the window can be larger than a far circle
        seed = np.array([bx + bw / 2 - x0 - 0.5, by + bh / 2 - y0 - 0.5])
        j = 1 + int(np.argmin(np.linalg.norm(cents[1:] - seed, axis=1)))
        sel = lab == j
        w = np.where(sel, roi - np.float32(t), np.float32(0.0))
        mom = cv2.moments(w)                     # intensity-weighted centroid without index grids
        if mom["m00"] <= 0:
            return None
        cx = mom["m10"] / mom["m00"] + x0
        cy = mom["m01"] / mom["m00"] + y0
        # the paper's centre: bounding box of the Canny outline
        edges = cv2.Canny(raw, self.cfg.canny_low, self.cfg.canny_high)
        ex, ey, ew, eh = cv2.boundingRect(edges)          # box of the non-zero (edge) pixels
        if ew > 0:
            bbox_c = np.array([ex + (ew - 1) / 2 + x0, ey + (eh - 1) / 2 + y0])
        else:
            bbox_c = np.array([cx, cy])
        st = stats[j]
        at_border = (st[0] + x0 <= 0 or st[1] + y0 <= 0 or st[0] + st[2] + x0 >= W or st[1] + st[3] + y0 >= H)
        if with_levels:
            # the core is the blob above 35 % of its contrast: a blurred disc's core diameter
            # is close to the disc's (the search's equivalent diameter is used the same way)
            return (np.array([cx, cy]), bbox_c, bool(at_border), peak, b,
                    float(np.sqrt(4 * st[4] / np.pi)), (int(st[2]), int(st[3])))
        return np.array([cx, cy]), bbox_c, bool(at_border)


def _quartile(v: np.ndarray) -> float:
    """np.percentile(v, 25) (linear interpolation) by a partial sort: 10x cheaper on a few
    hundred values."""
    pos = 0.25 * (len(v) - 1)
    lo = int(pos)
    hi = min(lo + 1, len(v) - 1)
    part = np.partition(v, (lo, hi))
    return float(part[lo]) + (pos - lo) * (float(part[hi]) - float(part[lo]))


def _box_sum(ii: np.ndarray, x0: int, y0: int, x1: int, y1: int, w: int, h: int) -> tuple[float, float]:
    """Sum and pixel count of img[y0:y1, x0:x1] (clipped) from its integral image."""
    x0, x1 = max(0, x0), min(w, x1)
    y0, y1 = max(0, y0), min(h, y1)
    if x1 <= x0 or y1 <= y0:
        return 0.0, 0.0
    s = ii[y1, x1] - ii[y0, x1] - ii[y1, x0] + ii[y0, x0]
    return float(s), float((x1 - x0) * (y1 - y0))
