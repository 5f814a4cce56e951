"""A real radar's physical parameters from its own recording (`radarcl fit-sensor`): the
background law (noise and its scale, clutter: ``snr_evidence.Clutter``) and the sensitivity
(``snr_1m2_at_10m_db``) of the detection-statistics model, by maximum likelihood of the powers
it measured, with intervals from a jackknife over scans.

Every bin in the range window measures x = r / N (N: its beam's noise floor, as the interpreter
takes it). Per band of range the bins are a mixture: a share pi of them hold a typical target of
median SNR s(r) (the radar equation: ``sensor_model.upright_snr``, averaged over the beam's
offsets and the band's ranges), the rest the background:

    p(x | band) = (1 - c) [pi pT(x; s(r)) + (1 - pi) pN(x)] + c pC(x)

(the model's own p1 and p0, ``snr_evidence``: clutter masks a target). The clutter does not fall
with range and targets do, as r^-4: that is what tells them apart without a lidar. The fit
maximises the likelihood of the histograms of ln x per scan and band (``PowerCounts``; each bin's
probability the difference of the mixture's distribution function at its edges, so quantised
levels and zeros count right) over (c, clutter median, clutter spread, sensitivity, noise scale: the
noise's mean over the median-based floor, which clutter and echoes move), each band's
pi at its own maximum given the rest. With a lidar, the cells it calls free give the background's
bins alone (``fit(..., background=...)``).

Only the product of sensitivity and the typical target's reflectivity and extent enters, so the
sensitivity is fitted for the configuration's typical target (``target_gamma_db``,
``target_extent_m``). Blocking and the look limit are not fitted here: what lies behind a first
surface has no truth a recording without a lidar could give (the configuration keeps them and
says so).
"""

import dataclasses
import math
from dataclasses import dataclass

import numpy as np

from radarcl import node_pairs, sensor_model
from radarcl.errors import ConfigError
from radarcl.snr_evidence import DB, SPREAD_STEPS, Clutter, noise_floor

U_EDGES = np.arange(-12.0, 18.01, 0.5)      # ln x histogram edges; outside: the first and last bins
N_BANDS = 12                                 # log-spaced bands of range over the window
MIN_SCANS = 3                                # the jackknife's least
MIN_BINS = 20000                             # powers per fit
FITTED = ("clutter_share", "clutter_db", "clutter_spread_db", "snr_1m2_at_10m_db", "noise_scale")


@dataclass(frozen=True)
class PowerCounts:
    """Histograms of ln x: ``counts`` (n_scans, n_bands, len(U_EDGES) + 1) int64 (bin 0: below the
    first edge, zeros included; the last: above the last), the bands' ``ranges_m`` (n_bands, 3)
    (three ranges spanning each band, where the target's SNR is averaged)."""

    counts: np.ndarray
    ranges_m: np.ndarray

    @property
    def n_scans(self):
        return self.counts.shape[0]

    def without(self, scan):
        """The counts of every scan but ``scan`` (the jackknife's)."""
        return PowerCounts(np.delete(self.counts, scan, axis=0), self.ranges_m)


