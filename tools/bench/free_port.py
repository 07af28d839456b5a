#!/usr/bin/env python3
"""Prints a TCP port on 127.0.0.1 that is free now and outside the kernel's ephemeral range.

A port the kernel picks for a bind to port 0 comes from the ephemeral range, and so does the local
port of every outgoing connection: between the moment a benchmark picks a router's port and the
moment the router binds it, the stations' connections could take it ("Address already in use").
Outside that range only another listener can. The stations pick their own ports the same way
(`free_port` in transport/src/network/config.rs). Falls back to the kernel's choice, with a
warning, where no port outside the range is free.
"""

import random
import socket
import sys

FIRST_PICKED_PORT = 10000


def ephemeral_range():
    try:
        with open("/proc/sys/net/ipv4/ip_local_port_range") as f:
            lo, hi = (int(x) for x in f.read().split())
    except (OSError, ValueError):
        lo, hi = 0, -1
    if not 1 <= lo <= hi <= 65535:
        return 32768, 60999  # Linux's default
    return lo, hi


def bindable(port):
    with socket.socket() as s:
        try:
            s.bind(("127.0.0.1", port))
            return True
        except OSError:
            return False


def main():
    lo, hi = ephemeral_range()
    candidates = list(range(FIRST_PICKED_PORT, lo)) + list(range(hi + 1, 65536))
    for port in random.sample(candidates, min(64, len(candidates))):
        if bindable(port):
            print(port)
            return
    print(
        f"free_port.py: no free port outside the ephemeral range {lo}-{hi}: "
        "using the kernel's choice",
        file=sys.stderr,
    )
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        print(s.getsockname()[1])


if __name__ == "__main__":
    main()
