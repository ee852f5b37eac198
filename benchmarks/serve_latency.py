"""Round trips of the 2D demo's WebSocket: a click's layout sent, its light paths back.

Starts ``embree-rt serve --port 0`` (the kernels warm before it prints its URL), then plays the
demo's clicks from a Python client: circles placed one at a time (glass, mirror and matte in
turn), each layout sent as the page sends it after a click, ``--rays`` rays from the light,
``--rounds`` rounds of ``--clicks`` clicks. Reports per round the median and maximum round trip
in milliseconds, and the server's own tracing time where it reports one. Issue 14's target: a
click answered within 50 ms. (The browser adds its drawing on top; the page's status line shows
the whole round trip as it saw it.)

    python benchmarks/serve_latency.py --rounds 5 --clicks 12

Prints one JSON object on stdout.
"""

from __future__ import annotations

import argparse
import json
import re
import signal
import statistics
import subprocess
import sys
import time

from websockets.sync.client import connect

MATERIALS = ("glass", "mirror", "matte")


def layout(clicks: int, rays: int, request: int) -> dict:
    circles = [
        {
            "x": 160.0 + 70.0 * k,
            "y": 120.0 + 40.0 * (k % 5),
            "r": 30.0 + 5 * (k % 4),
            "material": MATERIALS[k % 3],
        }
        for k in range(clicks)
    ]
    return {
        "type": "trace",
        "id": request,
        "circles": circles,
        "light": [80.0, 300.0],
        "rays": rays,
        "spread": 360,
        "aim": 0,
    }


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--rounds", type=int, default=5)
    parser.add_argument("--clicks", type=int, default=12)
    parser.add_argument("--rays", type=int, default=180)
    args = parser.parse_args(argv)
    server = subprocess.Popen(
        [sys.executable, "-m", "embree_rt", "serve", "--port", "0"],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    try:
        line = server.stdout.readline()
        match = re.search(r"at (http://[^/ ]+)/ ", line)
        if not match:
            raise SystemExit(f"unexpected first line from the server: {line!r}")
        url = match.group(1).replace("http://", "ws://") + "/ws/2d"
        rounds, request = [], 0
        with connect(url, open_timeout=30, max_size=None) as socket:
            for _ in range(args.rounds):
                trips = []
                for click in range(1, args.clicks + 1):
                    request += 1
                    started = time.perf_counter()
                    socket.send(json.dumps(layout(click, args.rays, request)))
                    reply = json.loads(socket.recv(timeout=30))
                    trips.append(1e3 * (time.perf_counter() - started))
                    if reply.get("type") != "rays":
                        raise SystemExit(f"unexpected reply: {str(reply)[:200]}")
                rounds.append(
                    {
                        "median_ms": round(statistics.median(trips), 2),
                        "max_ms": round(max(trips), 2),
                    }
                )
    finally:
        server.send_signal(signal.SIGINT)
        server.communicate(timeout=30)
    medians = [r["median_ms"] for r in rounds]
    print(
        json.dumps(
            {
                "config": vars(args),
                "rounds": rounds,
                "median_of_round_medians_ms": statistics.median(medians),
                "target_ms": 50,
            },
            indent=2,
        )
    )


if __name__ == "__main__":
    main()
