"""float64 numpy oracle of every stage: the semantics, written plainly.

Kernels are tested against these functions at named tolerances; benchmarks report kernel error
against them. Nothing here is fast, and nothing here needs OpenCL.
"""

import math

import numpy as np

from radarcl import logodds
from radarcl.errors import ConfigError, ShapeError
from radarcl.geometry import check_poses
from radarcl.node_pairs import node_lerp, quantised_rho2
from radarcl.snr_evidence import bounded, gap_mixture, noise_floor

WINDOWS = ("hann", "rect")
OUTPUTS = ("magnitude", "power")

# Per-beam flags set while loading samples (range_fft kernel and oracle alike).
FLAG_NONFINITE = 1   # a NaN or Inf sample: the beam is invalid and gives no evidence
FLAG_CLIPPED = 2     # a sample at or beyond the clip level: the ADC saturated
# Per-beam flags set by the interpreter on the range profile it is given.
FLAG_BAD_PROFILE = 4  # a profile bin that is NaN, Inf, negative or beyond PROFILE_LIMIT
FLAG_SILENT = 8       # every bin exactly 0: the receiver measured nothing
# More flags set while loading samples.
FLAG_OVERRANGE = 16   # a float sample beyond sample_limit(n): its power would not fit float32
FLAG_CROSSTALK = 32   # real input: the FFT partner is PAIR_RATIO times stronger (see beam_flags)
# Beams with any of these give no evidence and no pulses. A clipped beam still does.
NO_EVIDENCE_FLAGS = FLAG_NONFINITE | FLAG_BAD_PROFILE | FLAG_SILENT | FLAG_OVERRANGE | FLAG_CROSSTALK
# Range processing pairs real beams (2m, 2m + 1) in one complex float32 FFT. Its rounding puts
# about 1e-7 log2(N) of the stronger beam into the weaker one, so the weaker is flagged when the
# stronger's largest |sample| exceeds PAIR_RATIO times its own: below that, what leaks is at
# most ~1e-2 of the weaker beam's largest sample (tests/test_range_fft.py measures it). int16
# samples never reach it (32768 / 1), except a beam of zeros beside a live one.
PAIR_RATIO = 2.0 ** 15
# A power profile bin must stay below this, so that CFAR's sums of up to 2 x 4096 training
# cells stay finite in float32 (3.4e38).
PROFILE_LIMIT = 1e34


def sample_limit(n_samples):
    """Largest |sample| of a float input whose power, after a sum over ``n_samples``, stays
    below a quarter of the largest float32: sqrt(FLT_MAX) / (2 n). Beyond it a beam is
    FLAG_OVERRANGE (int16 samples never are)."""
    return float(np.sqrt(np.finfo(np.float32).max)) / (2.0 * int(n_samples))


FLOAT32_MAX = float(np.finfo(np.float32).max)


def window_coefficients(kind, n):
    """Window of length n, float64.

    ``"hann"`` is the periodic (DFT-even) Hann window 0.5 - 0.5 cos(2 pi j / n), the same as
    ``scipy.signal.get_window("hann", n)``: -31 dB sidelobes and a mainlobe 1.5x wider than the
    rectangular window's (paper §3.2, Fig. 3). ``"rect"`` is all ones (no window).
    """
    if kind == "hann":
        return 0.5 - 0.5 * np.cos(2.0 * np.pi * np.arange(n) / n)
    if kind == "rect":
        return np.ones(n)
    raise ConfigError(f"window must be one of {WINDOWS}, got {kind!r}")


def range_gain(n_bins, bin_spacing_m, exponent):
    """Range-attenuation compensation r^k per bin (paper §2: "a filter generally corrects for
    attenuation due to distance"): (j * bin_spacing_m) ** exponent, float64, shape (n_bins,).

    Use k = 2 on magnitudes or k = 4 on powers to undo the radar equation's 1/r^4 in power.
    Bin 0 (zero range) gets gain 0 for k > 0.
    """
    if not np.isfinite(exponent) or not np.isfinite(bin_spacing_m) or bin_spacing_m <= 0:
        raise ConfigError(f"range gain needs a finite exponent and a positive bin spacing, "
                          f"got exponent {exponent!r}, spacing {bin_spacing_m!r}")
    return (np.arange(n_bins) * float(bin_spacing_m)) ** float(exponent)


