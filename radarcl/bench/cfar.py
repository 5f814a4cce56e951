"""`radarcl bench cfar`: CFAR + eq. 12 interpreter kernels against vectorised numpy.

Both compute the same thing for one paper frame (64 x 4 beams, 512 bins of power after a
1024-point FFT): cell-averaging CFAR with the shift edge rule, detections, pulses, and eq. 12
evidence in fixed point. numpy's formulation is the fastest we could write: one float64
cumulative sum per frame gives every window sum by two subtractions (float64 keeps the
cancellation harmless at 120 dB), pulses come from the edges of the mask, and the first wide
pulse per beam from one scatter-min. The kernel's figure includes uploading the profiles.
"""

import numpy as np

from radarcl import logodds, oracle
from radarcl.bench.timing import interleaved_medians
from radarcl.config.stage_config import PAPER_RADAR, CfarConfig, InterpretConfig
from radarcl.errors import ConfigError
from radarcl.pipeline import Detection

N_FFT = 1024


class NumpyDetection:
    """CA-CFAR + eq. 12 in vectorised numpy, for 2-D (beams, bins) float32 power profiles."""

    def __init__(self, n_bins, bin_spacing_m, cfar_config, interpret_config):
        if cfar_config.kind != "ca":
            raise ConfigError("the numpy baseline implements CA-CFAR only")
        c, t = cfar_config, interpret_config
        i = np.arange(n_bins)
        # The shift edge rule's cells (one definition, the oracle's) as a run below and a run
        # above each bin; sum of x[a:b] = C[b] - C[a] with C[0] = 0; an empty run is 0:0.
        cells = oracle.training_cells(n_bins, c.guard, c.train)
        n_below = (cells < i[:, None]).sum(axis=1)
        n_above = c.n_train - n_below
        self.b_lo = np.where(n_below > 0, cells[:, 0], 0)
        self.b_hi = self.b_lo + n_below
        self.a_hi = np.where(n_above > 0, cells[:, -1] + 1, 0)
        self.a_lo = self.a_hi - n_above
        self.alpha, self.floor, self.n_train = c.alpha, c.noise_floor, c.n_train
        self.first, self.last = t.bin_interval(bin_spacing_m, n_bins)
        self.wide_bins = t.wide_bins(bin_spacing_m)
        self.k_occ = t.k_occ
        self.e_high, self.e_low = (int(v) for v in logodds.to_fixed([t.e_high, t.e_low]))
        self.inside = (i >= self.first) & (i <= self.last)

    def __call__(self, r):
        n_beams, n_bins = r.shape
        cum = np.zeros((n_beams, n_bins + 1))
        np.cumsum(r, axis=1, out=cum[:, 1:])
        sums = cum[:, self.b_hi] - cum[:, self.b_lo] + cum[:, self.a_hi] - cum[:, self.a_lo]
        noise = np.maximum(sums * (1.0 / self.n_train), self.floor).astype(np.float32)
        mask = r > self.alpha * noise
        m = mask & self.inside
        # Pulses: runs of m. Starts and ends in row-major order pair up one to one.
        padded = np.zeros((n_beams, n_bins + 2), bool)
        padded[:, 1:-1] = m
        edges = np.diff(padded.view(np.int8), axis=1)
        beam_s, start = np.nonzero(edges == 1)
        _, stop = np.nonzero(edges == -1)          # one past the last bin of each run
        wide = stop - start >= self.wide_bins
        first_wide_end = np.full(n_beams, n_bins, np.int64)
        np.minimum.at(first_wide_end, beam_s[wide], stop[wide] - 1)
        # Peak of each run: its first bin holding the run's maximum.
        flat = r.reshape(-1)
        in_run = np.flatnonzero(m.reshape(-1))
        run_of = np.cumsum(edges[:, :-1].reshape(-1) == 1)[in_run] - 1
        values = flat[in_run]
        run_max = np.maximum.reduceat(values, np.flatnonzero(np.diff(run_of, prepend=-1))) if len(values) else values
        at_max = np.flatnonzero(values == run_max[run_of])
        first_of_run = at_max[np.diff(run_of[at_max], prepend=-1) != 0]
        peak = in_run[first_of_run] % n_bins
        with np.errstate(divide="ignore"):
            nats = self.k_occ * (np.log10(r) - np.log10(noise))
        pulse_ev = np.rint(np.clip(nats, 0.0, logodds.EVIDENCE_LIMIT_NATS) * logodds.SCALE).astype(np.int32)
        after = np.arange(n_bins)[None, :] > first_wide_end[:, None]
        evidence = np.where(m, pulse_ev, np.where(after, self.e_low, self.e_high))
        evidence[:, ~self.inside] = 0
        valid = np.isfinite(r).all(axis=1) & (r >= 0).all(axis=1) & (r != 0).any(axis=1)
        evidence[~valid] = 0
        return noise, mask, evidence, (beam_s, start, stop - 1, peak, wide)


