"""The detection-statistics sensor model: evidence from the radar's own detection
statistics, a knowledge channel, and correlated evidence counted once.

For a voxel v that a beam covers, the update is the log-likelihood ratio of what the beam
observed in v's range bin, occupied against free:

    no detection:  e = ln((1 - P_v) / (1 - D))          detection:  e = ln(P_v / D)

with P_v = D + (1 - D) delta_v the probability that the bin detects when v holds a typical target,
D the probability that it detects when v is free, and delta_v the voxel's *detection opportunity*:

    delta_v = tau_j (P_d(S_j g(rho2)) - P_fa) / (1 - P_fa)

- P_d(S) is the CFAR's Swerling-1 detection probability at SNR S, P_fa(alpha / (1 + S)) for every
  kind (``cfar_theory``), with the false-alarm rate the pipeline *achieves*: x4 zero padding and
  the Hann window correlate the training cells, so a 1e-3 design CA-CFAR alarms about 8.5e-3 of
  the time (``cfar_theory.achieved_statistics``);
- S_j is the SNR of a typical target at bin j's range on the beam's axis (the radar equation of
  ``scene.observe``: a 1 m^2 target at 10 m gives ``snr_1m2_at_10m_db``), g(rho2) = 4^-kappa rho2
  the two-way gain at the voxel's offset from the axis (kappa < 1 for a target wider than the
  footprint);
- tau_j = exp(-X_j) the fraction of the beam not yet blocked by nearer echoes: X_j sums the
  energy of the pulses that ended before bin j, in units of an opaque beam-filling surface's
  (with "snr" evidence, a blocker may leave a gap: with the chance ``blocker_gap`` v's target
  is unblocked, and the likelihood behind nearer echoes is the mixture of the two);
- D = P_fa on a bin where nothing else is known, and close to 1 on the flanks of a pulse whose
  peak lies elsewhere (its spread explains the detection whether or not v is occupied).

That is the binary outcome (``sensor_model.evidence = "detection"``). The default,
``"snr"``, uses what the bin measured, not only whether it crossed the threshold: the bin's power
over the beam's noise floor, x = r / N (``snr_evidence.noise_floor``: its median power over the
range window / ln 2, the mean of exponential noise), gives the log-likelihood ratio of a typical
target of median SNR s_v = tau_j S_j g(rho2) at v against v free (``snr_evidence.SnrTable``):

    e = ln(L / (1 - q + q L)),   L = E_s[exp(x s / (1 + s)) / (1 + s)]

(Swerling 1 over the known noise: the power is exponential with mean 1 + s; E_s over the
log-normal RCS prior; q = D, the chance that a free voxel's bin holds an echo anyway, bounds the
evidence at ln(1 / q) as the detection's is bounded). An echo the CFAR does not call a detection
(under its threshold, or masked by nearby echoes in its training cells) still counts by its
strength, and the local noise estimate, which nearby echoes inflate, no longer sets the scale.

So beam edges and far ranges give weak free evidence, shadows get none and a strong echo gives
strong evidence. delta_v itself is the knowledge channel: the looks in which an object at v would
have been seen; summed per voxel it tells "never observed" (0) from "observed, undecided".
A look whose knowledge rounds to 0 gives no "snr" evidence either: the reading's look limit counts
only looks with knowledge, and evidence it did not count would add up frame after frame (behind a
blocker, the gap's ln(1 - g) on every quiet bin, and an echo the gap does not explain). The
binary outcome's miss evidence vanishes with delta by itself; a detection's, ln(1 + delta w (1 -
P_fa) / P_fa), keeps up to 1 / (8192 P_fa) nat where delta rounds to 0 (0.014 nat at P_fa 0.0085),
and the fusion's interpolation between a node with knowledge and one without can still round
the knowledge to 0 under up to half a node's evidence: the limit holds for most looks, not all.

The CFAR still finds the pulses: a pulse's energy (with "snr", its summed (x - 1)+ over the floor)
blocks the beam behind it, and delta, the knowledge, stays the CFAR's detection opportunity.

Correlated evidence: looks from one viewpoint share speckle and model error, so they are not
independent. The grid keeps exact integer sums (order-independent), and the number of looks n;
the reading divides the evidence E of a voxel looked at more than ``look_limit`` times by
n / look_limit (``read_log_odds``): at most that many looks' worth of mean evidence, however
many scans. The reading adds the prior, the world's base rate of occupied voxels, everywhere: a
voxel never observed reads that calibrated probability, and is told unknown by its knowledge.

The node pairs, what the interpreter writes and the fusion reads: ``radarcl.node_pairs``.
"""

