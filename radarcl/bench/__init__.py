"""Benchmarks: each prints ratios against a baseline measured in the same run."""

import time

import numpy as np


def interleaved_medians(functions, repeat, block=10, warmup=3):
    """Median seconds per call of each callable.

    The callables take turns in blocks of ``block`` back-to-back calls, so machine noise (other
    processes, clock changes) falls on all of them alike while each runs in the steady state of a
    frame-rate loop. (Alternating single calls would make every OpenCL launch on PoCL wake its
    sleeping worker threads, a cost a streaming pipeline does not pay.)
    """
    for fn in functions.values():
        for _ in range(warmup):
            fn()
    times = {name: [] for name in functions}
    for _ in range(max(1, repeat // block)):
        for name, fn in functions.items():
            start = time.perf_counter()
            for _ in range(block):
                fn()
            times[name].append((time.perf_counter() - start) / block)
    return {name: float(np.median(t)) for name, t in times.items()}
