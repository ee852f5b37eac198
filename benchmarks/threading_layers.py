"""Numba's parallel loops on a loaded machine: one ``prange`` loop over chunks of work, on 1 and
2 threads, under each of numba's threading layers that loads here, with and without a busy
process pinned to nothing (``--busy N`` starts N ``while 1: pass`` processes for the run).

Each (layer, threads) case runs in a fresh interpreter (``NUMBA_THREADING_LAYER``,
``NUMBA_NUM_THREADS``), cases taking turns ``--turns`` times; the loop's work is fixed
(``--items`` square roots in ``--chunks`` chunks), so ``seconds`` compares like with like.
``--chunks 2`` is the static halves numba's default split gives two threads; many small
chunks let a thread that ran take more of them (the omp layer schedules ``prange`` statically
either way: what changes is only how much one chunk holds).

    python benchmarks/threading_layers.py --busy 1
    python benchmarks/threading_layers.py --items 2000000 --turns 2

Prints one JSON object on stdout. A layer that cannot load (tbb without the tbb package) is
listed with its error.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys

CASE = r"""
import json, sys, time
import numpy as np
from numba import njit, prange, threading_layer

@njit(parallel=True, cache=False)
def work(items, chunks, out):
    size = (items + chunks - 1) // chunks
    for c in prange(chunks):
        total = 0.0
        for i in range(c * size, min(items, (c + 1) * size)):
            total += np.sqrt(np.float64(i))
        out[c] = total

items, chunks = int(sys.argv[1]), int(sys.argv[2])
out = np.zeros(chunks)
work(1000, chunks, out)  # compile
began = time.perf_counter()
work(items, chunks, out)
print(json.dumps({"seconds": time.perf_counter() - began, "layer": threading_layer()}))
"""


def run_case(layer: str, threads: int, items: int, chunks: int) -> dict:
    env = {**os.environ, "NUMBA_THREADING_LAYER": layer, "NUMBA_NUM_THREADS": str(threads)}
    done = subprocess.run(
        [sys.executable, "-c", CASE, str(items), str(chunks)],
        env=env,
        capture_output=True,
        text=True,
        check=False,
    )
    if done.returncode:
        return {"error": done.stderr.strip().splitlines()[-1] if done.stderr else "failed"}
    return json.loads(done.stdout)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--items", type=int, default=50_000_000)
    parser.add_argument("--turns", type=int, default=3)
    parser.add_argument("--busy", type=int, default=0)
    parser.add_argument("--layers", default="workqueue,omp,tbb")
    args = parser.parse_args()
    busy = [subprocess.Popen([sys.executable, "-c", "while 1: pass"]) for _ in range(args.busy)]
    try:
        cases = [
            (layer, threads, chunks)
            for layer in args.layers.split(",")
            for threads in (1, 2)
            for chunks in ((2, 256) if threads == 2 else (1,))
        ]
        results: dict[str, dict] = {}
        for _ in range(args.turns):
            for layer, threads, chunks in cases:
                key = f"{layer}/threads={threads}/chunks={chunks}"
                answer = run_case(layer, threads, args.items, chunks)
                entry = results.setdefault(key, {"seconds": []})
                if "error" in answer:
                    entry["error"] = answer["error"]
                else:
                    entry["seconds"].append(round(answer["seconds"], 4))
                    entry["layer"] = answer["layer"]
    finally:
        for process in busy:
            process.kill()
            process.wait()
    for entry in results.values():
        if entry["seconds"]:
            entry["median_s"] = sorted(entry["seconds"])[len(entry["seconds"]) // 2]
    print(
        json.dumps(
            {"items": args.items, "busy": args.busy, "cpus": os.cpu_count(), "cases": results},
            indent=1,
        )
    )


if __name__ == "__main__":
    main()
