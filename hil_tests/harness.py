"""What the HIL tests and the benchmarks that drive the same process stacks share."""
from __future__ import annotations

import os
import socket

CHROMIUM = os.environ.get("SPACEARM_CHROMIUM", "/usr/bin/chromium")
# No GPU here: WebGL on SwiftShader, but the page itself rastered and composited by Skia on
# the CPU (rastering it through SwiftShader costs about 3x the CPU, measured).
CHROMIUM_ARGS = ["--use-gl=angle", "--use-angle=swiftshader", "--enable-unsafe-swiftshader",
                 "--ignore-gpu-blocklist", "--disable-gpu-rasterization", "--disable-gpu-compositing"]


def free_port() -> int:
    """A TCP port on the loopback interface that nothing listens on right now."""
    with socket.socket() as sock:
        sock.bind(("127.0.0.1", 0))
        return sock.getsockname()[1]
