"""The "snr" evidence of the detection-statistics model (``radarcl.sensor_model``): the
log-likelihood ratio of a bin's measured power for a voxel holding a typical target against the
voxel free, tabulated once and read bilinearly (here in float64, in ``kernels/interpret_nodes.cl``
from the same float32 table).

A bin's power over the beam's noise floor, x = r / N (``noise_floor``: the median power of the
range window / ln 2, the mean of exponential noise were the window noise alone; the noise's mean
in these units is v, ``Clutter.noise_scale``, 1 unless echoes and clutter move the median). Where
nothing is, a real radar shows more than noise: sidelobes of strong echoes in the same scan,
multipath, clutter. The background is exponential noise, or with the chance c (``Clutter.share``)
clutter, exponential power of mean v + G with G log-normal (``Clutter.median_db`` over the
floor, ``Clutter.spread_db``):

    p0(x) = (1 - c) pN(x) + c pC(x),    pN(x) = exp(-x / v) / v,   pC(x) = E_G[exp(-x / (v + G)) / (v + G)]
    p1(x) = (1 - c) pT(x; s) + c pC(x),  pT(x; s) = E_s[exp(-x / (v + s)) / (v + s)]
    e = ln(L / (1 - q + q L)),           L = p1 / p0

pT: a Swerling-1 target of median SNR s (exponential power of mean v + s) with a log-normal RCS
prior; where clutter is, it masks the target. With clutter (c > 0) a weak target (s -> 0) makes
p1 -> p0 and e -> 0 whatever the power: a bin holding far more than the target could give is
explained by the background, not by v (without clutter, the default and every simulated radar's,
a bright bin still says ln(1 / q) of a weak target: ``bounded`` caps it there). q, the chance that a free voxel's bin holds v's echo anyway (the CFAR's
achieved false-alarm rate), bounds the evidence at ln(1 / q), as a detection's is bounded (with
c = 0 and v = 1, L = E_s[exp(x s / (1 + s)) / (1 + s)]: the model without clutter). ``bounded`` then holds
each look's evidence within what a CFAR detection says at its opportunity delta (the chance a
typical target at v would have been detected), +-ln(1 + delta (1 - q) / q): a look that could
hardly have seen v says little of it either way, however strong or weak the bin.
``snr_evidence`` is the quadrature, ``SnrTable`` its table.
"""

import functools
import math
from dataclasses import dataclass

import numpy as np

from radarcl.errors import ConfigError

SNR_U = (-8.0, 16.0, 385)        # u = ln x: the bin's power over the floor, -35 to +69.5 dB (clamped outside)
SNR_V = (-40.0, 16.0, 449)       # v = ln s: the typical target's median SNR, -174 to +69.5 dB
SPREAD_STEPS = 161               # trapezoid nodes over +-8 standard deviations of the log-normal RCS prior
CLUTTER_STEPS = 97               # the same over the clutter's log-normal power
GAP_CAP = 1e-6                   # the gap mixture reads e^e at most (1 - this) / q (L finite)
LN2 = math.log(2.0)
DB = math.log(10.0) / 10.0       # nat per dB of power


@dataclass(frozen=True)
class Clutter:
    """The background where nothing is: exponential noise of mean ``noise_scale`` over the floor
    the interpreter takes, and with the chance ``share`` clutter on it, exponential power of mean
    noise_scale + G, G log-normal with median ``median_db`` and spread ``spread_db`` [dB] (sidelobes
    of strong echoes, multipath, diffuse scatterers). ``share`` 0 and ``noise_scale`` 1: noise
    alone, as the floor assumes (a simulator's world without its harder physics)."""

    share: float = 0.0
    median_db: float = 10.0
    spread_db: float = 10.0
    noise_scale: float = 1.0

    def __post_init__(self):
        if not 0.0 <= self.share < 1.0:
            raise ConfigError(f"the clutter share {self.share!r} is outside [0, 1)")
        if not self.noise_scale > 0.0:
            raise ConfigError(f"the noise scale {self.noise_scale!r} must be positive")

    def ln_density(self, x):
        """ln pC(x): the log-density of clutter power x (array) over the floor (-inf with share 0)."""
        x = np.asarray(x, np.float64)
        if not self.share:
            return np.full(x.shape, -np.inf)
        sigma = self.spread_db * DB
        z = np.linspace(-8.0, 8.0, CLUTTER_STEPS) if sigma else np.zeros(1)
        w = np.exp(-0.5 * z * z)
        mean = self.noise_scale + np.exp(self.median_db * DB + sigma * z)
        terms = -x[..., None] / mean - np.log(mean) + np.log(w / w.sum())
        top = terms.max(axis=-1, keepdims=True)
        return top[..., 0] + np.log(np.exp(terms - top).sum(axis=-1))

    def ln_noise(self, x):
        """ln pN(x): the log-density of noise power x (array)."""
        return -np.asarray(x, np.float64) / self.noise_scale - math.log(self.noise_scale)

    def ln_background(self, x):
        """ln p0(x): noise, or with the chance ``share`` clutter."""
        if not self.share:
            return self.ln_noise(x)
        return np.logaddexp(math.log1p(-self.share) + self.ln_noise(x), math.log(self.share) + self.ln_density(x))


