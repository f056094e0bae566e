#!/usr/bin/env python3
"""CPU time per frame of `volsplat bench`, for machines too loaded for wall-clock medians
(issue 29 item 7; docs/BENCHMARKS.md §21). Optional; never run in CI.

    python3 bench/cpu_per_frame.py [--frames 8] [--rounds 3] LABEL=BIN [LABEL=BIN ...] -- BENCH-ARGS

For each binary, alternating them `--rounds` times, it runs `BIN bench BENCH-ARGS --frames 1
--orbit 0` and `... --frames N --orbit 0` and takes the difference of their user + system CPU
time (`os.wait4`'s rusage) over N − 1: the CPU one frame costs, summed over the threads, without
loading, preparing or the first frame. Other processes on the machine change it far less than
they change the wall clock (they do not run inside it; only their cache traffic does), so it
compares builds on a shared machine; the wall time of T threads on T idle cores is about this
divided by T, times the threads' imbalance. A BIN may be a script that adds flags
(`exec volsplat "$@" --level auto`). Prints the median and every round, and the wall-clock
median of the N-frame run for reference.
"""
import argparse
import json
import os
import statistics
import subprocess
import sys


def run(binary, args, frames):
    """CPU ms (user + system) of one `bench` run and its JSON summary."""
    cmd = [binary, "bench", *args, "--frames", str(frames), "--orbit", "0"]
    p = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    out = p.stdout.read()
    err = p.stderr.read()
    _, status, ru = os.wait4(p.pid, 0)
    if os.waitstatus_to_exitcode(status) != 0:
        raise RuntimeError(f"{' '.join(cmd)} failed:\n{err.decode()[-2000:]}")
    summary = json.loads(out.decode().strip().splitlines()[-1])
    return (ru.ru_utime + ru.ru_stime) * 1e3, summary


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--frames", type=int, default=8)
    ap.add_argument("--rounds", type=int, default=3)
    ap.add_argument("bins", nargs="+", help="LABEL=BIN (then -- and the bench arguments)")
    own, bench_args = sys.argv[1:], []
    if "--" in own:
        i = own.index("--")
        own, bench_args = own[:i], own[i + 1:]
    argv = ap.parse_args(own)
    bins = argv.bins
    cpu = {b: [] for b in bins}
    wall = {b: [] for b in bins}
    for _ in range(argv.rounds):
        for b in bins:
            binary = b.split("=", 1)[-1]
            one, _ = run(binary, bench_args, 1)
            many, summary = run(binary, bench_args, argv.frames)
            cpu[b].append((many - one) / (argv.frames - 1))
            wall[b].append(summary["median_ms"])
    for b in bins:
        label = b.split("=", 1)[0]
        rounds = ", ".join(f"{x:.1f}" for x in cpu[b])
        print(f"{label:>12}: CPU {statistics.median(cpu[b]):7.1f} ms/frame ({rounds}); "
              f"wall median {statistics.median(wall[b]):.1f} ms")


if __name__ == "__main__":
    main()
