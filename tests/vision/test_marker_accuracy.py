"""Marker pose from rendered frames (clutter, uneven light, distortion, blur, sensor noise)
against the renderer's ground truth, by distance and viewing angle.

Thresholds sit above what the pipeline measured here (bench/bench_vision.py prints the
figures) and at or below the issue's targets: 0.3 mm / 0.1 deg at 200 mm, 1 mm / 0.3 deg at
300 mm, detection at 1.5 m."""
from __future__ import annotations

import numpy as np
import pytest

from tests.vision.views import pose_error, view

# distance m -> (position m, rotation rad) allowed, views (tilt deg, azimuth deg)
CASES = {
    0.15: (0.15e-3, np.radians(0.05), [(0, 0), (20, 60), (35, 200)]),
    0.20: (0.15e-3, np.radians(0.05), [(0, 0), (20, 120), (35, 300)]),
    0.30: (0.20e-3, np.radians(0.08), [(0, 0), (20, 30), (35, 250)]),
    0.50: (0.30e-3, np.radians(0.10), [(0, 0), (25, 90)]),
    0.80: (0.50e-3, np.radians(0.15), [(0, 0), (25, 180)]),
    1.00: (0.80e-3, np.radians(0.20), [(0, 0), (25, 270)]),
    1.50: (2.00e-3, np.radians(0.30), [(0, 0), (15, 45)]),
}


@pytest.mark.parametrize("distance", sorted(CASES))
def test_marker_pose_within_tolerance_by_distance_and_angle(pipeline, camera, distance):
    tol_pos, tol_rot, views = CASES[distance]
    for tilt, azimuth in views:
        truth = view(distance, np.radians(tilt), np.radians(azimuth))
        result = pipeline.process(camera.render(truth))
        assert result.ok, f"{distance} m, tilt {tilt} deg: {result.reason}: {result.message}"
        pos, rot = pose_error(result.camera_T_marker, truth)
        assert pos <= tol_pos and rot <= tol_rot, \
            f"{distance} m, tilt {tilt} deg: {pos * 1e3:.3f} mm / {np.degrees(rot):.3f} deg"


def test_marker_off_centre_in_the_image_is_measured(pipeline, camera):
    # near the image corner: distortion and the ellipse-centre correction matter most there
    truth = view(0.3, np.radians(15), 0.5, offset=(0.06, 0.045))
    result = pipeline.process(camera.render(truth))
    assert result.ok, result.message
    pos, rot = pose_error(result.camera_T_marker, truth)
    assert pos <= 0.2e-3 and rot <= np.radians(0.08)


def test_tracking_with_a_prior_gives_the_same_pose(pipeline, camera):
    truth = view(0.25, np.radians(10), 1.0)
    frame = camera.render(truth)
    full = pipeline.process(frame)
    prior = truth.copy()
    prior[:3, 3] += (0.004, -0.003, 0.005)                     # last frame's pose, arm moved since
    tracked = pipeline.process(frame, prior)
    assert full.ok and tracked.ok
    pos, rot = pose_error(tracked.camera_T_marker, full.camera_T_marker)
    # the same circles measured through other windows: equal to rounding and the noise on the
    # window edges (up to 2.3e-6 rad over noise seeds 1-5, with either renderer), far below the
    # 0.05 deg (8.7e-4 rad) the poses are held to
    assert pos < 1e-6 and rot < 1e-5
