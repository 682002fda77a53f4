"""`spacearm console-web`: the operator console in the browser (3-D scene, presimulation,
live state, camera monitor), served on 127.0.0.1 as one more client of the daemon."""
from __future__ import annotations

import asyncio
from pathlib import Path

import typer

from spacearm.console.client import DEFAULT_API, ApiClient
from spacearm.console.errors import BadInput, CommandFailed, friendly_errors
from spacearm.base.transport.hub import is_loopback
from spacearm.base.config.arm import load_arm_config
from spacearm.base.config.scene import DEFAULT_SCENE
from spacearm.base.kinematics.model import KinematicModel


def register(app: typer.Typer) -> None:
    @app.command("console-web")
    @friendly_errors
    def console_web(
            connect: str = typer.Option(DEFAULT_API, "--connect", envvar="SPACEARM_API",
                                        help="Daemon API address (tcp:HOST:PORT or unix:PATH)."),
            token: str = typer.Option(None, "--token", envvar="SPACEARM_TOKEN", help="API token, when the daemon is exposed."),
            port: int = typer.Option(8740, "--port", min=0, max=65535, help="Web port (0: any free port)."),
            host: str = typer.Option("127.0.0.1", "--host", help="Web address; loopback only."),
            arm: Path = typer.Option(Path("configs/arm/oru_testbed_6dof.toml"), "--arm",
                                     help="The daemon's arm file (kinematics for the scene and presimulation)."),
            scene: Path = typer.Option(DEFAULT_SCENE, "--scene", help="Cell file: ORU stores and ORUs."),
            camera: str = typer.Option(None, "--camera", help="Shared-memory frame ring of the eye-in-hand camera."),
    ) -> None:
        """Serve the browser console: 3-D scene with presimulation, live state, stop/reset, camera."""
        from spacearm.console.web.scene_model import load_scene_description
        from spacearm.console.web.server import WebOptions, serve

        if not is_loopback(host):
            # The page carries the operator's control lease; it is not for other machines.
            raise BadInput(f"--host {host}: the web console listens on loopback only (127.0.0.1 or ::1; "
                           "use an SSH tunnel to reach it from elsewhere)", "bad_argument")
        arm_config = load_arm_config(arm)
        model = KinematicModel.from_config(arm_config)
        with ApiClient(connect, token) as client:
            status = client.call("status")
        if status.get("arm") not in (None, model.name):
            raise CommandFailed(f"the daemon flies arm {status['arm']!r} but --arm {arm} is {model.name!r}; "
                                "presimulation needs the daemon's arm file")
        camera_feed = None
        if camera:
            from spacearm.console.web.camera_feed import CameraFeed
            try:
                camera_feed = CameraFeed(camera)
            except (OSError, ValueError, TimeoutError) as exc:
                raise CommandFailed(f"camera ring {camera!r}: {exc}") from None
        options = WebOptions(api=connect, token=token, model=model,
                             scene={**load_scene_description(scene, model),
                                    # the postures `move joints NAME` knows, for the page's presets
                                    "postures": {"home": [j.home for j in arm_config.joints],
                                                 **arm_config.postures}},
                             period=float(status.get("period") or 0.02), host=host, port=port,
                             camera=camera_feed)
        try:
            asyncio.run(serve(options))
        except KeyboardInterrupt:
            pass
        except OSError as exc:
            raise CommandFailed(f"cannot serve on {host}:{port}: {exc}") from None