import functools
import math
from dataclasses import dataclass, fields

import numpy as np

from radarcl import cfar_theory, logodds
from radarcl.errors import ConfigError
from radarcl.node_pairs import NODES
from radarcl.snr_evidence import Clutter, SnrTable

# -- the physical parameters ---------------------------------------------------------------------------------------
# Each key's physical range: a value outside is refused with the key, the value and the range.
RANGES = {   # key: (lo, hi, unit, what it is)
    "snr_1m2_at_10m_db": (0.0, 120.0, "dB", "SNR of a 1 m^2 target at 10 m on the beam's axis (the sensor's sensitivity)"),
    "target_gamma_db": (-40.0, 10.0, "dB", "reflectivity of a typical occupied voxel's upright surface"),
    "target_spread_db": (0.0, 15.0, "dB", "log-normal spread of the typical target's mean RCS"),
    "target_extent_m": (0.01, 10.0, "m", "side of the typical target's patch"),
    "terrain_gamma_db": (-40.0, 10.0, "dB", "reflectivity of the terrain at grazing incidence"),
    "terrain_band_m": (0.0, 10.0, "m", "voxels whose centre lies below the ground plane + this are terrain"),
    "block_gamma_db": (-40.0, 10.0, "dB", "a detected echo blocks the beam as an opaque surface of this reflectivity"),
    "blocker_gap": (0.0, 0.5, "", "the chance that a voxel behind nearer echoes lies in a gap they leave "
                                  "(partial blockers)"),
    "look_limit": (0.5, 1e4, "looks", "correlated evidence counts at most this many looks' worth"),
    "prior_nats": (-10.0, 0.0, "nat", "log-odds of an occupied voxel before any look (the world's base rate)"),
    "prior_looks": (0.0, 100.0, "looks", "looks at which the prior applies in full (0: everywhere, never-observed "
                                         "voxels too)"),
    "false_alarm": (0.0, 0.5, "", "a measured false-alarm rate of the CFAR on these profiles (0: from its "
                                  "statistics)"),
    "clutter_share": (0.0, 0.99, "", "the chance that a bin holds clutter where nothing is (sidelobes, multipath, "
                                     "diffuse scatterers; 0: noise alone)"),
    "clutter_db": (-20.0, 80.0, "dB", "the clutter's median power over the noise floor"),
    "clutter_spread_db": (0.0, 30.0, "dB", "log-normal spread of the clutter's power"),
    "noise_scale": (0.1, 10.0, "", "the noise's mean over the floor the interpreter takes (the window's median / "
                                   "ln 2; 1: noise alone sets the median)"),
}
EVIDENCE_KINDS = ("snr", "detection")             # sensor_model.evidence: the measured SNR, or the CFAR's outcome
EVIDENCE_BOUNDS = ("detection", "none")           # sensor_model.evidence_bound: a look says no more than a detection
GROUND_RANGE = (0.0, 1000.0, "m")                 # ground_below_m: the sensor's height above the ground plane (0: none)
DEFAULT_SNR_DB = 50.0                             # the sensitivity assumed for a profile that gives none
BLOCKER_GAP = 0.01                                # sensor_model.blocker_gap's default (ModelParams)
# the least gap other than 0: below it the mixture's posterior rests on a likelihood ratio at its
# cap, whose float32 rounding the device's nodes amplify by up to 1 / gap (a gap that small is no
# gap a map could tell from none)
BLOCKER_GAP_MIN = 1e-4
READING = ("look_limit", "prior_nats", "prior_looks", "known_looks")   # what a map keeps to be read (``read_log_odds``)
KNOWN_LOOKS = 0.5                 # a voxel whose knowledge reaches this many looks is observed; below, it reads the prior
PRIOR_VOXEL_M = 0.2               # the voxel at which the default priors are the base rate (``prior_for_voxel``)


