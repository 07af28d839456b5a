"""A Foxglove WebSocket viewer for benchmarks (foxglove.websocket.v1, the `websockets` package, not
our code): connects to URL (retrying until it is up, at most SECONDS), subscribes to every
advertised channel, takes and decodes nothing but the frame headers for SECONDS, and prints one
JSON line: messages and bytes received per topic.

usage: live_viewer.py URL SECONDS
"""
import asyncio
import json
import struct
import sys
import time

import websockets


async def main(url, seconds):
    deadline = time.monotonic() + seconds
    counts, sizes, topics = {}, {}, {}
    while True:
        try:
            ws = await websockets.connect(url, subprotocols=["foxglove.websocket.v1"], max_size=None)
            break
        except OSError:
            if time.monotonic() > deadline:
                raise
            await asyncio.sleep(0.05)
    async with ws:
        while time.monotonic() < deadline:
            try:
                raw = await asyncio.wait_for(ws.recv(), timeout=max(0.01, deadline - time.monotonic()))
            except (asyncio.TimeoutError, websockets.ConnectionClosed):
                break  # the window is over, or the station stopped
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
                counts[t] = counts.get(t, 0) + 1
                sizes[t] = sizes.get(t, 0) + len(raw)
    print(json.dumps({"messages": counts, "bytes": sizes}))


asyncio.run(main(sys.argv[1], float(sys.argv[2])))