def beam_flags(samples, clip_level=np.inf, paired=None):
    """Per-beam flags (uint8, shape samples.shape[:-1]) of range processing.

    FLAG_NONFINITE if any sample (I or Q) is NaN or Inf; FLAG_OVERRANGE if a finite one is
    beyond ``sample_limit(n)`` (float input; such samples enter the FFT as 0, like non-finite
    ones, so they cannot spoil a paired beam); FLAG_CLIPPED if any |sample| >= clip_level;
    for real input paired in FFTs (``paired``, default: real input), the beams taken in pairs
    (2m, 2m + 1) in C order: FLAG_CROSSTALK on the weaker of a pair when the other's largest
    loaded |sample| exceeds PAIR_RATIO times its own."""
    x = np.asarray(samples)
    complex_input = np.iscomplexobj(x)
    parts = (x.real, x.imag) if complex_input else (x,)
    limit = sample_limit(x.shape[-1]) if x.dtype.kind in "fc" else np.inf
    nonfinite = np.zeros(x.shape[:-1], bool)
    overrange = np.zeros(x.shape[:-1], bool)
    clipped = np.zeros(x.shape[:-1], bool)
    peak = np.zeros(x.shape[:-1])
    for part in parts:
        part = part.astype(np.float64)
        finite = np.isfinite(part)
        nonfinite |= ~finite.all(axis=-1)
        mag = np.abs(np.where(finite, part, 0.0))
        over = mag > limit
        overrange |= over.any(axis=-1)
        loaded = np.where(over, 0.0, mag)
        clipped |= (loaded >= clip_level).any(axis=-1)
        peak = np.maximum(peak, loaded.max(axis=-1))
    flags = nonfinite * FLAG_NONFINITE + overrange * FLAG_OVERRANGE + clipped * FLAG_CLIPPED
    if not complex_input if paired is None else paired:
        flat, m = flags.reshape(-1), peak.reshape(-1)
        for a in range(0, len(m) - 1, 2):
            if m[a] > PAIR_RATIO * m[a + 1]:
                flat[a + 1] |= FLAG_CROSSTALK
            if m[a + 1] > PAIR_RATIO * m[a]:
                flat[a] |= FLAG_CROSSTALK
        flags = flat.reshape(flags.shape)
    return flags.astype(np.uint8)


def range_profile(samples, n_fft, *, window="hann", output="magnitude", gain=None):
    """Range processing of beat-signal samples (paper §3.2, eq. 11), in float64.

    samples: (..., n) real or complex. Each beam is windowed, zero padded to ``n_fft`` (a power
    of two >= n), transformed, and its bins are calibrated by the window's coherent gain so that
    a complex tone of amplitude A on a bin centre reads A (a real one A/2) at any padding.
    Kept bins: all n_fft for complex input, the n_fft/2 below Nyquist for real input (the
    paper's "512 range bins" for n_fft = 1024). ``output`` is the magnitude or its square;
    ``gain`` (n_bins,) multiplies the result, e.g. ``range_gain``. Beams with a non-finite
    sample, or a float sample beyond ``sample_limit(n)``, come out all NaN (see ``beam_flags``):
    they are invalid and must give no evidence.
    """
    x = np.asarray(samples)
    if x.ndim < 1 or x.shape[-1] < 1:
        raise ShapeError(f"samples must be (..., n_samples) with n_samples >= 1, got shape {x.shape}")
    n = x.shape[-1]
    if not (isinstance(n_fft, (int, np.integer)) and n_fft >= n and n_fft & (n_fft - 1) == 0):
        raise ConfigError(f"n_fft must be a power of two >= n_samples = {n}, got {n_fft!r}")
    if output not in OUTPUTS:
        raise ConfigError(f"output must be one of {OUTPUTS}, got {output!r}")
    is_complex = np.iscomplexobj(x)
    limit = sample_limit(n) if x.dtype.kind in "fc" else np.inf
    x = x.astype(np.complex128 if is_complex else np.float64)
    with np.errstate(invalid="ignore"):
        usable = np.isfinite(x) & (np.abs(x.real) <= limit) & (np.abs(x.imag) <= limit)
    invalid = ~usable.all(axis=-1)
    w = window_coefficients(window, n)
    spectrum = np.fft.fft(np.where(usable, x, 0) * w, n=int(n_fft), axis=-1)
    n_bins = n_fft if is_complex else n_fft // 2
    result = np.abs(spectrum[..., :n_bins]) / w.sum()
    if output == "power":
        result = result ** 2
    if gain is not None:
        gain = np.asarray(gain, dtype=np.float64)
        if gain.shape != (n_bins,):
            raise ShapeError(f"gain must have shape ({n_bins},), got {gain.shape}")
        result = result * gain
    result[invalid] = np.nan
    return result


