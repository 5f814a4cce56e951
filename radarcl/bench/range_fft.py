"""`radarcl bench range-fft`: the range-FFT kernel against scipy.fft and numpy.fft.

All three compute the same thing for one paper frame (64 x 4 beams of 256 real int16 samples):
Hann window, zero padding to n_fft, FFT, calibrated magnitude of the n_fft/2 bins below Nyquist.
scipy and numpy use a real FFT (rfft) in float32, their fastest form. Times are medians of
interleaved repetitions; the kernel's figure includes the upload of the frame (what a pipeline
pays per frame; the profiles stay on the device for CFAR). Errors are against the float64 oracle.
"""

import numpy as np

from radarcl import oracle
from radarcl.bench.timing import interleaved_medians
from radarcl.config.stage_config import PAPER_RADAR
from radarcl.scene.fmcw import Adc, PointTarget, simulate_frame
from radarcl.stages.range_fft import RangeFFT

GOAL_N_FFT = 1024


def paper_frame(seed=0):
    """A frame of the paper's radar: a few point targets, receiver noise, a 12-bit ADC."""
    rng = np.random.default_rng(seed)
    targets = [PointTarget(int(rng.integers(64)), int(rng.integers(4)), float(rng.uniform(2, 60)),
                           float(rng.uniform(0.01, 0.5)), float(rng.uniform(0, 2 * np.pi))) for _ in range(40)]
    return simulate_frame(PAPER_RADAR, targets, noise_rms=2e-3, adc=Adc(bits=12), seed=seed).samples


def run(runtime, n_ffts=(512, GOAL_N_FFT), repeat=200):
    """Measure every n_fft; returns a dict (the --json object)."""
    import scipy.fft

    frame = paper_frame()
    w = oracle.window_coefficients("hann", frame.shape[-1])
    w32 = (w / w.sum()).astype(np.float32)
    runs = []
    for n_fft in n_ffts:
        plan = RangeFFT(runtime, frame.shape[:2], frame.shape[2], n_fft)
        half = n_fft // 2

        def kernel_only():
            plan.enqueue().wait()

        def upload_and_kernel():
            plan.enqueue(wait_for=[plan.upload(frame)]).wait()

        def round_trip():
            plan(frame)

        def with_scipy():
            return np.abs(scipy.fft.rfft(frame * w32, n=n_fft, axis=-1)[..., :half])

        def with_numpy():
            return np.abs(np.fft.rfft(frame * w32, n=n_fft, axis=-1)[..., :half])

        plan.upload(frame).wait()
        t = interleaved_medians(dict(kernel=kernel_only, pipeline=upload_and_kernel, round_trip=round_trip,
                                     scipy=with_scipy, numpy=with_numpy), repeat)
        expected = oracle.range_profile(frame, n_fft)
        scale = np.abs(expected).max()
        runs.append(dict(
            n_fft=n_fft, n_beams=plan.n_beams, local_size=plan.local_size,
            ms_per_frame=t["pipeline"] * 1e3, kernel_ms_per_frame=t["kernel"] * 1e3,
            round_trip_ms_per_frame=t["round_trip"] * 1e3,
            scipy_ms_per_frame=t["scipy"] * 1e3, numpy_ms_per_frame=t["numpy"] * 1e3,
            ratio_vs_scipy=t["pipeline"] / t["scipy"], ratio_vs_numpy=t["pipeline"] / t["numpy"],
            max_rel_err=float(np.abs(plan(frame).profiles - expected).max() / scale),
            scipy_max_rel_err=float(np.abs(with_scipy() - expected).max() / scale),
        ))
    goal = next((r for r in runs if r["n_fft"] == GOAL_N_FFT), runs[-1])
    return dict(benchmark="range-fft", device=runtime.name, repeat=repeat,
                goal="ratio_vs_scipy <= 1.0 at n_fft = 1024", **goal, runs=runs)


def format_table(result):
    """Human-readable lines for a ``run`` result."""
    lines = [f"range FFT, {result['n_beams']} beams x 256 int16 samples, Hann, magnitude; "
             f"median of {result['repeat']} interleaved runs on {result['device']}",
             f"{'n_fft':>6} {'kernel+upload':>14} {'kernel':>8} {'round trip':>11} {'scipy':>8} {'numpy':>8} "
             f"{'/scipy':>7} {'/numpy':>7} {'max rel err':>12} {'scipy err':>10}"]
    for r in result["runs"]:
        lines.append(f"{r['n_fft']:>6} {r['ms_per_frame']:>11.3f} ms {r['kernel_ms_per_frame']:>8.3f} "
                     f"{r['round_trip_ms_per_frame']:>11.3f} {r['scipy_ms_per_frame']:>8.3f} "
                     f"{r['numpy_ms_per_frame']:>8.3f} {r['ratio_vs_scipy']:>7.2f} {r['ratio_vs_numpy']:>7.2f} "
                     f"{r['max_rel_err']:>12.2e} {r['scipy_max_rel_err']:>10.2e}")
    lines.append(f"goal: {result['goal']} -> {result['ratio_vs_scipy']:.2f}")
    return lines


def add_arguments(parser):
    """`radarcl bench range-fft` options."""
    from radarcl.commands.options import positive_int

    parser.add_argument("--repeat", type=positive_int, default=200, help="timed repetitions per variant "
                                                                          "(default: %(default)s)")
    parser.add_argument("--n-fft", type=positive_int, nargs="+", default=[512, GOAL_N_FFT],
                        help="FFT lengths, powers of two >= 256 (default: 512 1024)")


def command(args, runtime, say):
    """Run the bench; returns (result dict, table lines)."""
    result = run(runtime(), n_ffts=tuple(args.n_fft), repeat=args.repeat)
    return result, format_table(result)
