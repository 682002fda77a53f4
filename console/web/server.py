"""The browser console's web server: static page, scene, presimulation, and one WebSocket
per page carrying state (pushed) and commands (forwarded to the daemon).

Authority: the server is one more console of the operator who started it. Commands go to
the daemon's command API unchanged, with the operator's control lease taken and kept exactly
as `spacearm move ...` does (console/lease_store.py); the page never sees the lease key and
can send only the console's commands. The daemon validates everything; the server adds
nothing it could bypass. It listens on 127.0.0.1 and accepts only requests addressed to a
loopback host name from a page it served (Host and Origin checks against DNS rebinding and
cross-site requests from other pages in the same browser).
"""
from __future__ import annotations

import asyncio
import json
import logging
import threading
import time
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from aiohttp import WSMsgType, web

from spacearm.console import lease_store
from spacearm.console.client import ApiClient
from spacearm.console.commands.operate import _controlled_call, _take
from spacearm.console.errors import CommandFailed
from spacearm.controller.daemon.api_errors import ErrorCode
from spacearm.console.web.camera_feed import CameraFeed
from spacearm.console.web.presim import Presimulator
from spacearm.console.web.state_feed import StateFeed, StateUpdate
from spacearm.base.kinematics.model import KinematicModel

STATIC_DIR = Path(__file__).resolve().parent / "static"
THREE_DIR = Path("/usr/share/javascript/three")          # Debian libjs-three (scripts/bootstrap.sh)
LOOPBACK_HOSTS = {"127.0.0.1", "localhost", "[::1]"}
MAX_MESSAGE = 64 * 1024
IDLE_INTERVAL = 1.0   # s between state updates to a page while nothing it shows changes

# The console's commands (console/commands/operate.py); True: needs the control lease.
COMMANDS: dict[str, bool] = {"ping": False, "status": False, "stop": False, "enable": True,
                             "disable": True, "reset": True, "jog": True, "move_joints": True,
                             "move_pose": True}

log = logging.getLogger("spacearm.web")


@dataclass
class WebOptions:
    api: str
    token: str | None
    model: KinematicModel
    scene: dict[str, Any]
    period: float = 0.02
    host: str = "127.0.0.1"
    port: int = 8740
    camera: CameraFeed | None = None


@dataclass(eq=False)   # pages are kept in a set by identity
class Page:
    """One open page: its WebSocket, its own API connection (its session at the daemon, so a
    jog stops when the page goes away), and the newest state not yet sent."""
    ws: web.WebSocketResponse
    client: ApiClient | None = None
    lock: threading.Lock = field(default_factory=threading.Lock)   # one API call at a time
    pending: StateUpdate | None = None
    primed: bool = False          # has had one whole status
    shown: tuple = ()             # shown_key of the last update offered
    sent_at: float = 0.0          # monotonic s it was offered
    skipped: bool = False         # updates left out since (nothing visible changed)
    wake: asyncio.Event = field(default_factory=asyncio.Event)