def training_cells(n_bins, guard, train):
    """Training-cell indices of every cell under the "shift" edge rule, int64 (n_bins, 2 train).

    Row i lists, in increasing order, ``train`` cells below i - guard and ``train`` above
    i + guard; near an end, the cells one side lacks are taken further out on the other side.
    The first ``train`` entries are the lower half, the last ``train`` the upper half (the two
    halves GO- and SO-CFAR compare). Needs n_bins >= 1 + 2 guard + 2 train.
    """
    if n_bins < 1 + 2 * guard + 2 * train:
        raise ConfigError(f"{n_bins} bins cannot hold guard {guard} + training {train} cells per side")
    i = np.arange(n_bins)[:, None]
    have_below = np.minimum(train, np.maximum(0, i - guard))
    have_above = np.minimum(train, np.maximum(0, n_bins - 1 - i - guard))
    n_below = have_below + (train - have_above)
    u = np.arange(2 * train)[None, :]
    return np.where(u < n_below, i - guard - n_below + u, i + guard + 1 + (u - n_below))


def cfar(profiles, config):
    """CFAR of power profiles (..., n_bins), in float64: ``(noise, ratio, mask)``.

    noise: the estimate n_i of ``config.kind`` over ``training_cells``, floored at
        ``config.noise_floor``; ratio: r_i / n_i, saturated at the largest float32;
    mask: r_i > alpha n_i (bool). NaN in a window propagates into noise and ratio and never
    detects.
    """
    r = np.asarray(profiles, dtype=np.float64)
    if r.ndim < 1:
        raise ShapeError(f"profiles must be (..., n_bins), got shape {r.shape}")
    config.check_profile_length(r.shape[-1])
    cells = r[..., training_cells(r.shape[-1], config.guard, config.train)]
    lower, upper = cells[..., :config.train], cells[..., config.train:]
    if config.kind == "ca":
        estimate = cells.mean(axis=-1)
    elif config.kind == "go":
        estimate = np.maximum(lower.mean(axis=-1), upper.mean(axis=-1))
    elif config.kind == "so":
        estimate = np.minimum(lower.mean(axis=-1), upper.mean(axis=-1))
    else:
        estimate = np.sort(cells, axis=-1)[..., config.rank - 1]
    noise = np.maximum(estimate, config.noise_floor)
    with np.errstate(over="ignore", invalid="ignore"):
        ratio = np.minimum(r / noise, FLOAT32_MAX)
        mask = r > config.alpha * noise
    return noise, ratio, mask


def profile_flags(profiles):
    """uint8 (...) per-beam flags of power profiles (..., n_bins): FLAG_BAD_PROFILE where a bin is
    NaN, Inf, negative or beyond PROFILE_LIMIT (the CFAR's sums would overflow float32 there),
    FLAG_SILENT where every bin is 0."""
    r = np.asarray(profiles, dtype=np.float64)
    with np.errstate(invalid="ignore"):
        bad = ~(np.isfinite(r) & (r >= 0) & (r <= PROFILE_LIMIT)).all(axis=-1)
    silent = ~(r != 0).any(axis=-1)
    return (np.where(bad, FLAG_BAD_PROFILE, 0) | np.where(silent, FLAG_SILENT, 0)).astype(np.uint8)