@dataclass(frozen=True)
class ModelParams:
    """The physical parameters of the detection-statistics model (``RANGES``; configuration keys
    ``sensor_model.<name>``; the sensor's ``[sensitivity] snr_1m2_at_10m_db`` for the first).
    ``ground_below_m``: the sensor's height above the ground plane (0: no terrain class, e.g. a
    spinning radar's one horizontal beam)."""

    snr_1m2_at_10m_db: float = DEFAULT_SNR_DB
    # the typical target and the terrain: fitted by maximum likelihood on the training scenes
    # (`radarcl calibrate --model detstats`; the fit and its errors: docs/design/models.md). A
    # simulator's world: a real radar's may differ.
    target_gamma_db: float = -20.0
    target_spread_db: float = 10.0
    target_extent_m: float = 0.4
    terrain_gamma_db: float = -24.0
    terrain_band_m: float = 0.3
    # how much echo blocks the beam: no likelihood identifies it (what lies behind the first surface
    # has no truth a radar could know), so it is the least blocking whose maps of the training
    # scenes keep the obstacles from reading free (the rule and the candidates: docs/design/models.md)
    block_gamma_db: float = -26.0
    # a blocker is often partial (a car below a fan beam, a post in a wide one): behind nearer echoes
    # the power's likelihood is a mixture, the blocked target's and (with this chance) the unblocked
    # one's; chosen as block_gamma_db is
    blocker_gap: float = BLOCKER_GAP
    # the reading: an unconstrained fit would call obstacles free to get the free air right, so it
    # is the best likelihood among the readings whose training maps meet the calibration and
    # false-free goals (docs/design/models.md). The prior is the base rate: it falls with the voxel.
    look_limit: float = 2.0
    prior_nats: float = -4.0
    prior_looks: float = 0.0
    false_alarm: float = 0.0
    # the background where nothing is, beyond exponential noise (``snr_evidence.Clutter``): none in a
    # simulator's world; a real radar's is fitted from its recording (``radarcl fit-sensor``)
    clutter_share: float = 0.0
    clutter_db: float = 10.0
    clutter_spread_db: float = 10.0
    noise_scale: float = 1.0
    ground_below_m: float = 0.0
    evidence: str = "snr"
    # a look says no more than a detection would at its opportunity (snr_evidence.bounded): a real
    # radar's strong echo where no typical target could be is a sidelobe, multipath or clutter as
    # often as a target; "none" scores a world without them
    evidence_bound: str = "detection"

    def __post_init__(self):
        for name, (lo, hi, unit, _) in RANGES.items():
            check_range(f"sensor_model.{name}", getattr(self, name), lo, hi, unit)
        check_range("sensor_model.ground_below_m", self.ground_below_m, *GROUND_RANGE)
        if 0.0 < self.blocker_gap < BLOCKER_GAP_MIN:
            raise ConfigError(f"sensor_model.blocker_gap = {self.blocker_gap:g}: expected 0 (no gap) or at least "
                              f"{BLOCKER_GAP_MIN:g} (a smaller gap is below what the device's float32 mixture "
                              "resolves, and no map could tell it from none)")
        if self.evidence not in EVIDENCE_KINDS:
            raise ConfigError(f"sensor_model.evidence = {self.evidence!r}: expected one of {', '.join(EVIDENCE_KINDS)}")
        if self.evidence_bound not in EVIDENCE_BOUNDS:
            raise ConfigError(f"sensor_model.evidence_bound = {self.evidence_bound!r}: expected one of "
                              f"{', '.join(EVIDENCE_BOUNDS)}")

    @classmethod
    def of(cls, values):
        """From configuration values {"sensor_model.<name>": value} (what is missing: the defaults)."""
        names = [f.name for f in fields(cls)]
        return cls(**{n: values[f"sensor_model.{n}"] for n in names if f"sensor_model.{n}" in values})

    @property
    def reading(self):
        """The parameters a map is read with (``read_log_odds``), as a dict."""
        return {**{k: float(getattr(self, k)) for k in READING if k != "known_looks"}, "known_looks": KNOWN_LOOKS}

    @property
    def clutter(self):
        """The background law (``snr_evidence.Clutter``) of the "snr" evidence."""
        return Clutter(self.clutter_share, self.clutter_db, self.clutter_spread_db, self.noise_scale)