NO_CLUTTER = Clutter()


@dataclass(frozen=True)
class SnrTable:
    """e(u, v) [nat] on a regular grid (``SNR_U`` x ``SNR_V``): the evidence of a bin whose power
    is x = e^u times the beam's noise floor, for a voxel whose typical target has median SNR e^v
    there (module docstring), below ln(1 / q).
    Read bilinearly (``__call__``; the kernel reads the same float32 table the same way); u and v
    outside the grid are clamped to it, and the first column (v = -40: a target 174 dB under the
    noise, whose prior's tail reaches no measurable power) is 0 exactly, so a voxel no target
    could reach gets no evidence."""

    values: np.ndarray               # (SNR_U[2], SNR_V[2]) float64 [nat]
    q: float
    clutter: Clutter = NO_CLUTTER

    @classmethod
    def build(cls, spread_db, q, clutter=NO_CLUTTER):
        """The table of a prior of ``spread_db``, a false-alarm share ``q`` in (0, 1/2] and a
        background ``clutter``; built once per set (``_snr_table``)."""
        return _snr_table(float(spread_db), float(q), clutter)

    def __call__(self, u, v):
        """Bilinear read at u = ln x, v = ln s (arrays, broadcast), float64."""
        fu = _grid_position(u, SNR_U)
        fv = _grid_position(v, SNR_V)
        iu = np.minimum(fu.astype(np.int64), SNR_U[2] - 2)
        iv = np.minimum(fv.astype(np.int64), SNR_V[2] - 2)
        du, dv = fu - iu, fv - iv
        t = self.values
        return ((t[iu, iv] * (1.0 - dv) + t[iu, iv + 1] * dv) * (1.0 - du)
                + (t[iu + 1, iv] * (1.0 - dv) + t[iu + 1, iv + 1] * dv) * du)


def _grid_position(x, grid):
    lo, hi, n = grid
    x = np.asarray(x, np.float64)
    return np.clip((np.where(np.isnan(x), lo, x) - lo) * ((n - 1) / (hi - lo)), 0.0, n - 1.0)


def snr_evidence(x, ln_s, spread_db, q, clutter=NO_CLUTTER):
    """The exact evidence [nat] of power ratios ``x`` (array) for median SNRs e^``ln_s`` (array,
    broadcast) against a background ``clutter``: what the table (``SnrTable``) holds, the
    quadrature it tabulates (trapezoid over the log-normal priors)."""
    x = np.asarray(x, np.float64)
    sigma = spread_db * DB
    z = np.linspace(-8.0, 8.0, SPREAD_STEPS) if sigma else np.zeros(1)
    w = np.exp(-0.5 * z * z)
    w = w / w.sum()
    ln_s = np.asarray(ln_s, np.float64)[..., None] + sigma * z
    mean = clutter.noise_scale + np.exp(np.minimum(ln_s, 700.0))
    terms = -x[..., None] / mean - np.log(mean) + np.log(w)
    top = terms.max(axis=-1, keepdims=True)
    ln_target = top[..., 0] + np.log(np.exp(terms - top).sum(axis=-1))     # ln pT(x; s)
    if clutter.share:
        c, ln_c = clutter.share, clutter.ln_density(x)
        ln_l = (np.logaddexp(math.log1p(-c) + ln_target, math.log(c) + ln_c)
                - np.logaddexp(math.log1p(-c) + clutter.ln_noise(x), math.log(c) + ln_c))
    else:
        ln_l = ln_target - clutter.ln_noise(x)
    return ln_l - np.logaddexp(math.log1p(-q), math.log(q) + ln_l)