def _profiles_noise_mask(profiles, noise, mask):
    """The interpreters' inputs as float64, float64 and bool arrays of one shape (..., n_bins)."""
    r = np.asarray(profiles, dtype=np.float64)
    n = np.asarray(noise, dtype=np.float64)
    m = np.asarray(mask).astype(bool)
    if r.ndim < 1 or n.shape != r.shape or m.shape != r.shape:
        raise ShapeError(f"profiles, noise and mask must share one shape (..., n_bins), got "
                         f"{r.shape}, {n.shape}, {m.shape}")
    return r, n, m


def interpret(profiles, noise, mask, config, bin_spacing_m, flags=None):
    """The down-range interpreter, eq. 12 (or, with ``config.occludes``, radarcl's
    occlusion-aware variant: ``InterpretConfig``), on (..., n_bins) arrays, plainly, beam by beam.

    profiles: power r_i; noise, mask: from ``cfar``; flags: per-beam flags from range
    processing (..., ) or None. Returns ``(evidence, pulses, n_pulses, flags)``:
    evidence int32 (..., n_bins) in ``logodds`` units; pulses int32
    (..., max_pulses, 4) rows [start, end, peak, wide] (inclusive bins, -1 where unused);
    n_pulses int32 (...) the true count (may exceed max_pulses); flags uint8 (...) with
    FLAG_BAD_PROFILE / FLAG_SILENT added. Beams with a ``NO_EVIDENCE_FLAGS`` flag give 0
    evidence and no pulses. Pulses are runs of detections inside the evidence interval.
    """
    r, n, m = _profiles_noise_mask(profiles, noise, mask)
    batch, n_bins = r.shape[:-1], r.shape[-1]
    flags_in = np.zeros(batch, np.uint8) if flags is None else np.asarray(flags, np.uint8)
    if flags_in.shape != batch:
        raise ShapeError(f"flags must have shape {batch}, got {flags_in.shape}")
    first, last = config.bin_interval(bin_spacing_m, n_bins)
    wide_bins = config.wide_bins(bin_spacing_m)
    e_high, e_low, e_far = (int(v) for v in logodds.to_fixed([config.e_high, config.e_low, config.e_high_far]))
    occlusion, span = config.occludes, max(last - first, 1)
    evidence = np.zeros(r.shape, np.int32)
    pulses = np.full((*batch, config.max_pulses, 4), -1, np.int32)
    n_pulses = np.zeros(batch, np.int32)
    flags_out = flags_in | profile_flags(r)
    for beam in np.ndindex(*batch):
        rb, nb, mb = r[beam], n[beam], m[beam]
        if flags_out[beam] & NO_EVIDENCE_FLAGS:
            continue
        after_wide = False              # the paper: after the first wide pulse; occlusion: the first surface
        j = first
        while j <= last:
            if not mb[j]:
                if after_wide:
                    evidence[beam][j] = e_low
                elif occlusion:         # E_h in range, in integers truncated toward 0, as C divides
                    step = (e_far - e_high) * (j - first)
                    evidence[beam][j] = e_high + (abs(step) // span) * (1 if step >= 0 else -1)
                else:
                    evidence[beam][j] = e_high
                j += 1
                continue
            start, strongest = j, -np.inf
            while j <= last and mb[j]:
                decades = np.log10(rb[j]) - np.log10(nb[j])
                strongest = max(strongest, decades)
                evidence[beam][j] = logodds.to_fixed(max(0.0, config.k_occ * decades))
                j += 1
            end = j - 1
            wide = end - start + 1 >= wide_bins
            k = n_pulses[beam]
            if k < config.max_pulses:
                peak = start + int(np.argmax(rb[start:end + 1]))
                pulses[beam][k] = (start, end, peak, int(wide))
            n_pulses[beam] += 1
            after_wide = after_wide or wide or (occlusion and strongest >= config.surface_db / 10.0)
    return evidence, pulses, n_pulses, flags_out


def fusion(spec, evidence, lattice, model, poses, bin_spacing_m, first_bin, last_bin, margin=0.0, nodes=None,
           terrain_dz=-math.inf):
    """Eq. 9 for one frame with the beam volume of §3.4 (radarcl.geometry), brute force.

    spec: a ``GridSpec``; evidence: (n_beams, n_bins) int eq. 12 updates [logodds units], beam
    b = i * n_el + k; lattice, model: ``BeamLattice``, ``BeamModel``; poses: (4, 4) or
    (n_beams, 4, 4); bins outside [first_bin, last_bin] give nothing.

    Every beam is tested against every voxel centre p (no candidate windows): with (d, y, z)
    the coordinates of p in the beam frame and r = |p - beam origin|, the voxel takes
    rint(evidence[b, rint(r / spacing)] * weight(rho2)) when d > 0 and rho2 <= 1 (rint: half
    to even). Returns (sums int64 (nz, ny, nx), updates int64 (nz, ny, nx): beams that
    reached each voxel, ambiguous bool (nz, ny, nx)): voxels where some decision of a beam
    whose rho2 <= 1 + margin, at a bin within one of [first_bin, last_bin], (rho2 vs 1, the
    bin, d vs 0) lies within ``margin`` of its boundary, so float32 may decide it otherwise.
    With ``nodes`` and ``terrain_dz``, the detection-statistics model's, as ``fusion_at_points``.
    """
    nz, ny, nx = spec.array_shape
    iz, iy, ix = np.indices((nz, ny, nx)).reshape(3, -1)
    centres = spec.index_to_world(np.stack([ix, iy, iz], axis=1))
    out = fusion_at_points(centres, evidence, lattice, model, poses, bin_spacing_m, first_bin, last_bin, margin,
                           nodes=nodes, terrain_dz=terrain_dz)
    return tuple(a.reshape(nz, ny, nx) for a in out)


def fusion_at_points(centres, evidence, lattice, model, poses, bin_spacing_m, first_bin, last_bin, margin=0.0,
                     beams=None, nodes=None, terrain_dz=-math.inf):
    """``fusion`` at voxel centres (n, 3) [m, world], over ``beams`` (indices; default all).
    Returns (sums, updates, ambiguous), each (n,).

    With ``nodes`` = (evidence nodes, opportunity nodes), each (n_beams, n_bins, CLASSES, NODES)
    int (the detection-statistics model, ``node_pairs.unpack_nodes``), ``evidence`` is ignored:
    a voxel takes ``node_pairs.node_lerp`` of its bin's nodes of its class at its quantised
    rho2 (class 1, terrain, where its centre lies more than -``terrain_dz`` below the beam's
    origin: z - origin z < terrain_dz; else class 0), and the result has two more arrays, the
    knowledge sums and the counts of updates with an opportunity above 0 (n,)."""
    if nodes is not None:
        e_nodes, d_nodes = (np.asarray(a) for a in nodes)
        knowledge = np.zeros(len(centres), np.int64)
        looks = np.zeros(len(centres), np.int64)
        evidence = np.zeros(e_nodes.shape[:2], np.int64)
    evidence = np.asarray(evidence)
    P = check_poses(poses, lattice.n_beams)
    centres = np.asarray(centres, dtype=np.float64)
    rotations = lattice.beam_rotations()
    sums = np.zeros(len(centres), np.int64)
    updates = np.zeros(len(centres), np.int64)
    ambiguous = np.zeros(len(centres), bool)
    for b in range(lattice.n_beams) if beams is None else beams:
        T = P[b if len(P) > 1 else 0]
        x = centres - T[:3, 3]
        d, y, z = (x @ (T[:3, :3] @ rotations[b])).T
        bins = np.linalg.norm(x, axis=1) / bin_spacing_m
        j = np.rint(bins).astype(np.int64)
        rho2 = model.rho2(d, y, z)
        near = (rho2 <= 1 + margin) & (j >= first_bin - 1) & (j <= last_bin + 1)
        ambiguous |= near & ((np.abs(rho2 - 1) < margin) | (np.abs(np.abs(bins - j) - 0.5) < margin)
                             | (np.abs(d) < margin))
        inside = (d > 0) & (rho2 <= 1) & (j >= first_bin) & (j <= last_bin)
        if nodes is not None:
            q = quantised_rho2(rho2[inside])
            cls = (x[inside, 2] < terrain_dz).astype(np.int64)
            sums[inside] += node_lerp(e_nodes[b, j[inside], cls], q)
            opportunity = node_lerp(d_nodes[b, j[inside], cls], q)
            knowledge[inside] += opportunity
            looks[inside] += opportunity > 0
            updates[inside] += 1
            continue
        e = evidence[b, j[inside]].astype(np.float64)
        sums[inside] += np.rint(e * model.weight(rho2[inside])).astype(np.int64)
        updates[inside] += 1
    if nodes is not None:
        return sums, updates, ambiguous, knowledge, looks
    return sums, updates, ambiguous


def interpret_detstats(profiles, noise, mask, config, bin_spacing_m, model, flags=None):
    """The detection-statistics interpreter (``sensor_model``; ``radarcl.models.detstats``) on
    (..., n_bins) arrays, in float64.

    ``model`` is a ``sensor_model.BinModel``. Per beam and bin j inside the range window, with
    pulses as runs of detections (as ``interpret``):
      tau_j = exp(-X_j), X_j the summed blocking of the pulses that ended before j: a pulse's
          sum of (r/n - 1)+ over its bins times model.blocking at its peak (its first largest r);
      delta = tau_j model.opportunity[j] per class and node;
      a bin without detection: e = ln(1 - delta) = ln((1 - tau) + tau model.miss[j]);
      a detected bin: e = ln(1 + delta w_j (1 - P_fa) / P_fa), w_j = r_j / r_peak of its pulse
          (the echo came from where the profile is strongest: its flanks share less).
    With "snr" evidence (``model.graded``) every bin's evidence is instead
      e = model.snr_table(ln x_j, ln tau_j + model.ln_snr[j]), x_j = r_j / N,
    N the beam's ``snr_evidence.noise_floor`` over the window, and a pulse blocks by its summed
    (x - 1)+ (over the floor, not the CFAR's local estimate); delta as above. Behind nearer
    echoes (X_j > 0) with ``model.blocker_gap`` g > 0 the evidence is the mixture's,
    e = ln(L / (1 - q + q L)), L = (1 - g) L_b + g L_0 (L_b, L_0: the likelihood ratios of the
    table's e at ln tau_j + ln_snr and at ln_snr), and delta = ((1 - w) tau_j + w) opportunity
    where the gap's posterior w = g L_0 / L exceeds 1/2 (``_detstats_graded``); every look's evidence is then held within +-delta ln(1 / q)
    (``snr_evidence.bounded``). A node whose opportunity rounds to 0 gets evidence 0, with either
    evidence (the reading counts only looks with knowledge).
    Returns ``(evidence, opportunity, pulses, n_pulses, flags)``: evidence int32 (..., n_bins,
    CLASSES, NODES) [logodds units, clamped to +-16 nat], opportunity int32 (same shape)
    [KNOWLEDGE_SCALE units], pulses, n_pulses and flags as ``interpret``'s. Beams with a
    ``NO_EVIDENCE_FLAGS`` flag give 0 and no pulses; bins outside the window give 0."""
    r, n, m = _profiles_noise_mask(profiles, noise, mask)
    _, pulses, n_pulses, flags_out = interpret(r, n, m, config, bin_spacing_m, flags)
    batch, n_bins = r.shape[:-1], r.shape[-1]
    if model.opportunity.shape[0] != n_bins:
        raise ShapeError(f"the model has {model.opportunity.shape[0]} bins, the profiles {n_bins}")
    first, last = config.bin_interval(bin_spacing_m, n_bins)
    tail = model.opportunity.shape[1:]
    evidence = np.zeros((*batch, n_bins, *tail), np.int32).reshape(-1, n_bins, *tail)
    opportunity = np.zeros_like(evidence)
    c_det = (1.0 - model.pfa) / model.pfa
    for b, (rb, nb, mb) in enumerate(zip(r.reshape(-1, n_bins), n.reshape(-1, n_bins), m.reshape(-1, n_bins))):
        if flags_out.reshape(-1)[b] & NO_EVIDENCE_FLAGS:
            continue
        if model.graded:
            evidence[b], opportunity[b] = _detstats_graded(rb, mb, first, last, model)
            continue
        blocked, j = 0.0, first
        while j <= last:
            if not mb[j]:
                tau = math.exp(-blocked)
                opportunity[b, j] = np.rint(tau * model.opportunity[j] * logodds.KNOWLEDGE_SCALE)
                with np.errstate(divide="ignore"):
                    evidence[b, j] = np.where(opportunity[b, j] != 0,
                                              logodds.to_fixed(np.log((1.0 - tau) + tau * model.miss[j])), 0)
                j += 1
                continue
            start = j
            while j <= last and mb[j]:
                j += 1
            run = slice(start, j)
            peak = start + int(np.argmax(rb[run]))
            tau = math.exp(-blocked)
            for i in range(start, j):
                delta = tau * model.opportunity[i]
                opportunity[b, i] = np.rint(delta * logodds.KNOWLEDGE_SCALE)
                evidence[b, i] = np.where(opportunity[b, i] != 0,
                                          logodds.to_fixed(np.log1p(delta * (rb[i] / rb[peak]) * c_det)), 0)
            blocked += np.maximum(rb[run] / nb[run] - 1.0, 0.0).sum() * model.blocking[peak]
    shape = (*batch, n_bins, *tail)
    return evidence.reshape(shape), opportunity.reshape(shape), pulses, n_pulses, flags_out


def _detstats_graded(r, m, first, last, model):
    """One beam of ``interpret_detstats`` with "snr" evidence: (evidence, opportunity), each
    (n_bins, CLASSES, NODES) int32."""
    n_bins = len(r)
    evidence = np.zeros((n_bins, *model.opportunity.shape[1:]), np.int32)
    opportunity = np.zeros_like(evidence)
    if first > last:
        return evidence, opportunity
    x = r / noise_floor(r, first, last, model.noise_floor)
    blocked = np.zeros(n_bins)                      # X_j: the blocking of the pulses that ended before j
    j = first
    while j <= last:
        if m[j]:
            start = j
            while j <= last and m[j]:
                j += 1
            peak = start + int(np.argmax(r[start:j]))
            blocked[j:] += np.maximum(x[start:j] - 1.0, 0.0).sum() * model.blocking[peak]
        else:
            j += 1
    window = slice(first, last + 1)
    with np.errstate(divide="ignore"):
        ln_x = np.log(x[window])[:, None, None]
    tau = np.exp(-blocked[window, None, None])
    e = model.snr_table(ln_x, -blocked[window, None, None] + model.ln_snr[window])
    known = np.broadcast_to(tau, e.shape).copy()
    gap = model.blocker_gap
    behind = blocked[window] > 0.0 if gap else np.zeros(e.shape[0], bool)
    if behind.any():
        # behind nearer echoes: through a gap they leave (chance ``gap``, a partial blocker), v's
        # target is unblocked; the mixture of the two likelihoods, and the posterior chance of the gap
        e[behind], w = gap_mixture(e[behind], model.snr_table(ln_x[behind], model.ln_snr[window][behind]),
                                   model.snr_table.q, gap)
        # the knowledge follows the gap only where the power makes it more likely than not (noise
        # behind a blocker tells little of a gap, and each look with any knowledge counts as one
        # in the reading's look limit)
        known[behind] = np.where(w > 0.5, (1.0 - w) * tau[behind] + w, tau[behind])
    opportunity[window] = np.rint(known * model.opportunity[window] * logodds.KNOWLEDGE_SCALE)
    # a look says no more than a detection would at its opportunity, either way, and nothing without an
    # opportunity: the reading's look limit counts only looks that could see, and evidence it does
    # not count would grow with every frame
    e = bounded(e, known, model.opportunity[window], model.snr_table.q, model.bounded)
    evidence[window] = np.where(opportunity[window] != 0, logodds.to_fixed(e), 0)
    return evidence, opportunity
