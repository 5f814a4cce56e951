"""Calibration as a fit: the interpreter's constants by maximum likelihood on the training scenes.

The fused log-odds of a voxel is linear in the interpreter's constants. With the occlusion-aware
interpreter (``InterpretConfig``, model "occlusion"), each in-range bin's evidence is

    k_occ * F_occ + e_high * F_near + e_high_far * F_far + e_low * F_after

with per-bin features: F_occ = max(0, log10(r / n)) on pulse bins; on noise bins before the
first surface F_near = 1 - f and F_far = f (f: the bin's place between the first and the last
bin of the range window, the interpreter's ramp); F_after = 1 on noise bins after it. The fusion
sums evidence over beams with the beam model's weights (eq. 9), so a voxel's log-odds is the
same linear form in the *fused* features. ``fused_features`` fuses each feature as a channel of
its own with the fusion kernel (the weighting exactly as the map applies it); ``fit`` is a
logistic regression without intercept of the visibility truth (DETECTABLE or WEAK: 1,
FREE-visible: 0; shadowed voxels are unknowable and left out) on them, by Newton's method, with
the signs eq. 12 requires (k_occ >= 0, the E's <= 0: a coefficient that leaves its side is held
at 0 and the rest refitted). The coefficients are log-odds per unit of feature: k_occ in nat per
decade of r/n, the E's in nat per update.

For the paper's form (model "paper") F_near and F_far are one feature (no ramp) and the surface
is the first wide pulse. The surface threshold and the CFAR settings are not linear: they are
chosen among candidates by the log-likelihood on validation scenes (``calibrate``).
"""

import math
from dataclasses import dataclass

import numpy as np

from radarcl import logodds, models
from radarcl.errors import ConfigError
from radarcl.evaluation import visibility as vis
from radarcl.grid import EvidenceGrid
from radarcl.pipeline import Mapping
from radarcl.stages.fusion import Fusion

CHANNELS = ("occ", "near", "far", "after")

# `radarcl calibrate --voxel 0.2` (occlusion-aware interpreter; training scenes 101-104, validated
# on 105 and 106; the held-out scenes never seen): the candidate with the best validation
# log-likelihood and its constants refitted on all six. The demo's default map uses these; a change
# to the simulator or the scenes means running it again.
CALIBRATED = {"cfar.kind": "ca", "cfar.pfa": 1e-3, "interpret.model": "occlusion", "interpret.surface_db": 15.0,
              "interpret.k_occ": 0.0811, "interpret.e_high": -1.1553, "interpret.e_high_far": -2.276,
              "interpret.e_low": -0.9791}
# The detection-statistics model read as the last release read it: no prior, so a voxel never
# observed reads 0 (p 1/2) and the known free voxels read near it (the bench's comparison row).
DETSTATS_NO_PRIOR = {"interpret.model": "detstats", "sensor_model.prior_nats": 0.0}
SIGNS = {"interpret.k_occ": 1, "interpret.e_high": -1, "interpret.e_high_far": -1, "interpret.e_low": -1}