def power_counts(scans, bin_spacing_m, range_min_m, range_max_m, mask=None):
    """``PowerCounts`` of ``scans`` (each (n_az, n_bins) linear power): x over each beam's noise
    floor (``snr_evidence.noise_floor`` over the window, as the interpreter), bins in
    [range_min_m, range_max_m] in N_BANDS log-spaced bands. ``mask`` (a list of bool arrays like
    the scans, or None): only the bins it keeps count (e.g. the cells a lidar calls free); the
    floor is still the whole beam's."""
    n_bins = np.shape(scans[0])[-1]
    ranges = np.arange(n_bins) * float(bin_spacing_m)
    window = np.flatnonzero((ranges >= range_min_m) & (ranges <= range_max_m))
    if len(window) < N_BANDS:
        raise ConfigError(f"the range window {range_min_m:g}-{range_max_m:g} m holds {len(window)} bins; the fit "
                          f"needs at least {N_BANDS}")
    first, last = int(window[0]), int(window[-1])
    lo = max(ranges[first], bin_spacing_m)
    edges = np.geomspace(lo, ranges[last] + bin_spacing_m, N_BANDS + 1)
    band = np.clip(np.searchsorted(edges, ranges[first:last + 1], side="right") - 1, 0, N_BANDS - 1)
    counts = np.zeros((len(scans), N_BANDS, len(U_EDGES) + 1), np.int64)
    for i, power in enumerate(scans):
        p = np.asarray(power, np.float64)
        x = p[:, first:last + 1] / noise_floor(p, first, last)[:, None]
        with np.errstate(divide="ignore"):
            k = np.searchsorted(U_EDGES, np.log(x), side="right")
        keep = np.ones(x.shape, bool) if mask is None else np.asarray(mask[i], bool)[:, first:last + 1]
        np.add.at(counts[i], (np.broadcast_to(band, x.shape)[keep], k[keep]), 1)
    spans = np.stack([edges[:-1], np.sqrt(edges[:-1] * edges[1:]), edges[1:]], axis=1)
    return PowerCounts(counts, spans)


def _cdf_noise(x, scale):
    return -np.expm1(-x / scale)


def _cdf_exp_mixture(x, ln_means, weights, scale):
    """E over log-normal powers G (ln G: ``ln_means``) of the distribution function at ``x``
    (edges) of exponential power of mean ``scale`` + G."""
    mean = scale + np.exp(ln_means)                                 # (..., nodes)
    return (-np.expm1(-x[..., None] / mean[..., None, :]) * weights[..., None, :]).sum(axis=-1)


def _nodes(spread_db, steps):
    sigma = spread_db * DB
    z = np.linspace(-8.0, 8.0, steps) if sigma else np.zeros(1)
    w = np.exp(-0.5 * z * z)
    return sigma * z, w / w.sum()


@dataclass(frozen=True)
class Geometry:
    """What ties the sensitivity to the typical target's SNR per band: the model's parameters
    (its typical target) and the beam's half-power half-widths [rad]."""

    params: sensor_model.ModelParams
    half_az_rad: float
    half_el_rad: float

    def ln_snr(self, ranges_m, sensitivity_db):
        """(n_bands, 15): ln s of the typical target at the band's three ranges and five offsets
        in the beam (rho2 = 0 .. 1), at ``sensitivity_db``."""
        p = dataclasses.replace(self.params, snr_1m2_at_10m_db=float(sensitivity_db))
        ln_s, kappa = sensor_model.upright_snr(p, ranges_m.reshape(-1), self.half_az_rad, self.half_el_rad)
        t = np.arange(node_pairs.NODES) / (node_pairs.NODES - 1) * math.log(4.0)
        out = ln_s[:, None] - kappa[:, None] * t[None, :]
        return out.reshape(ranges_m.shape[0], -1)


