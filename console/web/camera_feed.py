"""Camera monitor: the newest eye-in-hand frame from the shared-memory ring
(base/vision/frames.py) with the marker found by the controller's own vision pipeline
(controller/vision/pipeline.py) drawn on it: the identified circle centres, the marker axes
from the PnP pose, distance and reprojection error, or the reason no marker was found.

Runs only when a page asks (a few times a second, in the web server's worker threads): it
reads the ring without blocking its writer and never touches the daemon or its cycle.
"""
from __future__ import annotations

import threading
from typing import Any

import cv2
import numpy as np

MONITOR_WIDTH = 680   # px of the image sent to the page (half the GC1380H's 1360)
AXIS_LENGTH = 0.03    # m, marker axes drawn from the estimated pose


class CameraFeed:
    def __init__(self, ring_name: str, attach_timeout: float = 5.0, ring: Any = None):
        from spacearm.base.vision.frames import ShmFrameRing
        from spacearm.controller.vision.pipeline import VisionPipeline
        self.ring_name = ring_name
        self.ring = ring if ring is not None else ShmFrameRing.attach(ring_name, timeout=attach_timeout)
        self.pipeline = VisionPipeline.from_configs()
        self._lock = threading.Lock()            # one frame processed at a time, whoever asks
        self._cached: tuple[int, bytes] | None = None
        self.last_result: Any = None

    def describe(self) -> dict[str, Any]:
        return {"ring": self.ring_name, "width": self.ring.width, "height": self.ring.height}

    def latest_frame_png(self) -> tuple[int, bytes] | None:
        """(frame number, PNG) of the newest frame, or None before the first."""
        with self._lock:
            frame = self.ring.latest()
            if frame is None:
                return None
            if self._cached is not None and self._cached[0] == frame.seq:
                return self._cached
            result = self.pipeline.process(frame)
            self.last_result = result
            image = cv2.cvtColor(frame.image, cv2.COLOR_GRAY2BGR)
            self._overlay(image, result)
            scale = MONITOR_WIDTH / image.shape[1]
            if scale < 1.0:
                image = cv2.resize(image, None, fx=scale, fy=scale, interpolation=cv2.INTER_AREA)
            cv2.putText(image, self._caption(frame.seq, result), (8, 22), cv2.FONT_HERSHEY_SIMPLEX,
                        0.55, (0, 255, 0) if result.ok else (0, 80, 255), 1, cv2.LINE_AA)
            ok, png = cv2.imencode(".png", image)
            if not ok:
                return None
            self._cached = (frame.seq, png.tobytes())
            return self._cached

    def _overlay(self, image: np.ndarray, result: Any) -> None:
        if not result.ok:
            return
        for name, centre in zip(self.pipeline.marker.names, result.centres_px):
            c = tuple(int(round(v)) for v in centre)
            cv2.circle(image, c, 14, (0, 200, 255), 2, cv2.LINE_AA)
            cv2.putText(image, name, (c[0] + 16, c[1] - 10), cv2.FONT_HERSHEY_SIMPLEX, 0.9, (0, 200, 255), 2)
        T = result.camera_T_marker
        axes = np.array([[0, 0, 0], [AXIS_LENGTH, 0, 0], [0, AXIS_LENGTH, 0], [0, 0, AXIS_LENGTH]], float)
        uv = self.pipeline.camera.project((T[:3, :3] @ axes.T).T + T[:3, 3])
        origin = tuple(int(round(v)) for v in uv[0])
        for tip, colour in zip(uv[1:], ((0, 0, 255), (0, 255, 0), (255, 0, 0))):
            cv2.line(image, origin, tuple(int(round(v)) for v in tip), colour, 3, cv2.LINE_AA)

    @staticmethod
    def _caption(seq: int, result: Any) -> str:
        if result.ok:
            return (f"frame {seq}  marker at {1e3 * result.distance:.0f} mm  rms {result.rms_px:.2f} px  "
                    f"{1e3 * result.processing_time:.0f} ms")
        return f"frame {seq}  no marker: {result.reason}"

    def close(self) -> None:
        self.ring.close()