def bin_features(profiles, noise, mask, config, bin_spacing_m):
    """(n_beams, n_bins, 4) features F_occ, F_near, F_far, F_after of one frame (see the module),
    for ``config`` (an ``InterpretConfig``: its range window, wide-pulse rule, model and
    surface_db); float64, 0 outside the range window."""
    r = np.asarray(profiles, np.float64).reshape(-1, np.shape(profiles)[-1])
    n = np.asarray(noise, np.float64).reshape(r.shape)
    m = np.asarray(mask).astype(bool).reshape(r.shape)
    first, last = config.bin_interval(bin_spacing_m, r.shape[1])
    wide_bins = config.wide_bins(bin_spacing_m)
    surface_decades = config.surface_db / 10.0 if config.occludes else math.inf
    out = np.zeros(r.shape + (4,))
    if first > last:
        return out
    with np.errstate(divide="ignore", invalid="ignore"):
        decades = np.log10(r) - np.log10(n)
    j = np.arange(r.shape[1])
    frac = np.clip((j - first) / max(last - first, 1), 0.0, 1.0)
    window = (j >= first) & (j <= last)
    for b in range(r.shape[0]):
        pulse = m[b] & window
        edges = np.flatnonzero(np.diff(np.concatenate([[0], pulse.astype(np.int8), [0]])))
        after = last + 1
        for start, stop in zip(edges[::2], edges[1::2]):            # runs [start, stop)
            if stop - start >= wide_bins or decades[b, start:stop].max() >= surface_decades:
                after = stop
                break
        noise_bins = window & ~pulse
        out[b, pulse, 0] = np.maximum(0.0, decades[b, pulse])
        before = noise_bins & (j < after)
        out[b, before, 1] = 1.0 - frac[before]
        out[b, before, 2] = frac[before]
        out[b, noise_bins & (j >= after), 3] = 1.0
    return out.reshape(np.shape(profiles) + (4,))


def fused_features(runtime, obs, config, spec, progress=None):
    """(nz, ny, nx, 4) float64: each feature of every frame of ``obs`` fused as its own channel
    with ``config``'s CFAR, beams and beam model (eq. 9's weights), into grids of ``spec``."""
    mapping = Mapping.from_config(runtime, config=config, grid=EvidenceGrid(runtime, spec))
    f, lattice, model = mapping.fusion, mapping.fusion.lattice, mapping.fusion.model
    icfg, spacing = config.interpret_config(), f.bin_spacing_m
    channels = [Fusion(runtime, EvidenceGrid(runtime, spec), lattice, model, f.n_bins, spacing, f.first_bin,
                       f.last_bin) for _ in CHANNELS]
    for k, (frame, pose) in enumerate(zip(obs.samples, obs.poses)):
        profiles = mapping.range_fft(frame).profiles
        cfar = mapping.detection.cfar(profiles)
        feats = bin_features(profiles, cfar.noise, cfar.mask, icfg, spacing).reshape(f.evidence_shape + (4,))
        for c, fusion in enumerate(channels):
            fusion.upload(np.rint(feats[..., c] * logodds.SCALE).astype(np.int32)).wait()
            fusion.enqueue(plan=fusion.plan(pose))
        if progress is not None:
            progress(k + 1, len(obs.poses))
    runtime.queue.finish()
    return np.stack([c.grid.snapshot() for c in channels], axis=-1) / float(logodds.SCALE)


def merged(X, model):
    """The feature columns the constants of ``model`` (an ``interpret.model`` name) weigh: F_near
    and F_far one feature for a model whose E_h does not ramp (eq. 12)."""
    if models.get(model).occludes:
        return X
    return np.column_stack([X[:, 0], X[:, 1] + X[:, 2], X[:, 3]])


def design(features, truth, model):
    """(X, y) of the visible voxels of ``truth`` (a ``VisibilityTruth``): the fused features
    (merged to the paper's three for a model without the ramp, ``merged``) and occupied
    (DETECTABLE or WEAK) or not."""
    c = truth.classes
    keep = (c == vis.FREE_VISIBLE) | (c == vis.DETECTABLE) | (c == vis.WEAK)
    return merged(features[keep], model).astype(np.float32), (c[keep] != vis.FREE_VISIBLE)      # float32: half the memory; fit in float64


@dataclass
class Fit:
    """Coefficients (a dict by configuration key), their standard errors (Wald, from the
    observed information), the mean log-likelihood per voxel and which were held at 0."""

    values: dict
    stderr: dict
    log_likelihood: float
    held: list
    n: int


def log_likelihood(X, y, beta):
    """Mean log p(y) per row of the logistic model L = X beta."""
    L = X @ beta
    return float(np.mean(np.where(y, -np.logaddexp(0.0, -L), -np.logaddexp(0.0, L))))


