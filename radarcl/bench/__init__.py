"""Benchmarks: each prints ratios against a baseline measured in the same run."""

import time

import numpy as np


def interleaved_medians(functions, repeat, block=10, warmup=3):
    """Median seconds per call of each callable.

    The callables take turns in blocks of ``block`` back-to-back calls, so machine noise (other
    processes, clock changes) falls on all of them alike while each runs in the steady state of a
    frame-rate loop. (Measured on PoCL: alternating single calls made the range-FFT kernel take
    0.8 ms instead of 0.59, likely the cost of waking PoCL's idle worker threads, which a
    streaming pipeline does not pay.)
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
