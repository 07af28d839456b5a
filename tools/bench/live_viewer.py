"""A Foxglove WebSocket viewer for benchmarks (foxglove.websocket.v1, the `websockets` package, not
our code). One process for a whole benchmark, steered by commands on stdin, one a line, each
answered by one line on stdout (and `started` once it is up):

  connect [U]  unless still connected: connect to U, or else URL (retrying until it is up, at most
               20 s), subscribe to every advertised channel, and answer `ready` once a message of
               every subscribed channel that sends at ~60 Hz (/tf, /scene) has arrived: its steady
               state from then
  disconnect   close the connection; answer `closed`
  quit         (or the end of stdin) print one JSON line, messages and bytes received per topic
               over every connection, and exit

Between `connect` and `disconnect` it takes every message and decodes nothing but the frame
headers. Its start-up (the interpreter, imports) happens once, before any measured window: a viewer
that a researcher keeps open costs what it costs connected, not what starting Python costs.

usage: live_viewer.py URL | @FILE
  @FILE: the newest ws:// address in FILE (a station's log), read again at each attempt to connect:
  a network process the supervisor restarted serves on a new port
"""
import asyncio
import json
import re
import struct
import sys
import time

import websockets

STEADY = {"/tf", "/scene"}


class Viewer:
    def __init__(self, url):
        self.url = url
        self.counts, self.sizes = {}, {}
        self.ws = None
        self.pump = None

    async def connect(self, url=None):
        if self.pump is not None and not self.pump.done():
            return  # still connected and taking every message
        self.url = url or self.url
        deadline = time.monotonic() + 20
        while True:
            try:
                self.ws = await websockets.connect(
                    self.address(), subprotocols=["foxglove.websocket.v1"], max_size=None
                )
                break
            except (OSError, LookupError):
                if time.monotonic() > deadline:
                    raise
                await asyncio.sleep(0.05)
        ready = asyncio.get_running_loop().create_future()
        self.pump = asyncio.create_task(self.take(self.ws, ready))
        await asyncio.wait_for(ready, 20)

    def address(self):
        if not self.url.startswith("@"):
            return self.url
        with open(self.url[1:]) as f:
            found = re.findall(r"ws://[0-9.:]+", f.read())
        if not found:
            raise LookupError(f"no ws:// address in {self.url[1:]} yet")
        return found[-1]

    async def take(self, ws, ready):
        topics, seen = {}, set()
        try:
            async for raw in ws:
                if isinstance(raw, str):
                    msg = json.loads(raw)
                    if msg.get("op") == "advertise":
                        subs = []
                        for c in msg["channels"]:
                            topics[c["id"]] = c["topic"]
                            subs.append({"id": c["id"], "channelId": c["id"]})
                        await ws.send(json.dumps({"op": "subscribe", "subscriptions": subs}))
                    continue
                if raw[0] == 0x01:
                    sub, _ = struct.unpack_from("<IQ", raw, 1)
                    t = topics.get(sub, str(sub))
                    self.counts[t] = self.counts.get(t, 0) + 1
                    self.sizes[t] = self.sizes.get(t, 0) + len(raw)
                    if not ready.done():
                        seen.add(t)
                        if STEADY <= seen:
                            ready.set_result(None)
        except websockets.ConnectionClosed:
            pass  # the station stopped
        if not ready.done():
            ready.set_exception(ConnectionError("closed before every channel sent"))

    async def disconnect(self):
        if self.ws is not None:
            await self.ws.close()
            await self.pump
        self.ws = self.pump = None


async def main(url):
    loop = asyncio.get_running_loop()
    stdin = asyncio.StreamReader()
    await loop.connect_read_pipe(lambda: asyncio.StreamReaderProtocol(stdin), sys.stdin)
    v = Viewer(url)

    def answer(text):
        sys.stdout.write(text + "\n")
        sys.stdout.flush()

    answer("started")  # imports done: nothing of the start-up is left for a measured window
    while True:
        line = (await stdin.readline()).decode().strip()
        if line.split()[:1] == ["connect"]:
            await v.connect(*line.split()[1:2])
            answer("ready")
        elif line == "disconnect":
            await v.disconnect()
            answer("closed")
        elif line in ("quit", ""):
            await v.disconnect()
            answer(json.dumps({"messages": v.counts, "bytes": v.sizes}))
            return
        else:
            answer(f"unknown command {line!r}")


asyncio.run(main(sys.argv[1]))