def fit(X, y, model, max_iter=100, zero=()):
    """Maximum-likelihood ``Fit`` of y on X without intercept, with eq. 12's signs; the
    constants named in ``zero`` are held at 0 (e.g. E_l: unknown behind the first surface)."""
    names = models.get(model).fitted
    signs = np.array([SIGNS[k] for k in names])
    free = np.array([k not in zero for k in names])
    X = np.asarray(X, np.float64)
    y = np.asarray(y, np.float64)
    if not len(y) or y.min() == y.max():
        raise ConfigError("calibration needs both occupied and free visible voxels")
    while True:
        beta = np.zeros(len(names))
        for _ in range(max_iter):
            Xf = X[:, free]
            p = 1.0 / (1.0 + np.exp(-(X @ beta)))
            w = p * (1 - p)
            H = Xf.T @ (Xf * w[:, None]) + 1e-9 * np.eye(int(free.sum()))
            step = np.linalg.solve(H, Xf.T @ (y - p))
            beta[free] += step
            if np.abs(step).max() < 1e-10:
                break
        wrong = free & (np.sign(beta) * signs < 0)
        if not wrong.any():
            break
        free &= ~wrong                              # held at 0 (the boundary of the allowed side)
        beta[~free] = 0.0
    cov = np.linalg.inv(H)
    se = np.zeros(len(names))
    se[free] = np.sqrt(np.diag(cov))
    return Fit(dict(zip(names, beta.tolist())), dict(zip(names, se.tolist())), log_likelihood(X, y.astype(bool), beta),
               [k for k, f in zip(names, free) if not f and k not in zero], len(y))


def with_intervals(final, jackknife):
    """The constants of ``final`` (a ``Fit``) with their Wald and jackknife standard errors and
    the 95 % interval from the jackknife. ``jackknife``: the refitted values with each part (a
    scene, a scan) left out in turn, (parts, constants)."""
    jack = np.asarray(jackknife, np.float64)
    k = len(jack)
    se = np.sqrt((k - 1) / k * ((jack - jack.mean(axis=0)) ** 2).sum(axis=0))
    return {key: dict(value=v, wald_se=final.stderr[key], jackknife_se=float(s),
                      ci95=[v - 1.96 * float(s), v + 1.96 * float(s)])
            for (key, v), s in zip(final.values.items(), se)}


def candidate_lines(candidates, chosen, heading, key):
    """Printed lines of a calibration's candidate search: a heading (what the candidates are,
    then the criterion in ``heading``), then each candidate's ``key``, the chosen one starred."""
    lines = [f"  {heading}"]
    for row in candidates:
        mark = "*" if row["candidate"] == chosen else " "
        lines.append(f"{mark} {row['candidate'][:60]:60s} {row[key]:.5f}")
    return lines


def constant_lines(constants, held, parts, note_zero=""):
    """Printed lines of ``with_intervals``'s constants; ``held``: those the sign constraint held
    at 0; ``parts``: what the jackknife left out; ``note_zero``: why a constant fixed at 0 is."""
    lines = [f"  fitted constants (value, Wald SE, jackknife SE over {parts}, 95 % interval from the jackknife):"]
    for key, c in constants.items():
        why = " (held at 0: the fit wanted the other sign)" if key in held else \
            (f" (held at 0: {note_zero})" if note_zero and c["value"] == 0 else "")
        lines.append(f"    {key:22s} {c['value']:9.4f}  {c['wald_se']:.4f}  {c['jackknife_se']:.4f}  "
                     f"[{c['ci95'][0]:.4f}, {c['ci95'][1]:.4f}]{why}")
    return lines


def pool_reliability(row_sets):
    """Reliability rows of several scenes pooled bin by bin (counts add; means weighted by count)."""
    out = []
    for rows in zip(*row_sets):
        n = sum(r[2] for r in rows)
        out.append((rows[0][0], rows[0][1], n, sum(r[2] * r[3] for r in rows) / n if n else 0.0,
                    sum(r[2] * r[4] for r in rows) / n if n else 0.0))
    return out
