"""Timing for the benchmarks: interleaved medians, with blocks that other processes disturbed left out."""

import time

import numpy as np


def interleaved_medians(functions, repeat, block=10, warmup=3, load=None, max_other=0.25):
    """Median seconds per call of each callable.

    The callables take turns in blocks of ``block`` back-to-back calls, so machine noise (other
    processes, clock changes) falls on all of them alike while each runs in the steady state of a
    frame-rate loop (alternating single calls would add the cost of waking PoCL's idle worker
    threads, which a streaming pipeline does not pay).

    These machines are shared: a block during which other processes used more than
    ``max_other`` of a core (``OtherLoad``, from /proc) is discarded, unless every block of a
    callable was. ``load``, a dict, receives per callable the blocks kept and discarded and the
    other processes' mean share of a core.
    """
    for fn in functions.values():
        for _ in range(warmup):
            fn()
    times = {name: [] for name in functions}
    others = {name: [] for name in functions}
    for _ in range(max(1, repeat // block)):
        for name, fn in functions.items():
            meter = OtherLoad()
            start = time.perf_counter()
            for _ in range(block):
                fn()
            times[name].append((time.perf_counter() - start) / block)
            others[name].append(meter.cores())
    out = {}
    for name, t in times.items():
        t, o = np.array(t), np.array(others[name], float)
        quiet = ~(o > max_other)                     # NaN (no /proc) counts as quiet
        out[name] = float(np.median(t[quiet] if quiet.any() else t))
        if load is not None:
            load[name] = dict(blocks_kept=int(quiet.sum()) if quiet.any() else len(t),
                              blocks_discarded=int((~quiet).sum()) if quiet.any() else 0,
                              other_cores=float(np.nanmean(o)) if np.isfinite(o).any() else None)
    return out


class OtherLoad:
    """CPU used by other processes since creation, in cores (Linux /proc; NaN elsewhere): all
    CPUs' busy time less this process's (its threads, PoCL's included) and that of ``pids`` (the
    benchmark's own workers, e.g. Dask's), per second of wall."""

    def __init__(self, pids=()):
        self.pids = ["self", *map(str, pids)]
        self.start = (time.perf_counter(), *self._ticks())

    def _ticks(self):
        try:
            with open("/proc/stat") as f:
                cpu = [int(v) for v in f.readline().split()[1:]]
            own = 0
            for pid in self.pids:
                with open(f"/proc/{pid}/stat") as f:
                    fields = f.read().rsplit(")", 1)[1].split()
                own += int(fields[11]) + int(fields[12])                       # utime + stime
            return sum(cpu) - cpu[3] - cpu[4], own                              # busy - (idle, iowait)
        except (OSError, ValueError, IndexError):
            return float("nan"), float("nan")

    MIN_WALL_S = 0.1        # /proc counts in ticks of 10 ms: a shorter span cannot be judged

    def cores(self):
        """Other processes' mean share of a core since creation; NaN for spans under
        ``MIN_WALL_S`` or without /proc."""
        import os

        wall = time.perf_counter() - self.start[0]
        if wall < self.MIN_WALL_S:
            return float("nan")
        busy, own = self._ticks()
        hz = os.sysconf("SC_CLK_TCK") if hasattr(os, "sysconf") else 100
        return max(0.0, ((busy - self.start[1]) - (own - self.start[2])) / hz / wall)
