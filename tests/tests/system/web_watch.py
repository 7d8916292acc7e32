"""Watches `scout web` as a page does: prints the type of each message it is sent (`state`,
`status`, `silent`, ...), one a line, until killed.

Usage: web_watch.py HOST:PORT TOKEN
"""

import asyncio
import json
import sys

import websockets

HOST, TOKEN = sys.argv[1:3]


async def main():
    async with websockets.connect(f"ws://{HOST}/ws?token={TOKEN}", origin=f"http://{HOST}") as ws:
        async for message in ws:
            print(json.loads(message)["type"], flush=True)


asyncio.run(main())