DEFAULTS = {f.name: f.default for f in fields(ModelParams)}


def prior_for_voxel(prior_nats, voxel_m):
    """A prior fitted at ``PRIOR_VOXEL_M`` as the base rate at ``voxel_m``: surfaces fill a share of
    space in proportion to the voxel's edge, so the odds of an occupied voxel scale with it:
    prior + ln(voxel_m / PRIOR_VOXEL_M) (-4 nat at 0.2 m: -4.69 at 0.1 m, -3.31 at 0.4 m)."""
    return float(prior_nats) + math.log(float(voxel_m) / PRIOR_VOXEL_M)


def terrain_dz(params):
    """The fusion's terrain test: a voxel whose centre lies below its beam's origin by more than
    ground_below_m - terrain_band_m is terrain (-inf without a ground plane)."""
    return params.terrain_band_m - params.ground_below_m if params.ground_below_m else -math.inf


def check_range(key, value, lo, hi, unit=""):
    """``value`` as a float, or ConfigError naming the key, the value and its physical range."""
    if isinstance(value, bool) or not isinstance(value, (int, float, np.floating, np.integer)) \
            or not math.isfinite(value) or not lo <= value <= hi:
        raise ConfigError(f"{key} = {value!r} is outside its physical range [{lo:g}, {hi:g}]{' ' + unit if unit else ''}")
    return float(value)


# -- P_d of the CFAR against the SNR, with the prior over the target's RCS ------------------------------------------
TABLE_X = (-7.0, 16.0)           # ln S from -30 to 70 dB
TABLE_POINTS = 1024
HERMITE_NODES = 32               # Gauss-Hermite nodes over the log-normal RCS spread
HANN_ENBW = 1.5                  # equivalent noise bandwidth of the Hann window [bins of the unpadded FFT]


def hann(n):
    """The periodic Hann window (``oracle.window_coefficients("hann", n)``, which sits a layer up)."""
    return 0.5 - 0.5 * np.cos(2.0 * np.pi * np.arange(n) / n)


@dataclass(frozen=True)
class DetectionTable:
    """delta(x) = (P_d(e^x) - P_fa) / (1 - P_fa) on x = ln S (``TABLE_X``, ``TABLE_POINTS``
    points): the CFAR's Swerling-1 P_d averaged over a log-normal mean RCS of ``spread_db``, with
    the false-alarm rate the pipeline achieves (``pfa``: cells correlated by ``oversampling``
    bins per resolution cell of a Hann-windowed FFT; ``oversampling`` None: independent cells)."""

    x: np.ndarray
    delta: np.ndarray
    pfa: float

    @classmethod
    def build(cls, kind, factor, n_train, rank=None, oversampling=4.0, spread_db=0.0):
        """The table of a CFAR (``CfarConfig``'s kind, factor, n_train, rank); built once per
        set of arguments (``_detection_table``)."""
        return _detection_table(kind, float(factor), int(n_train), rank, oversampling, float(spread_db))

    def __call__(self, ln_snr):
        """delta at ln S (array), linear in x between points; 0 below the table, its last value above."""
        return np.interp(ln_snr, self.x, self.delta, left=0.0, right=float(self.delta[-1]))