def paper_profiles(seed=0):
    """Power profiles of one paper frame (``scene.echoes.paper_like_frame``): receiver noise,
    ground returns, and point echoes up to ~100 dB above the noise."""
    from radarcl.scene.echoes import paper_like_frame

    return paper_like_frame(seed)


def run(runtime, repeat=200):
    """Measure the kernels and numpy on one paper frame; returns a dict (the --json object)."""
    profiles = paper_profiles()
    batch, n_bins = profiles.shape[:-1], profiles.shape[-1]
    spacing = PAPER_RADAR.bin_spacing_m(N_FFT)
    cfar_config, interpret_config = CfarConfig(), InterpretConfig()
    detection = Detection(runtime, batch, n_bins, spacing, cfar_config, interpret_config)
    baseline = NumpyDetection(n_bins, spacing, cfar_config, interpret_config)
    flat = profiles.reshape(-1, n_bins)

    def kernels():
        copy = detection.cfar.upload(profiles)
        detection.enqueue(wait_for=[copy]).wait()

    def cfar_only():
        detection.cfar.enqueue().wait()

    def with_numpy():
        return baseline(flat)

    kernels()
    t = interleaved_medians(dict(kernels=kernels, cfar=cfar_only, numpy=with_numpy), repeat)
    result = detection(profiles)
    noise, ratio, mask = oracle.cfar(profiles, cfar_config)
    evidence, _, n_pulses, _ = oracle.interpret(profiles, noise, mask, interpret_config, spacing)
    np_noise, np_mask, np_evidence, _ = with_numpy()
    return dict(
        benchmark="cfar", device=runtime.name, repeat=repeat, n_beams=int(np.prod(batch)), n_bins=n_bins,
        cfar=dict(kind=cfar_config.kind, guard=cfar_config.guard, train=cfar_config.train, pfa=cfar_config.pfa),
        ms_per_frame=t["kernels"] * 1e3, cfar_ms_per_frame=t["cfar"] * 1e3,
        numpy_ms_per_frame=t["numpy"] * 1e3, ratio_vs_numpy=t["numpy"] / t["kernels"],
        goal="ratio_vs_numpy >= 5",
        noise_max_rel_err=float(np.max(np.abs(result.cfar.noise - noise) / noise)),
        numpy_noise_max_rel_err=float(np.max(np.abs(np_noise.reshape(noise.shape) - noise) / noise)),
        mask_mismatches=int(np.count_nonzero(result.cfar.mask != mask)),
        evidence_max_abs_err_units=int(np.abs(result.interpret.evidence.astype(np.int64) - evidence).max()),
        numpy_evidence_max_abs_err_units=int(np.abs(np_evidence.reshape(evidence.shape).astype(np.int64)
                                                    - evidence).max()),
        detections=int(mask.sum()), pulses=int(n_pulses.sum()),
    )


def format_table(result):
    """Human-readable lines for a ``run`` result."""
    c = result["cfar"]
    return [
        f"CFAR ({c['kind'].upper()}, guard {c['guard']}, train {c['train']}, Pfa {c['pfa']:g}) + eq. 12 "
        f"interpreter, {result['n_beams']} beams x {result['n_bins']} bins; median of {result['repeat']} "
        f"interleaved runs on {result['device']}",
        f"  kernels (upload + CFAR + interpreter) {result['ms_per_frame']:8.3f} ms/frame "
        f"(CFAR alone {result['cfar_ms_per_frame']:.3f})",
        f"  numpy (cumulative sums)               {result['numpy_ms_per_frame']:8.3f} ms/frame",
        f"  ratio_vs_numpy {result['ratio_vs_numpy']:.2f} (goal: >= 5)",
        f"  vs float64 oracle: noise rel err {result['noise_max_rel_err']:.2e} (numpy "
        f"{result['numpy_noise_max_rel_err']:.2e}), mask mismatches {result['mask_mismatches']}, "
        f"evidence err {result['evidence_max_abs_err_units']} units (numpy "
        f"{result['numpy_evidence_max_abs_err_units']})",
        f"  {result['detections']} detections in {result['pulses']} pulses",
    ]


def add_arguments(parser):
    """`radarcl bench cfar` options."""
    from radarcl.commands.options import positive_int

    parser.add_argument("--repeat", type=positive_int, default=200, help="timed repetitions per variant "
                                                                          "(default: %(default)s)")


def command(args, runtime, say):
    """Run the bench; returns (result dict, table lines)."""
    result = run(runtime(), repeat=args.repeat)
    return result, format_table(result)
