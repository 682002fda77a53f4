"""The camera's cheaper passes give the pixels of the plain whole-image operations they replace:
OpenCV's whole-image upsampling and Gaussian blur against the band-by-band versions, the
sensor's physics written out over the whole frame against its banded noise, a flat layer's
blur that skips the inside of an opaque board, and the board drawn in its patch against the
board drawn square by square over the whole frame (the way it was drawn before)."""
from __future__ import annotations

import cv2
import numpy as np
import pytest

from spacearm.base.config.board import load_board
from spacearm.base.spatial import xyz_rpy_to_transform
from spacearm.base.vision.camera import CameraModel
from spacearm.base.vision.config import load_camera
from spacearm.firmware_sim.calibration_board import EDGE_STEPS, SHIFT, board_patch
from spacearm.firmware_sim.camera.noise import SensorModel
from spacearm.firmware_sim.camera.renderer import (Renderer, _blur, _blur_rows, _scale_of, _twice, _twice_rows,
                                                   _twice_rows_beside)

SEED = 3207           # this file's draws


@pytest.mark.parametrize("rows", [37, 300, 512])
def test_band_upsampling_and_blur_are_the_whole_image_operations(rows):
    rng = np.random.default_rng(SEED + rows)
    for dtype in (np.uint8, np.float32):
        small = (rng.random((rows, 201)) * 250).astype(dtype)
        whole = cv2.resize(small, (402, 2 * rows), interpolation=cv2.INTER_LINEAR)
        for step in (128, 7):
            starts = range(int(rng.integers(0, 2)), 2 * rows, step)      # odd band starts too
            bands = [_twice_rows(small, y, min(y + step, 2 * rows)) for y in starts]
            assert np.array_equal(np.vstack(bands), whole[starts[0]:])
    image = rng.random((rows, 133)).astype(np.float32)
    for sigma in (0.05, 0.4, 0.9, 2.5, 20.0):
        whole = cv2.GaussianBlur(image, (0, 0), sigma) if sigma >= 0.1 else image
        bands = [_blur_rows(image, y, min(y + 128, rows), sigma) for y in range(0, rows, 128)]
        assert np.array_equal(np.vstack(bands), whole), sigma


