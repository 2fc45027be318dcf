"""A jailed worker that runs the Python source it is sent: the jail's own tests try with it what a
script inside could do (``tests/test_jail.py``).

Only the user's process can send it anything, and what it runs is confined like any
worker, so it opens nothing the jail does not already allow; no product code starts it.
Started like :mod:`envs.jail_worker` (forked by a zygote, or ``python -m
scenario_bank.jail.probe IN_FD OUT_FD`` inside bubblewrap), it answers ``{"op": "run",
"code": SOURCE}`` with the value ``SOURCE`` leaves in the variable ``result`` (data only,
:mod:`.wire`), and ``exit``.
"""

from __future__ import annotations

import os
import sys
import time
from typing import List

from scenario_bank.jail import wire

__all__ = ["preload", "serve", "main"]


def preload() -> None:
    """Nothing to import ahead: the probe needs only the standard library and the wire format."""


def serve(inbound_fd: int, outbound_fd: int, started: float) -> int:
    """Say hello, then run each request's code; the exit status."""
    inbound = os.fdopen(inbound_fd, "rb", buffering=0)
    outbound = os.fdopen(outbound_fd, "wb", buffering=0)
    wire.write_message(outbound, {"ok": True, "value": {"import_seconds": time.perf_counter() - started}})
    while True:
        try:
            request = wire.read_message(inbound, 2**20)
        except EOFError:
            return 0
        if not isinstance(request, dict) or request.get("op") != "run":
            return 0
        namespace: dict = {"outbound_fd": outbound_fd}  # so a test can write raw bytes to the user's process
        try:
            exec(str(request.get("code", "")), namespace)  # noqa: S102  (the point of the probe, inside the jail)
            reply = {"ok": True, "value": namespace.get("result")}
        except Exception as error:
            reply = {"ok": False, "error": {"type": type(error).__name__, "message": str(error)[:4000]}}
        wire.write_message(outbound, reply)


def main(argv: List[str]) -> int:
    return serve(int(argv[0]), int(argv[1]), time.perf_counter())


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
