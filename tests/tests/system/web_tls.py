"""`scout web` over TLS: the page over https, its WebSocket over wss with the right token and
origin, refusals over wss, and nothing served in clear on the TLS port.

Usage: web_tls.py HOST:PORT TOKEN FINGERPRINT
"""

import asyncio
import hashlib
import json
import socket
import ssl
import sys
import urllib.request

import websockets

HOST, TOKEN, FINGERPRINT = sys.argv[1:4]
context = ssl.create_default_context()
context.check_hostname = False
context.verify_mode = ssl.CERT_NONE

# The certificate served is the one whose fingerprint was printed.
with socket.create_connection(HOST.rsplit(":", 1)) as raw:
    with context.wrap_socket(raw) as tls:
        der = tls.getpeercert(binary_form=True)
seen = ":".join(f"{b:02X}" for b in hashlib.sha256(der).digest())
assert seen == FINGERPRINT, (seen, FINGERPRINT)

page = urllib.request.urlopen(f"https://{HOST}/", context=context, timeout=10).read().decode()
assert 'id="estop"' in page, page[:200]

# In clear, the TLS port serves nothing.
with socket.create_connection(HOST.rsplit(":", 1), timeout=10) as raw:
    raw.sendall(b"GET / HTTP/1.1\r\nHost: x\r\n\r\n")
    try:
        answer = raw.recv(4096)
    except (ConnectionResetError, socket.timeout):
        answer = b""
    assert b"estop" not in answer, answer[:200]


async def main():
    origin = f"https://{HOST}"
    async with websockets.connect(f"wss://{HOST}/ws?token={TOKEN}", origin=origin, ssl=context) as ws:
        hello = json.loads(await ws.recv())
        assert hello["type"] == "hello" and hello["client"] == "web:operator", hello
    # A foreign origin is refused before the upgrade.
    try:
        async with websockets.connect(f"wss://{HOST}/ws?token={TOKEN}", origin=f"http://{HOST}", ssl=context):
            raise AssertionError("admitted from a foreign origin")
    except websockets.exceptions.InvalidStatus as refused:
        assert refused.response.status_code == 403, refused
    # A wrong token is told by the close code, which a page's script can see, and nothing else.
    async with websockets.connect(f"wss://{HOST}/ws?token=wrong-token-0123456789", origin=origin, ssl=context) as ws:
        try:
            message = await asyncio.wait_for(ws.recv(), 10)
            raise AssertionError(f"a wrong token was sent {message!r}")
        except websockets.exceptions.ConnectionClosed as closed:
            assert closed.rcvd is not None and closed.rcvd.code == 4401, closed


asyncio.run(main())
print("ok")