def test_band_upsampling_beside_a_hidden_span_is_the_whole_image_operation():
    """The wall upsampled only beside the columns a board hides: those beside are the whole
    image's upsampling, at any even span (at the image's edges too)."""
    rng = np.random.default_rng(SEED + 5)
    small = rng.random((150, 181)).astype(np.float32)
    whole = cv2.resize(small, (362, 300), interpolation=cv2.INTER_LINEAR)
    into = np.full((128 + 6, 362), np.nan, np.float32)
    spans = [(0, 200), (2, 360), (100, 362), (64, 68)]
    spans += [(int(xa), int(xa + 2 * rng.integers(2, (362 - xa) // 2 + 1))) for xa in rng.integers(0, 170, 6) * 2]
    for xa, xb in spans:
        for y in (0, 128, 256):
            band = _twice_rows_beside(small, y, min(y + 128, 300), into, (int(xa), int(xb)))
            beside = np.r_[0:xa, xb:362]
            assert np.array_equal(band[:, beside], whole[y:y + 128][:, beside]), (xa, xb, y)


def test_banded_sensor_noise_is_the_whole_frame_physics():
    cfg = load_camera().sensor
    sensor = SensorModel(cfg)
    rng = np.random.default_rng(SEED)
    signal = (rng.random((cfg.height, cfg.width), dtype=np.float32) * sensor.electrons_per_unit).astype(np.float32)
    normal = SensorModel(cfg)._noise_window(np.random.default_rng(SEED + 1))    # the window the frame reads
    k = 2 ** (cfg.adc_bits - cfg.output_bits)
    scale = 1.0 / (sensor.gain * k)
    electrons = signal + np.sqrt(signal + np.float32(cfg.dark_offset + cfg.read_noise ** 2)) * normal
    expected = np.clip(np.rint(electrons * scale + (cfg.dark_offset * scale - (k - 1) / (2.0 * k))), 0, 255)
    for read_only in (False, True):
        frame = signal.copy()
        frame.flags.writeable = not read_only
        got = sensor.expose_electrons(frame, np.random.default_rng(SEED + 1))
        # float rounding of the same sum in another order moves a pixel by 1 DN at most, rarely
        differ = got.astype(int) - expected
        assert np.abs(differ).max() <= 1 and np.count_nonzero(differ) < 1e-4 * differ.size


def _board_square_by_square(camera_T_board, board, camera):
    """The full-frame drawing of the board as the simulator did it before its patch: each polygon
    projected and filled alone into planes of the whole frame."""
    R, t = camera_T_board[:3, :3], camera_T_board[:3, 3]
    rvec = cv2.Rodrigues(R)[0]
    s, (nx, ny), m = board.square, board.squares, board.margin
    albedo = np.zeros((camera.height, camera.width), np.float32)
    alpha = np.zeros_like(albedo)

    def outline(x0, y0, x1, y1):
        u = np.linspace(0.0, 1.0, EDGE_STEPS, endpoint=False)
        pts = np.concatenate([np.c_[x0 + (x1 - x0) * u, np.full_like(u, y0)], np.c_[np.full_like(u, x1), y0 + (y1 - y0) * u],
                              np.c_[x1 - (x1 - x0) * u, np.full_like(u, y1)], np.c_[np.full_like(u, x0), y1 - (y1 - y0) * u]])
        return np.c_[pts, np.zeros(len(pts))]

    def fill(canvas, poly, value):
        if np.any((poly @ R.T + t)[:, 2] <= 0.01):
            return
        px, _ = cv2.projectPoints(poly, rvec, t, camera.K, camera.dist)
        cv2.fillPoly(canvas, [np.round(px.reshape(-1, 2) * (1 << SHIFT)).astype(np.int32)], float(value),
                     lineType=cv2.LINE_AA, shift=SHIFT)

    edge = outline(-s - m, -s - m, (nx - 1) * s + m, (ny - 1) * s + m)
    fill(alpha, edge, 1.0)
    fill(albedo, edge, board.light)
    for j in range(ny):
        for i in range(nx):
            if (i + j) % 2 == 0:
                fill(albedo, outline((i - 1) * s, (j - 1) * s, i * s, j * s), board.dark)
    return albedo, alpha


def test_board_patch_is_the_square_by_square_full_frame_drawing():
    """The board's labels (one byte a pixel, edges 8-connected) are the float planes the board
    was drawn as before, square by square over the frame with OpenCV's LINE_AA (which smooths
    edges only in 8-bit images): at random poses, margins and with the board partly out of view."""
    board = load_board()
    camera = CameraModel.from_config(load_camera())
    rng = np.random.default_rng(SEED)
    shown = 0
    for _ in range(12):      # tilted, off centre, partly out of the frame
        T = xyz_rpy_to_transform(list(rng.uniform([-0.3, -0.25, 0.15], [0.1, 0.1, 1.2])), list(rng.uniform(-0.6, 0.6, 3)))
        albedo, alpha = _board_square_by_square(T, board, camera)
        patch = board_patch(T, board, camera.K, camera.dist, (camera.width, camera.height), int(rng.integers(0, 12)))
        if patch is None:
            assert not alpha.any()
            continue
        labels, levels, (x, y) = patch
        (h, w) = labels.shape
        for plane, drawn in zip((levels[labels], (labels > 0).astype(np.float32)), (albedo, alpha)):
            assert np.array_equal(plane, drawn[y:y + h, x:x + w])
            drawn[y:y + h, x:x + w] = 0
            assert not drawn.any()                    # nothing of the board outside its patch
        shown += 1
    assert shown >= 8


def test_a_flat_layer_laid_skipping_the_covered_inside_is_the_whole_blur_composite():
    """A band with an opaque board across it: laid over the wall it is the plain formula
    wall * (1 - blur(coverage)) + shade * blur(albedo) over the whole band, whatever the band
    held inside the board; the planes are the labels looked up in the layer's tables."""
    rng = np.random.default_rng(SEED)
    shade = 0.83
    for sigma in (0.3, 0.67, 1.6):
        reach = int(np.ceil(4 * sigma)) + 2
        labels = np.zeros((400, 400), np.uint8)
        left, right, top = rng.integers(5, 60), rng.integers(300, 395), int(rng.integers(0, 100))
        labels[top:, left:right] = rng.integers(1, 4, (400 - top, right - left))
        labels[rng.integers(0, 400, 40), left - 1] = 3              # a ragged edge
        levels = rng.random(4).astype(np.float32)
        albedo_table, coverage_table = np.zeros(256, np.float32), np.ones(256, np.float32)
        albedo_table[1:4], albedo_table[0], coverage_table[0] = levels[1:], 0.0, 0.0
        if sigma == 0.67:     # levels a scale of the labels (the board's): multiplied, not looked up
            albedo_table[:4] = np.arange(4, dtype=np.float32) * levels[1]
        step = _scale_of(albedo_table[:4])
        assert (step is not None) == (sigma == 0.67)
        albedo, alpha = albedo_table[labels], (labels > 0).astype(np.float32)
        scratch = [np.empty((128 + 2 * reach, 400), np.float32) for _ in range(2)]
        laid = (labels, (albedo_table, coverage_table, scratch, step), sigma, reach, shade, (30, 0, 430, 400))   # a patch 30 px in
        wall = rng.random((400, 460), dtype=np.float32)
        expected = wall.copy()
        expected[:, 30:430] = wall[:, 30:430] * (1 - _blur(alpha, sigma)) + shade * _blur(albedo, sigma)
        covered = 0
        for y in range(0, 400, 128):
            rows = Renderer._flat_rows(laid, y, y + 128)
            band = wall[y:y + 128].copy()
            if rows[2] is not None:
                band[:, rows[2][0]:rows[2][1]] = np.nan      # the inside: not the wall's to show
                covered += 1
            Renderer._lay_flat_band(band, y, y + 128, laid, rows)
            # float rounding of the same sum in another order (the whole blur of an opaque
            # inside sums the kernel's weights to 1 within 1e-7)
            assert np.allclose(band, expected[y:y + 128], rtol=0, atol=1e-6), (sigma, y)
        assert covered >= 2


def test_a_still_board_is_rendered_once_and_a_moved_one_anew():
    from spacearm.firmware_sim.camera.renderer import FlatLayer
    from spacearm.firmware_sim.camera.simulator import CameraSimulator
    from tests.vision.views import view

    sim = CameraSimulator.from_configs(scene_seed=0, noise_seed=1)
    board, cam, gain = load_board(), sim.camera, sim.sensor.electrons_per_unit

    def layers(distance):
        T = xyz_rpy_to_transform([-0.1, -0.07, distance], [0.1, -0.1, 0.0])
        margin = sim.renderer.flat_margin(distance)
        labels, levels, origin = board_patch(T, board, cam.K, cam.dist, (cam.width, cam.height), margin)
        return [FlatLayer(labels, levels, distance, origin, margin)]

    still, marker = layers(0.4), view(0.7, 0.2, 1.0)
    first = sim.renderer.render(sim.scene, marker, still, gain=gain).copy()
    again = sim.renderer.render(sim.scene, marker, still, gain=gain)
    kept = sim.renderer.render(sim.scene, marker, still, gain=gain)
    assert np.array_equal(first, again) and kept is again and not kept.flags.writeable
    moved = sim.renderer.render(sim.scene, marker, layers(0.45), gain=gain)
    assert moved.flags.writeable and np.abs(moved - first).max() > 0.1 * first.max()
    # the same pose, the board drawn anew (new layers): rendered anew, the same image
    assert np.array_equal(sim.renderer.render(sim.scene, marker, layers(0.4), gain=gain), first)


def test_frames_exposed_band_by_band_as_rendered_are_the_whole_image_exposed():
    """The camera's frames (each band exposed as it is composited) against the renderer's whole irradiance image exposed whole, on poses the
    renderer's shortcuts were not written for: near and far, tilted, off centre, a board in view
    or not, the marker out of view, and an arm at rest (the kept image)."""
    from spacearm.firmware_sim.camera.renderer import FlatLayer
    from spacearm.firmware_sim.camera.simulator import CameraSimulator
    from tests.vision.views import view

    fused, whole = (CameraSimulator.from_configs(scene_seed=2, noise_seed=SEED) for _ in range(2))
    board, cam = load_board(), fused.camera
    rng = np.random.default_rng(SEED + 7)
    for i in range(10):
        pose = view(rng.uniform(0.15, 1.3), np.radians(rng.uniform(0, 35)), rng.uniform(0, 2 * np.pi),
                    tuple(rng.uniform(-0.06, 0.06, 2)) if i != 6 else (1.5, 0.0))     # 6: the marker out of view
        layers = []
        if i % 2:
            d = rng.uniform(0.25, 0.7)
            T = xyz_rpy_to_transform(list(rng.uniform([-0.25, -0.2, d], [0.05, 0.05, d])), list(rng.uniform(-0.4, 0.4, 3)))
            margin = fused.renderer.flat_margin(d)
            patch = board_patch(T, board, cam.K, cam.dist, (cam.width, cam.height), margin)
            layers = [] if patch is None else [FlatLayer(patch[0], patch[1], d, patch[2], margin)]
        for _ in range(3 if i == 4 else 1):          # once: the same pose thrice (rendered, kept, given again)
            got = fused.image(pose, layers)
            electrons = whole.renderer.render(whole.scene, pose, layers, gain=whole.sensor.electrons_per_unit)
            assert np.array_equal(got, whole.sensor.expose_electrons(electrons, whole.rng)), i


def test_a_foreground_laid_skipping_its_opaque_inside_is_the_whole_blur_composite():
    """A sharp foreground (full resolution) over a half-resolution wall: the composite, which
    neither blurs the transparency nor lays it inside the opaque plate, is the plain
    formula light * (wall * blur(transparency) + blur(albedo)) of whole-image operations."""
    rng = np.random.default_rng(SEED + 1)
    height, width = 512, 640
    wall = (rng.random((height // 2, width // 2)) * 255).astype(np.uint8)
    light = (1 + rng.random((height, width))).astype(np.float32)
    for sigma in (0.3, 0.9):
        clear = np.ones((420, 500), np.float32)
        top, left = int(rng.integers(5, 40)), int(rng.integers(5, 40))
        clear[top:400, left:480] = 0.0                           # the opaque plate
        clear[top - 1, left:480] = rng.random(480 - left)          # an anti-aliased edge
        clear[300:330, 100:140] = 0.5                             # a see-through detail inside
        albedo = (1 - clear) * rng.random((420, 500)).astype(np.float32)
        x0, y0 = 60, 40
        got = Renderer._composite((wall, True), light, ((albedo, clear), (x0, y0), 1, sigma))
        under = _twice(np.multiply(wall, np.float32(1.0 / 255.0), dtype=np.float32))
        region = under[y0:y0 + 420, x0:x0 + 500]
        region[:] = region * _blur(clear, sigma) + _blur(albedo, sigma)
        assert np.array_equal(got, under * light), sigma


def test_a_board_frame_is_the_whole_image_formulas_of_the_board_drawn_as_before():
    """The camera's frame of a board (the marker out of view), made of labels, blurred by a
    filter on them, laid band by band and not over the wall it hides, against whole-image
    operations on the board drawn the old way (float planes, square by square): the lit wall
    upsampled, times one minus the blurred coverage, plus the shade times the blurred albedo.
    The irradiance agrees to float rounding; the 8-bit frames (the same noise) differ by at
    most 1 DN in a few pixels of a million (the filter sums the same terms in another order)."""
    from spacearm.firmware_sim.camera.renderer import MAX_BLUR, FlatLayer
    from spacearm.firmware_sim.camera.simulator import CameraSimulator
    from tests.vision.views import view

    sim = CameraSimulator.from_configs(scene_seed=1, noise_seed=SEED)
    renderer, cam, board, scene = sim.renderer, sim.camera, load_board(), sim.scene
    gain = sim.sensor.electrons_per_unit
    rng = np.random.default_rng(SEED + 11)
    for _ in range(3):
        d = rng.uniform(0.3, 0.8)            # in focus to blurred (0.3-1.2 px)
        T = xyz_rpy_to_transform(list(rng.uniform([-0.2, -0.15, d], [0.0, 0.0, d])), list(rng.uniform(-0.4, 0.4, 3)))
        pose = view(rng.uniform(0.5, 1.2), 0.1, rng.uniform(0, 2 * np.pi), (1.5, 0.0))   # the marker out of view
        margin = renderer.flat_margin(d)
        labels, levels, origin = board_patch(T, board, cam.K, cam.dist, (cam.width, cam.height), margin)
        layers = [FlatLayer(labels, levels, d, origin, margin)]
        got = renderer.render(scene, pose, layers, gain=gain)

        albedo, alpha = _board_square_by_square(T, board, camera=cam)
        sigma = min(renderer.coc_sigma_px(d), MAX_BLUR)
        wall_sigma = min(renderer.coc_sigma_px(max(renderer._wall_axis_depth(scene, pose), 0.01)), MAX_BLUR)
        wall, halved = renderer._background(scene, pose, wall_sigma)
        wall = np.multiply(wall, np.float32(1.0 / 255.0), dtype=np.float32)
        wall = _twice(wall) if halved else wall
        shade = renderer._wall_shade(scene)
        expected = (wall * (1 - _blur(alpha, sigma)) + np.float32(shade) * _blur(albedo, sigma)) * gain * \
            renderer._illumination(scene)
        assert np.allclose(got, expected, rtol=2e-6, atol=1e-3)
        noisy = [sim.sensor.expose_electrons(image.copy(), np.random.default_rng(SEED + 3)) for image in (got, expected)]
        differ = noisy[0].astype(int) - noisy[1]
        assert np.abs(differ).max() <= 1 and np.count_nonzero(differ) < 1e-4 * differ.size