def bin_probabilities(theta, counts, geometry, pi=None):
    """(probabilities (n_bands, n_u) of each ln x bin under the mixture, pi (n_bands,)): at
    ``theta`` = (c, clutter median [dB], clutter spread [dB], sensitivity [dB], noise scale), with each band's
    target share pi at its maximum likelihood for ``counts`` (summed over scans) unless given
    (0: the background alone, 1: every bin holds the typical target)."""
    c, median_db, spread_db, sens_db, scale = theta
    x = np.exp(U_EDGES)
    edges = np.concatenate([[0.0], x, [np.inf]])
    f_noise = _cdf_noise(edges, scale)
    z, w = _nodes(spread_db, 97)
    f_clutter = _cdf_exp_mixture(edges, median_db * DB + z, w, scale) if c > 0 else f_noise
    zt, wt = _nodes(geometry.params.target_spread_db, SPREAD_STEPS // 4)
    ln_s = geometry.ln_snr(counts.ranges_m, sens_db)                  # (bands, 15)
    ln_means = (ln_s[:, :, None] + zt[None, None, :]).reshape(len(ln_s), -1)
    weights = np.broadcast_to((wt / ln_s.shape[1])[None, None, :], (*ln_s.shape, len(wt))).reshape(len(ln_s), -1)
    f_target = _cdf_exp_mixture(edges[None, :], np.minimum(ln_means, 700.0), weights, scale)    # (bands, edges)
    a = (1.0 - c) * np.diff(f_noise)[None, :] + c * np.diff(f_clutter)[None, :]
    b = (1.0 - c) * (np.diff(f_target, axis=1) - np.diff(f_noise)[None, :])
    if pi is None:
        pi = _best_share(counts.counts.sum(axis=0), a, b)
    return a + pi[:, None] * b, pi


def _best_share(n, a, b):
    """Per band, the share in [0, 1] maximising sum_k n_k ln(a_k + pi b_k) (concave: bisection
    on the derivative)."""
    lo, hi = np.zeros(len(n)), np.ones(len(n))
    floor = 1e-300

    def slope(pi):
        return (n * b / np.maximum(a + pi[:, None] * b, floor)).sum(axis=1)

    at_one = slope(hi) >= 0.0
    at_zero = slope(lo) <= 0.0
    for _ in range(50):
        mid = 0.5 * (lo + hi)
        up = slope(mid) > 0.0
        lo, hi = np.where(up, mid, lo), np.where(up, hi, mid)
    return np.where(at_one, 1.0, np.where(at_zero, 0.0, 0.5 * (lo + hi)))


def log_likelihood(theta, counts, geometry, pi=None):
    """Mean log-likelihood per bin [nat] of ``counts`` at ``theta`` (``bin_probabilities``)."""
    p, _ = bin_probabilities(theta, counts, geometry, pi)
    n = counts.counts.sum(axis=0)
    return float((n * np.log(np.maximum(p, 1e-300))).sum() / max(n.sum(), 1))


# the search space: (c, clutter median, clutter spread, sensitivity, noise scale), within the keys' ranges
def _bounds():
    r = sensor_model.RANGES
    return [(1e-4, 0.95), (max(r["clutter_db"][0], -10.0), min(r["clutter_db"][1], 60.0)),
            (0.5, r["clutter_spread_db"][1]), (r["snr_1m2_at_10m_db"][0] + 10.0, r["snr_1m2_at_10m_db"][1] - 10.0),
            (0.2, 5.0)]


def _search(counts, geometry, start=None, pi=None, free=(0, 1, 2, 3, 4)):
    """The likelihood's maximum over the parameters ``free`` (indices of ``FITTED``), the others
    held at ``start``; from ``start``, or from four sensitivities."""
    from scipy.optimize import minimize

    bounds = [_bounds()[i] for i in free]
    if start is not None:
        starts = [np.asarray(start, float)]
    else:
        starts = [np.array((0.1, 10.0, 8.0, s, 1.0)) for s in (30.0, 50.0, 70.0, 90.0)]

    def theta_of(t, base):
        out = np.array(base, float)
        out[list(free)] = t
        return out

    best = None
    for s0 in starts:
        res = minimize(lambda t: -log_likelihood(theta_of(t, s0), counts, geometry, pi), s0[list(free)],
                       method="Nelder-Mead", bounds=bounds, options=dict(xatol=1e-3, fatol=1e-9, maxiter=600))
        if best is None or res.fun < best[0]:
            best = res.fun, theta_of(res.x, s0)
    return best[1]


@dataclass(frozen=True)
class SensorFit:
    """The fitted values (``FITTED`` order), their jackknife standard errors over scans, the
    bands' target shares, the mean log-likelihood per bin of the fit and of noise alone (c = 0),
    how many scans and powers it used, the keys it could not bound, and whether a lidar told the
    background from the targets."""

    values: tuple
    errors: tuple
    shares: tuple
    log_likelihood: float
    noise_only: float
    n_scans: int
    n_powers: int
    at_edge: tuple = ()              # keys whose fit lies at the search's edge: the recording does not bound them
    lidar: bool = False              # fitted with the lidar's free and occupied cells apart

    def as_dict(self):
        return {k: dict(value=float(v), se=float(e)) for k, v, e in zip(FITTED, self.values, self.errors)}

    def config_values(self):
        """{"sensor_model.<key>": value} of the fit."""
        return {f"sensor_model.{k}": float(v) for k, v in zip(FITTED, self.values)}


def _check(counts, what):
    n = int(counts.counts.sum())
    if counts.n_scans < MIN_SCANS:
        raise ConfigError(f"the fit needs at least {MIN_SCANS} scans (its intervals are a jackknife over scans); "
                          f"got {counts.n_scans}")
    if n < MIN_BINS:
        raise ConfigError(f"the fit needs at least {MIN_BINS} powers {what}; the scans give {n}")
    return n


def fit(counts, geometry, report=None, background=None, targets=None):
    """``SensorFit`` of ``counts`` (``PowerCounts`` of every bin in the window): the mixture's
    search from four sensitivities, then one search per scan left out from the fit's values (the
    jackknife). With a lidar, ``background`` (the counts of the bins in cells it calls free) fits
    the background law alone and ``targets`` (those in cells it calls occupied) the sensitivity
    alone, each band all target. Refuses a recording too short or too empty to fit, and values
    outside their keys' physical ranges."""
    say = report or (lambda _: None)
    n = _check(counts, "in the range window")
    bright = int(counts.counts[:, :, np.searchsorted(U_EDGES, math.log(10.0)) + 1:].sum())   # bins wholly above
    if bright < 100:
        raise ConfigError(f"the scans hold {bright} bins 10 dB or more over their noise floor; the fit needs at "
                          f"least 100 echoes to tell targets from the background")
    lidar = background is not None
    if lidar:
        _check(background, "in cells the lidar calls free")
        if int(targets.counts.sum()) < 1000:
            raise ConfigError(f"the lidar's occupied cells hold {int(targets.counts.sum())} of the radar's bins; the "
                              f"fit needs at least 1000 (does the lidar overlap the radar's scans?)")

    def one(skip=None, start=None):
        take = (lambda c: c) if skip is None else (lambda c: c.without(skip))
        if not lidar:
            return _search(take(counts), geometry, start)
        zero, one_ = np.zeros(N_BANDS), np.ones(N_BANDS)
        theta = _search(take(background), geometry, start if start is not None else (0.1, 10.0, 8.0, 60.0, 1.0),
                        pi=zero, free=(0, 1, 2, 4))
        if start is None:
            grid = [(s, log_likelihood((*theta[:3], s, theta[4]), take(targets), geometry, one_))
                    for s in range(20, 111, 10)]
            theta[3] = max(grid, key=lambda g: g[1])[0]
        return _search(take(targets), geometry, theta, pi=one_, free=(3,))

    say(f"fitting {n:,} powers of {counts.n_scans} scans" + (" (the lidar's free and occupied cells apart)" if lidar
                                                             else "") + " ...")
    theta = one()
    jack = []
    for k in range(counts.n_scans):
        say(f"  jackknife: scan {k + 1} of {counts.n_scans} left out")
        jack.append(one(k, theta))
    jack = np.array(jack)
    m = counts.n_scans
    se = np.sqrt((m - 1) / m * ((jack - jack.mean(axis=0)) ** 2).sum(axis=0))
    for key, value in zip(FITTED, theta):
        lo, hi, unit, _ = sensor_model.RANGES[key]
        sensor_model.check_range(f"sensor_model.{key} (fitted)", float(value), lo, hi, unit)
    _, shares = bin_probabilities(theta, counts, geometry)
    noise_only = log_likelihood((0.0, *theta[1:]), counts, geometry)
    edge = [k for k, v, (lo, hi) in zip(FITTED, theta, _bounds()) if min(v - lo, hi - v) < 1e-3 * (hi - lo)]
    return SensorFit(tuple(float(v) for v in theta), tuple(float(e) for e in se), tuple(float(s) for s in shares),
                     log_likelihood(theta, counts, geometry), noise_only, m, n, tuple(edge), lidar)