@functools.lru_cache(maxsize=32)
def _detection_table(kind, factor, n_train, rank, oversampling, spread_db):
    corr = None if oversampling is None else cfar_theory.training_correlation(
        hann(256), oversampling, _guard_for(oversampling), n_train // 2)
    x = np.linspace(*TABLE_X, TABLE_POINTS)
    # P_d of one SNR on a wider grid (the spread reaches 3.4 of its widths either side), then the
    # log-normal average over Gauss-Hermite nodes by interpolation in ln S: the correlated
    # kinds' Monte Carlo is evaluated at TABLE_POINTS SNRs, not at every node of every point
    z, w = np.polynomial.hermite_e.hermegauss(HERMITE_NODES)
    w = w / w.sum()
    reach = spread_db * math.log(10.0) / 10.0 * float(np.abs(z).max())
    base = np.linspace(TABLE_X[0] - reach, TABLE_X[1] + reach, TABLE_POINTS + int(TABLE_POINTS * 2 * reach / 23.0))
    curve = cfar_theory.detection_curve(kind, factor, n_train, np.exp(base), rank, corr)
    ln_s = x[:, None] + spread_db * math.log(10.0) / 10.0 * z[None, :]
    pd = (np.interp(ln_s, base, curve) * w).sum(axis=1)
    pfa = float(cfar_theory.detection_curve(kind, factor, n_train, [0.0], rank, corr)[0])
    return DetectionTable(x, np.clip((pd - pfa) / (1.0 - pfa), 0.0, 1.0), pfa)


def _guard_for(oversampling):
    # The guard only has to keep the cell under test out of the training cells' correlation
    # (two resolution cells); the training cells' own correlation does not depend on it.
    return int(math.ceil(2 * oversampling))


# -- the radar equation per bin ---------------------------------------------------------------------------------------
R_REF_M = 10.0


def beam_solid_angle(half_az_rad, half_el_rad):
    """Effective solid angle of the two-way pattern 4^-rho2 over the plane: pi h_az h_el / ln 4 [sr]."""
    return math.pi * half_az_rad * half_el_rad / math.log(4.0)


def upright_snr(params, ranges_m, half_az_rad, half_el_rad):
    """Per range (array [m]): (ln S, kappa) of the typical upright target on the beam's axis: a
    square patch of side ``target_extent_m`` and reflectivity ``target_gamma_db`` seen through the
    two-way Gaussian pattern. Per axis, a patch of angular std a = extent / (r sqrt 12) against
    the pattern's std s = h / sqrt(2 ln 4) keeps s / sqrt(s^2 + a^2) of a point's gain and falls
    off the axis as 4^-(kappa rho2), kappa = s^2 / (s^2 + a^2) (a point: kappa 1; a wall wider
    than the footprint: kappa -> 0, its echo no longer depends on where in the beam v lies).
    kappa is the mean of the two axes' (the fusion knows rho2, not its parts)."""
    r = np.maximum(np.asarray(ranges_m, np.float64), 1e-3)
    s1 = 10.0 ** (params.snr_1m2_at_10m_db / 10.0)
    gamma = 10.0 ** (params.target_gamma_db / 10.0)
    ell = params.target_extent_m
    gain, kappa = 1.0, 0.0
    for h in (half_az_rad, half_el_rad):
        s2 = h * h / (2.0 * math.log(4.0))
        a2 = (ell / r) ** 2 / 12.0
        gain = gain * np.sqrt(s2 / (s2 + a2))
        kappa = kappa + 0.5 * s2 / (s2 + a2)
    return np.log(s1 * gamma * ell * ell * gain * (R_REF_M / r) ** 4), kappa


def terrain_snr(params, ranges_m, voxel_m):
    """Per range: ln S of a voxel's patch of terrain (``terrain_gamma_db``, horizontal area
    voxel^2) seen at the grazing angle psi from ``ground_below_m`` (sin psi = h / r): a point in
    angle (kappa 1). -inf everywhere without a ground plane (``ground_below_m`` 0)."""
    r = np.maximum(np.asarray(ranges_m, np.float64), 1e-3)
    if not params.ground_below_m:
        return np.full(r.shape, -np.inf)
    s1 = 10.0 ** (params.snr_1m2_at_10m_db / 10.0)
    gamma = 10.0 ** (params.terrain_gamma_db / 10.0)
    grazing = np.minimum(1.0, params.ground_below_m / r)
    return np.log(s1 * gamma * voxel_m * voxel_m * grazing * (R_REF_M / r) ** 4)


def block_snr(params, ranges_m, half_az_rad, half_el_rad):
    """Per range: the SNR of an opaque beam-filling surface of ``block_gamma_db``: the energy
    that blocks the whole beam (the unit of the occlusion walk)."""
    r = np.maximum(np.asarray(ranges_m, np.float64), 1e-3)
    s1 = 10.0 ** (params.snr_1m2_at_10m_db / 10.0)
    return s1 * 10.0 ** (params.block_gamma_db / 10.0) * r * r * beam_solid_angle(half_az_rad, half_el_rad) \
        * (R_REF_M / r) ** 4


@dataclass(frozen=True)
class BinModel:
    """What the interpreter needs of the model for one sensor, CFAR, range grid and voxel size:
    ``opportunity`` (n_bins, CLASSES, NODES) delta at tau = 1 (no blocking yet) per bin, class and
    node rho2 = k / 4; ``blocking`` (n_bins,) 1 / (S_block x noise_bins): a pulse's summed
    (r/n - 1)+ times the blocking at its peak is its share of an opaque beam-filling surface
    (``noise_bins``, the bins one echo's power spreads over: the window's equivalent noise
    bandwidth times the bins per resolution cell, 6 for the paper's Hann window padded x4);
    ``miss`` 1 - opportunity (kept apart: in float32 1 - delta would lose the digits that matter
    when delta is close to 1); ``pfa`` the achieved false-alarm rate. "snr" evidence also needs
    ``ln_snr`` (n_bins, CLASSES, NODES), ln of the typical target's median SNR per bin, class and
    node at tau = 1 (-inf: no such target, e.g. terrain without a ground plane), its ``snr_table``
    and the CFAR's ``noise_floor``, ``blocker_gap`` and whether each look is ``bounded`` by what a
    detection says (``ModelParams``); without a table the evidence is the CFAR's outcome (whose
    blocking is hard: no gap)."""

    opportunity: np.ndarray
    miss: np.ndarray
    blocking: np.ndarray
    pfa: float
    ln_snr: np.ndarray = None
    snr_table: SnrTable = None
    noise_floor: float = 1e-30
    blocker_gap: float = 0.0
    bounded: bool = True

    @property
    def graded(self):
        """True for "snr" evidence (the measured power's likelihood ratio), False for the CFAR's outcome."""
        return self.snr_table is not None

    @classmethod
    def build(cls, params, cfar, n_bins, bin_spacing_m, oversampling, half_az_rad, half_el_rad, voxel_m,
              range_min_m=0.0):
        """For ``params`` (``ModelParams``), a ``CfarConfig``, bins j at j x ``bin_spacing_m``,
        ``oversampling`` bins per resolution cell (None: treat the cells as independent), the
        beam's half-power half-widths [rad] and the grid's voxel [m]; ``range_min_m``: the
        nearest range the interpreter reads (where a measured false-alarm rate is checked)."""
        table = DetectionTable.build(cfar.kind, cfar.alpha, cfar.n_train, cfar.rank, oversampling,
                                     params.target_spread_db)
        ranges = np.arange(n_bins) * float(bin_spacing_m)
        t = np.arange(NODES) / (NODES - 1) * math.log(4.0)
        ln_up, kappa = upright_snr(params, ranges, half_az_rad, half_el_rad)
        ln_ter = terrain_snr(params, ranges, voxel_m)
        ln_snr = np.stack([ln_up[:, None] - kappa[:, None] * t[None, :], ln_ter[:, None] - t[None, :]], axis=1)
        opportunity = table(ln_snr)
        cells = 1.0 if oversampling is None else float(oversampling)
        blocking = 1.0 / (block_snr(params, ranges, half_az_rad, half_el_rad) * HANN_ENBW * cells)
        pfa = table.pfa
        if params.false_alarm:
            # P_d must lie in (P_fa, 1): a measured rate at or above the best P_d the typical target
            # reaches anywhere in the range window would make every look worthless (delta 0), silently
            read = ranges >= range_min_m
            best = float(table.pfa + (1.0 - table.pfa) * opportunity[read, 0, 0].max(initial=0.0))
            if params.false_alarm >= best:
                raise ConfigError(f"sensor_model.false_alarm = {params.false_alarm!r} leaves P_d outside (P_fa, 1): "
                                  f"the typical target's P_d is at most {best:.3g} here (sensor_model.target_gamma_db "
                                  f"= {params.target_gamma_db:g} dB at {params.snr_1m2_at_10m_db:g} dB sensitivity); "
                                  f"expected a false-alarm rate in [0, {best:.3g})")
        if params.false_alarm > pfa:
            # a measured rate above the statistics' (profiles whose noise is not exponential, clutter):
            # the same P_d, less of it beyond what noise alone gives
            pd = table.pfa + (1.0 - table.pfa) * opportunity
            pfa = params.false_alarm
            opportunity = np.clip((pd - pfa) / (1.0 - pfa), 0.0, 1.0)
        if params.evidence == "detection":
            return cls(opportunity, 1.0 - opportunity, blocking, pfa)
        return cls(opportunity, 1.0 - opportunity, blocking, pfa, ln_snr,
                   SnrTable.build(params.target_spread_db, min(pfa, 0.5), params.clutter), float(cfar.noise_floor),
                   params.blocker_gap, params.evidence_bound == "detection")


# -- the reading: correlated evidence and the prior ---------------------------------------------------------------------
def read_log_odds(evidence, knowledge, looks, reading):
    """Log-odds [nat] of stored sums, order-independent (a function of the exact integer sums):

        L = E / max(1, n / look_limit) + prior_nats x min(1, K / prior_looks)   where K >= known_looks,
        L = the prior alone                                                     elsewhere

    with E = ``evidence`` [logodds units], K = ``knowledge`` [KNOWLEDGE_SCALE units] in looks and
    n = ``looks`` the number of looks with an opportunity, ``reading`` a dict of ``READING``.
    Correlated looks (one viewpoint, one speckle, a partial blocker seen again) count at most
    ``look_limit`` looks' worth of their mean evidence, however many scans. Where E saturates
    (``gridspec.GRID_LIMIT``) the fusion stops counting looks, so the mean does not fade.

    The prior is the log-odds of an occupied voxel before any look: the world's base rate. With
    ``prior_looks`` 0 (the default) it applies everywhere, so a voxel never observed reads the base
    rate, a calibrated probability. A voxel with less than ``known_looks`` of knowledge is
    unobserved (``maps.map`` classes it so): it reads the prior whatever evidence reached it, so
    every query and export agrees with the map's classes. ``known_looks`` 0 (maps written before
    it was kept, whose reading lacks it) reads every voxel by its sums; ``prior_looks`` > 0 (maps
    written before that default) grows the prior with the knowledge, and a voxel never observed
    reads 0."""
    e = np.asarray(evidence, np.float64) / logodds.SCALE
    out = e / np.maximum(1.0, np.asarray(looks, np.float64) / float(reading["look_limit"]))
    prior = float(reading.get("prior_nats", 0.0))
    k = np.asarray(knowledge, np.float64)
    if prior and float(reading["prior_looks"]) > 0.0:
        prior = prior * np.minimum(1.0, k / logodds.KNOWLEDGE_SCALE / float(reading["prior_looks"]))
    known_looks = float(reading.get("known_looks", 0.0))
    if known_looks:
        out = np.where(k >= known_looks * logodds.KNOWLEDGE_SCALE, out, 0.0)
    return out + prior