@functools.lru_cache(maxsize=8)
def _snr_table(spread_db, q, clutter):
    if not 0.0 < q <= 0.5:
        raise ConfigError(f"the false-alarm share q = {q!r} is outside (0, 0.5]")
    u = np.linspace(*SNR_U)
    v = np.linspace(*SNR_V)
    values = np.empty((len(u), len(v)))
    for i in range(0, len(u), 32):             # 32 rows at a time (memory: rows x columns x SPREAD_STEPS)
        values[i:i + 32] = snr_evidence(np.exp(u[i:i + 32])[:, None], v[None, :], spread_db, q, clutter)
    values[:, 0] = 0.0
    values.setflags(write=False)
    return SnrTable(values, q, clutter)


def likelihood_ratio(e, q):
    """L of the evidence e = ln(L / (1 - q + q L)), with e^e capped just below its bound 1 / q
    (where L is unbounded and a mixture's evidence is ln(1 / q) anyway)."""
    t = np.minimum(np.exp(e), (1.0 - GAP_CAP) / q)
    return t * (1.0 - q) / (1.0 - q * t)


def gap_mixture(e_blocked, e_open, q, gap):
    """Behind nearer echoes that leave a gap with the chance ``gap`` (``sensor_model.blocker_gap``):
    (e, w), the evidence of the mixture L = (1 - gap) L_b + gap L_0 of the likelihood ratios of
    ``e_blocked`` (the target behind the blocker) and ``e_open`` (the target in the gap), and the
    gap's posterior chance w = gap L_0 / L (the kernel: ``write_graded``)."""
    lb = likelihood_ratio(e_blocked, q)
    l0 = likelihood_ratio(e_open, q)
    lm = (1.0 - gap) * lb + gap * l0
    return np.log(lm / (1.0 - q + q * lm)), gap * l0 / lm


NO_CAP = 1e30                    # ``detection_cap`` of a model whose looks are not bounded (finite: 0 x it is 0)


def detection_cap(opportunity, q, bounded=True):
    """ln(1 + delta (1 - q) / q) [nat] of an opportunity delta (array): what a detection says of a
    voxel that a look sees with the chance delta, q the chance it detects anyway (``bounded``);
    ``NO_CAP`` everywhere when the looks are not ``bounded``."""
    d = np.asarray(opportunity, np.float64)
    return np.log1p(d * ((1.0 - q) / q)) if bounded else np.full(d.shape, NO_CAP)


def bounded(e, known, opportunity, q, bound=True):
    """A look's evidence ``e`` [nat] within +-``known`` x ``detection_cap`` of its ``opportunity``:
    the measured power says no more than a CFAR detection would at the look's opportunity, either
    way, scaled by the share of the beam left to see the voxel (``known``: tau, or the gap's
    posterior; by the cap's concavity at most the cap of the blocked opportunity known x delta). A
    look that could hardly have seen the voxel so says little of it, however strong or weak the
    bin; one that sees it says at most ln(1 / q), as a detection does. ``bound`` False: ``e``
    unchanged (``sensor_model.evidence_bound = "none"``)."""
    most = np.asarray(known, np.float64) * detection_cap(opportunity, q, bound)
    return np.clip(e, -most, most)


def noise_floor(profiles, first, last, floor=1e-30):
    """The beams' noise floor [power], (...,): the median power of bins ``first`` .. ``last``
    (the ((last - first + 1) // 2)-th smallest, 0-based: one of the bins, no averaging) / ln 2,
    the mean of exponential noise whose median it is; at least ``floor`` (the CFAR's noise_floor)."""
    r = np.asarray(profiles, np.float64)[..., first:last + 1]
    k = r.shape[-1] // 2
    return np.maximum(np.partition(r, k, axis=-1)[..., k] / LN2, floor)
