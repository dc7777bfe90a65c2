"""The web side of ``surge watch``: the page and its assets from the package, the map as JSON, frames over a websocket.

Starlette serves, uvicorn runs it; nothing is fetched from elsewhere, so the
page works on a host with no internet.  A live feed pushes its newest frame
whenever it changes; a replay keeps one cursor per browser tab and moves it
on the tab's ``play``, ``pause``, ``step``, ``back``, ``seek N`` and
``speed X`` commands.
"""

from __future__ import annotations

import asyncio
import json
from pathlib import Path
from typing import Any

from coordinator.watch.live import LiveFeed
from coordinator.watch.replay import Replay

STATIC = Path(__file__).with_name("static")
#: Frames a second a replay plays at speed 1.
REPLAY_FPS = 4.0


def frame_message(index: int, count: int, playing: bool, frame: str) -> str:
    """One websocket message: the frame (already JSON) and where the player stands."""
    return f'{{"index":{index},"count":{count},"playing":{json.dumps(playing)},"frame":{frame}}}'


async def _live(ws: Any, feed: LiveFeed) -> None:
    from starlette.websockets import WebSocketDisconnect

    sent = -1
    receiver = asyncio.ensure_future(ws.receive_text())
    try:
        while True:
            version, text = feed.latest()
            if version != sent:
                await ws.send_text(frame_message(version, version + 1, True, text))
                sent = version
            done, _ = await asyncio.wait({receiver}, timeout=0.1)
            if done:
                receiver.result()  # a live view takes no commands; a closed tab raises here
                receiver = asyncio.ensure_future(ws.receive_text())
    except WebSocketDisconnect:
        pass
    finally:
        receiver.cancel()


async def _replay(ws: Any, replay: Replay) -> None:
    from starlette.websockets import WebSocketDisconnect

    n, ends = len(replay.frames), replay.minute_ends
    cursor, playing, speed = 0, False, 1.0
    try:
        while True:
            await ws.send_text(frame_message(cursor, n, playing, replay.frames[cursor]))
            try:
                timeout = 1.0 / (REPLAY_FPS * speed) if playing else None
                command = (await asyncio.wait_for(ws.receive_text(), timeout)).split()
            except TimeoutError:
                cursor = min(cursor + 1, n - 1)
                playing = cursor < n - 1
                continue
            verb, arg = command[0] if command else "", command[1] if len(command) > 1 else ""
            if verb == "play":
                playing = True
                cursor = 0 if cursor >= n - 1 else cursor
            elif verb == "pause":
                playing = False
            elif verb == "step":
                playing, cursor = False, next((e for e in ends if e > cursor), n - 1)
            elif verb == "back":
                playing, cursor = False, next((e for e in reversed(ends) if e < cursor), 0)
            elif verb == "seek" and arg.lstrip("-").isdigit():
                cursor = max(0, min(n - 1, int(arg)))
            elif verb == "speed":
                try:
                    speed = min(64.0, max(0.25, float(arg)))
                except ValueError:
                    pass
    except WebSocketDisconnect:
        pass


def make_app(feed: LiveFeed | Replay, title: str) -> Any:
    """The starlette application for a live feed or a replay."""
    from starlette.applications import Starlette
    from starlette.responses import FileResponse, JSONResponse
    from starlette.routing import Mount, Route, WebSocketRoute
    from starlette.staticfiles import StaticFiles

    mode = "replay" if isinstance(feed, Replay) else "live"

    async def index(request: Any) -> Any:
        return FileResponse(STATIC / "index.html")

    async def city(request: Any) -> Any:
        if feed.map is None:
            return JSONResponse({"error": "the run's city is not known yet"}, status_code=503)
        return JSONResponse({"mode": mode, "title": title, "run": feed.summary, **feed.map})

    async def frames(ws: Any) -> None:
        await ws.accept()
        if isinstance(feed, Replay):
            await _replay(ws, feed)
        else:
            await _live(ws, feed)

    return Starlette(routes=[
        Route("/", index),
        Route("/api/map", city),
        WebSocketRoute("/ws", frames),
        Mount("/static", app=StaticFiles(directory=STATIC), name="static"),
    ])