class WebConsole:
    def __init__(self, options: WebOptions):
        self.options = options
        self.feed = StateFeed(options.api, options.token, options.model)
        self.presim = Presimulator(options.model, options.period)
        self.pool = ThreadPoolExecutor(max_workers=4, thread_name_prefix="web-api")
        self.pages: set[Page] = set()
        self.app = web.Application(middlewares=[self._loopback_only], client_max_size=MAX_MESSAGE)
        self.app.add_routes([
            web.get("/", self._index),
            web.get("/api/scene", self._scene),
            web.get("/api/info", self._info),
            web.get("/api/camera.png", self._camera_frame),
            web.get("/ws", self._websocket),
            web.static("/static", STATIC_DIR),
        ])
        if THREE_DIR.is_dir():
            self.app.router.add_static("/vendor/three", THREE_DIR)
        self.app.on_startup.append(self._startup)
        self.app.on_cleanup.append(self._cleanup)

    # ---- life cycle ----------------------------------------------------------------------
    async def _startup(self, app: web.Application) -> None:
        self.loop = asyncio.get_running_loop()
        self.feed.start()
        self.feed.subscribe(self._on_state)

    async def _cleanup(self, app: web.Application) -> None:
        for page in list(self.pages):
            await page.ws.close()
        self.feed.stop()
        self.pool.shutdown(wait=False, cancel_futures=True)

    def _on_state(self, update: StateUpdate) -> None:
        """Feed thread: hand the newest state to every page's sender (latest only)."""
        self.loop.call_soon_threadsafe(self._offer, update)

    def _offer(self, update: StateUpdate) -> None:
        for page in self.pages:
            self._offer_to(page, update)

    @staticmethod
    def _offer_to(page: "Page", update: StateUpdate) -> None:
        """Every cycle while something the page shows changes; while nothing does (an arm at
        rest), one update every IDLE_INTERVAL: each message costs the browser CPU (an idle page
        at 50 messages/s used 10 % of a core in its renderer alone)."""
        now = time.monotonic()
        if page.primed and update.shown == page.shown and now - page.sent_at < IDLE_INTERVAL:
            page.skipped = True
            return
        if not page.primed or page.skipped or page.pending is not None:
            update = update.whole()   # the lean ones it missed may have carried stats or events
        page.skipped = False
        page.shown, page.sent_at = update.shown, now
        page.pending = update
        page.wake.set()

    # ---- security ------------------------------------------------------------------------
    @web.middleware
    async def _loopback_only(self, request: web.Request, handler):
        host = request.host.rsplit(":", 1)[0] if not request.host.startswith("[") else request.host.split("]")[0] + "]"
        if host not in LOOPBACK_HOSTS:
            raise web.HTTPForbidden(text=f"host {request.host!r} refused: the console answers loopback names only")
        origin = request.headers.get("Origin")
        if origin is not None and origin.split("://", 1)[-1] != request.host:
            raise web.HTTPForbidden(text=f"origin {origin!r} refused: only pages this server served may talk to it")
        return await handler(request)

    # ---- plain resources -----------------------------------------------------------------
    async def _index(self, request: web.Request) -> web.StreamResponse:
        return web.FileResponse(STATIC_DIR / "index.html", headers={"Cache-Control": "no-store"})

    async def _scene(self, request: web.Request) -> web.Response:
        return web.json_response({**self.options.scene, "three_available": THREE_DIR.is_dir(),
                                  "camera": self.options.camera.describe() if self.options.camera else None})

    async def _info(self, request: web.Request) -> web.Response:
        return web.json_response({"daemon": self.options.api, "pages": len(self.pages),
                                  "status_polls": self.feed.polls, "state_updates": self.feed.updates, "daemon_error": self.feed.error})

    async def _camera_frame(self, request: web.Request) -> web.Response:
        camera = self.options.camera
        if camera is None:
            raise web.HTTPNotFound(text="no camera")
        frame = await self.loop.run_in_executor(self.pool, camera.latest_frame_png)
        if frame is None:
            raise web.HTTPNotFound(text="no frame yet")
        if request.query.get("after") == str(frame[0]):   # the page has it: no image to decode again
            return web.Response(status=204, headers={"Cache-Control": "no-store", "X-Frame-Seq": str(frame[0])})
        return web.Response(body=frame[1], content_type="image/png",
                            headers={"Cache-Control": "no-store", "X-Frame-Seq": str(frame[0])})

    # ---- the page's WebSocket --------------------------------------------------------------
    async def _websocket(self, request: web.Request) -> web.WebSocketResponse:
        ws = web.WebSocketResponse(heartbeat=10.0, max_msg_size=MAX_MESSAGE)
        await ws.prepare(request)
        page = Page(ws)
        self.pages.add(page)
        if self.feed.latest is not None:
            self._offer_to(page, self.feed.latest)
        sender = asyncio.create_task(self._send_states(page))
        try:
            async for msg in ws:
                if msg.type != WSMsgType.TEXT:
                    continue
                asyncio.create_task(self._answer(page, msg.data))
        finally:
            self.pages.discard(page)
            sender.cancel()
            if page.client is not None:
                client, page.client = page.client, None
                await self.loop.run_in_executor(self.pool, client.close)
        return ws

    async def _send_states(self, page: Page) -> None:
        while not page.ws.closed:
            await page.wake.wait()
            page.wake.clear()
            update, page.pending = page.pending, None
            if update is None:
                continue
            try:
                await page.ws.send_str(update.text)
            except (ConnectionError, RuntimeError):
                return
            page.primed = True

    async def _answer(self, page: Page, text: str) -> None:
        try:
            request = json.loads(text)
            if not isinstance(request, dict):
                raise ValueError("message must be a JSON object")
        except ValueError as exc:
            await self._reply(page, None, error=f"bad message: {exc}")
            return
        op, request_id = request.get("op"), request.get("id")
        cmd, args = request.get("cmd"), request.get("args") or {}
        if not isinstance(args, dict):
            await self._reply(page, request_id, error="args must be a JSON object")
            return
        if op == "presim":
            status = self.feed.latest.status if self.feed.latest else None
            result = await self.loop.run_in_executor(self.pool, self.presim.run, cmd, args, status)
            await self._send(page, {**result.as_dict(), "id": request_id})
        elif op == "command":
            try:
                result = await self.loop.run_in_executor(self.pool, self._forward, page, cmd, args)
            except CommandFailed as exc:
                await self._reply(page, request_id, error=str(exc))
                return
            await self._reply(page, request_id, result=result)
        elif op == "clock":   # the page measures its state latency against this clock (app.js)
            await self._send(page, {"type": "clock", "id": request_id, "monotonic": time.monotonic()})
        elif op == "keepalive":   # a jog lives while its page is heard from (daemon watchdog)
            try:
                await self.loop.run_in_executor(self.pool, self._forward, page, "ping", {})
            except CommandFailed:
                pass
        else:
            await self._reply(page, request_id, error=f"unknown op {op!r}")

    def _forward(self, page: Page, cmd: Any, args: dict[str, Any]) -> Any:
        """API thread: the console's command, with the operator's lease where it needs one."""
        with page.lock:
            try:
                return self._forward_locked(page, cmd, args)
            except CommandFailed as exc:
                if exc.code == ErrorCode.NO_CONNECTION and page.client is not None:
                    page.client.close()      # the daemon went away: reconnect on the next command
                    page.client = None
                raise

    def _forward_locked(self, page: Page, cmd: Any, args: dict[str, Any]) -> Any:
        if cmd in ("control.take", "control.release"):
            return self._control(page, cmd)
        if cmd not in COMMANDS:
            raise CommandFailed(f"unknown command {cmd!r}; the page may send: {', '.join(sorted(COMMANDS))}")
        args = {k: v for k, v in args.items() if k != "lease"}   # the page never supplies a lease
        client = self._client(page)
        if COMMANDS[cmd]:
            return _controlled_call(client, cmd, session=self._session_name(page), **args)
        return client.call(cmd, **args)

    def _control(self, page: Page, cmd: str) -> dict[str, Any]:
        client = self._client(page)
        if cmd == "control.take":
            _take(client, session=self._session_name(page))
            return {"control": "taken"}
        key = lease_store.load(client.address)
        if key is None:
            raise CommandFailed("this console holds no control lease")
        client.call("control.release", lease=key)
        lease_store.forget(client.address)
        return {"control": "released"}

    def _session_name(self, page: Page) -> str:
        return f"web console :{self.options.port} page {id(page):x}"

    def _client(self, page: Page) -> ApiClient:
        if page.client is None:
            page.client = ApiClient(self.options.api, self.options.token)
        return page.client

    async def _reply(self, page: Page, request_id: Any, result: Any = None, error: str | None = None) -> None:
        message: dict[str, Any] = {"type": "reply", "id": request_id, "ok": error is None}
        message["result" if error is None else "error"] = result if error is None else error
        await self._send(page, message)

    @staticmethod
    async def _send(page: Page, message: dict[str, Any]) -> None:
        if not page.ws.closed:
            await page.ws.send_str(json.dumps(message))


async def serve(options: WebOptions) -> None:
    """Run until cancelled; prints the page address once listening."""
    console = WebConsole(options)
    runner = web.AppRunner(console.app, access_log=None)
    await runner.setup()
    site = web.TCPSite(runner, options.host, options.port)
    await site.start()
    port = runner.addresses[0][1]
    print(f"console-web: http://{options.host}:{port}/ (daemon {options.api})", flush=True)
    try:
        await asyncio.Event().wait()
    finally:
        await runner.cleanup()
