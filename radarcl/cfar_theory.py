"""CFAR detection theory: threshold factors from a design false-alarm probability, and the
detection probability of a fluctuating target (paper §3.3, Fig. 6).

Model (Richards, *Fundamentals of Radar Signal Processing*, §6.5): a square-law detector, so
noise power in every cell is exponential with an unknown mean, cells independent. The cell
under test is declared a detection when its power exceeds ``factor x estimate``, where the
estimate is formed from ``n`` training cells (``n/2`` per side):

========  ==========================================  ===========================================
kind      noise estimate                              P_fa(factor)
========  ==========================================  ===========================================
``ca``    mean of the n cells                         (1 + a/n)^-n, so a = n (P_fa^(-1/n) - 1)
``go``    greater of the two half means               2 (1+t)^-m - P_so(t),  t = a/m, m = n/2
``so``    smaller of the two half means               2 sum_k C(m-1+k, k) (2+t)^-(m+k), k < m
``os``    k-th smallest of the n cells (rank k)       prod_{i<k} (n-i) / (n-i+a)
========  ==========================================  ===========================================

(GO and SO: Gandhi & Kassam, IEEE Trans. AES 24(4), 1988; OS: Rohling, IEEE Trans. AES 19(4),
1983.) A Swerling 1 target of signal-to-noise ratio S makes the cell under test exponential
with mean (1 + S), so its detection probability is the same function at factor / (1 + S):
for CA that is the textbook P_d = (1 + a / (n (1 + S)))^-n.

Zero padding and windows correlate neighbouring range bins, so on real profiles the training
cells are not independent and the achieved P_fa departs from the design value; the design
holds exactly only for independent cells (tests/test_cfar_calibration.py measures it).
``detection_curve`` gives P_d(S) for correlated cells too: the identity
P_d(S) = E_Z[exp(-factor Z / (1 + S))] holds for any noise estimate Z independent of the cell
under test (a guard of at least two resolution cells makes it so), so with the cells' complex
correlation matrix C (``training_correlation``: window and zero padding) it is exact for CA,
prod_i (1 + factor lambda_i / (n (1 + S)))^-1 over C's eigenvalues, and a conditional Monte Carlo
over draws of Z for GO, SO and OS (exact in expectation, smooth in S). With the paper's x4
padding and Hann window, a design P_fa of 1e-3 achieves 8.47e-3 (CA), 5.9e-3 (GO), 2.9e-2 (SO)
and 7.9e-3 (OS), measured through the oracle's range FFT and CFAR (tests/test_cfar_calibration.py).
"""

import math

import numpy as np

from radarcl.errors import ConfigError

CFAR_KINDS = ("ca", "go", "so", "os")


def _so_pfa(t, m):
    # sum_k C(m-1+k, k) (2+t)^-(m+k), each term in logs: C(m-1+k, k) overflows a float beyond
    # m ~ 516 training cells, the powers underflow, their products do neither.
    log_base = math.log(2.0 + t)
    total = 0.0
    for k in range(m):
        log_term = (math.lgamma(m + k) - math.lgamma(k + 1) - math.lgamma(m)) - (m + k) * log_base
        total += math.exp(log_term)
    return 2.0 * total


def false_alarm_probability(kind, factor, n_train, rank=None):
    """P_fa of a ``kind`` CFAR with ``n_train`` independent exponential training cells in all
    (both sides) and threshold ``factor`` times its noise estimate (see the module table).
    ``rank`` (1-based, OS only) is the order statistic used as the estimate."""
    _check_kind(kind, n_train, rank)
    a = float(factor)
    if a < 0:
        raise ConfigError(f"the threshold factor must be >= 0, got {factor!r}")
    n, m = int(n_train), int(n_train) // 2
    if kind == "ca":
        return (1.0 + a / n) ** -n
    if kind == "so":
        return _so_pfa(a / m, m)
    if kind == "go":
        return 2.0 * (1.0 + a / m) ** -m - _so_pfa(a / m, m)
    pfa = 1.0
    for i in range(int(rank)):
        pfa *= (n - i) / (n - i + a)
    return pfa


def detection_probability_swerling1(kind, factor, n_train, snr, rank=None):
    """P_d of a Swerling 1 target of linear signal-to-noise ratio ``snr`` (>= 0) in the cell under
    test: ``false_alarm_probability`` at factor / (1 + snr)."""
    if not snr >= 0:
        raise ConfigError(f"snr must be >= 0 (linear power ratio), got {snr!r}")
    return false_alarm_probability(kind, float(factor) / (1.0 + snr), n_train, rank)


def threshold_factor(kind, pfa, n_train, rank=None):
    """The factor that gives the design false-alarm probability ``pfa`` in (0, 1).

    Closed form for CA; bisection in float64 to 1e-15 relative for GO, SO and OS, whose
    P_fa falls monotonically with the factor. Raises ConfigError when no factor reaches
    ``pfa``: at factor 0 every detector alarms on every cell (P_fa = 1), but SO's series sums a
    few ulp below 1 in float64, and a pfa in that gap is refused; so is one below what the
    largest finite factor gives."""
    _check_kind(kind, n_train, rank)
    if not (isinstance(pfa, (int, float)) and 0.0 < pfa < 1.0):
        raise ConfigError(f"pfa must lie strictly between 0 and 1, got {pfa!r}")
    n = int(n_train)
    if kind == "ca":
        return n * (pfa ** (-1.0 / n) - 1.0)
    at_zero = false_alarm_probability(kind, 0.0, n, rank)
    if pfa >= at_zero:
        raise ConfigError(f"a {kind.upper()} CFAR with {n} training cells has P_fa = {at_zero:.3g} at "
                          f"threshold factor 0, so it cannot reach pfa = {pfa!r}; ask for a smaller pfa")
    lo, hi = 0.0, 1.0
    while false_alarm_probability(kind, hi, n, rank) > pfa:
        hi *= 2.0
        if hi > 1e300:
            raise ConfigError(f"no finite threshold factor reaches pfa = {pfa!r}")
    for _ in range(200):
        mid = 0.5 * (lo + hi)
        if false_alarm_probability(kind, mid, n, rank) > pfa:
            lo = mid
        else:
            hi = mid
        if hi - lo <= 1e-15 * hi:
            break
    return hi


def default_rank(n_train):
    """Rohling's usual OS-CFAR rank: k = round(3n/4), which tolerates n/4 interfering targets."""
    return max(1, round(0.75 * int(n_train)))


def _check_kind(kind, n_train, rank):
    if kind not in CFAR_KINDS:
        raise ConfigError(f"CFAR kind must be one of {CFAR_KINDS}, got {kind!r}")
    if not (isinstance(n_train, int) and n_train >= 2 and n_train % 2 == 0):
        raise ConfigError(f"the number of training cells must be an even integer >= 2 "
                          f"(n/2 per side), got {n_train!r}")
    if kind == "os":
        if not (isinstance(rank, int) and 1 <= rank <= n_train):
            raise ConfigError(f"OS-CFAR rank must be an integer in [1, {n_train}] "
                              f"(the k-th smallest of the training cells), got {rank!r}")


# -- vectorised and correlated-cell statistics (the detection-statistics model, radarcl.sensor_model) ----------
def false_alarm_curve(kind, factors, n_train, rank=None):
    """``false_alarm_probability`` for an array of threshold factors (independent cells), float64."""
    _check_kind(kind, n_train, rank)
    a = np.asarray(factors, np.float64)
    n, m = int(n_train), int(n_train) // 2
    if kind == "ca":
        return np.exp(-n * np.log1p(a / n))
    if kind in ("so", "go"):
        t = a / m
        k = np.arange(m)
        log_c = np.array([math.lgamma(m + i) - math.lgamma(i + 1) - math.lgamma(m) for i in k])
        terms = log_c - (m + k) * np.log(2.0 + t)[..., None]
        top = terms.max(axis=-1, keepdims=True)
        so = 2.0 * np.exp(top[..., 0] + np.log(np.exp(terms - top).sum(axis=-1)))
        return so if kind == "so" else 2.0 * np.exp(-m * np.log1p(t)) - so
    k = int(rank)
    lg = np.vectorize(math.lgamma, otypes=[np.float64])
    return np.exp(math.lgamma(n + 1) - math.lgamma(n - k + 1) + lg(n - k + 1 + a) - lg(n + 1 + a))


def training_correlation(window, oversampling, guard, train):
    """(2 train, 2 train) complex correlation of the training cells' spectral values for white
    noise: c(k) = sum_j w_j^2 exp(-2 pi i k j / (oversampling x len(w))) / sum_j w_j^2 for cells
    k bins apart (window ``window`` coefficients; ``oversampling`` = bins per resolution cell,
    n_fft / n_samples for a zero-padded FFT). Cells ``guard`` + 1 .. ``guard`` + ``train`` on
    each side of the cell under test (the interior of a profile)."""
    w2 = np.asarray(window, np.float64) ** 2
    j = np.arange(len(w2))
    cells = np.r_[np.arange(-guard - train, -guard), np.arange(guard + 1, guard + train + 1)]
    d = (cells[:, None] - cells[None, :]).astype(np.float64)
    phase = np.exp(-2j * np.pi * d[..., None] * j / (float(oversampling) * len(w2)))
    return (w2 * phase).sum(axis=-1) / w2.sum()


def estimate_draws(kind, corr, rank=None, draws=1 << 16, seed=0):
    """Draws of the normalised noise estimate Z (noise mean 1) of a ``kind`` CFAR whose training
    cells have complex correlation ``corr`` (``training_correlation``): exponential cells made
    correlated through the Cholesky factor of ``corr``, a fixed seed (the same draws every call)."""
    c = np.asarray(corr)
    n = len(c)
    _check_kind(kind, n, rank)
    m = n // 2
    chol = np.linalg.cholesky(c + 1e-12 * np.eye(n))
    rng = np.random.default_rng(seed)
    z = (rng.standard_normal((draws, n)) + 1j * rng.standard_normal((draws, n))) / math.sqrt(2.0)
    x = np.abs(z @ chol.T) ** 2
    if kind == "ca":
        return x.mean(axis=1)
    if kind == "go":
        return np.maximum(x[:, :m].mean(axis=1), x[:, m:].mean(axis=1))
    if kind == "so":
        return np.minimum(x[:, :m].mean(axis=1), x[:, m:].mean(axis=1))
    return np.sort(x, axis=1)[:, int(rank) - 1]


def detection_curve(kind, factor, n_train, snr, rank=None, corr=None, draws=1 << 16):
    """P_d of a Swerling-1 target at linear SNRs ``snr`` (array, >= 0): with ``corr`` None the
    independent-cell formula (``false_alarm_curve`` at factor / (1 + S)); with a correlation
    matrix (``training_correlation``) exact for CA (eigenvalues) and a conditional Monte Carlo
    of ``draws`` fixed draws for GO, SO and OS (module docstring). P_d(0) is the achieved P_fa."""
    s = np.asarray(snr, np.float64)
    if (s < 0).any() or not np.isfinite(s).all():
        raise ConfigError("snr must be finite and >= 0 (linear power ratios)")
    scaled = float(factor) / (1.0 + s)
    if corr is None:
        return false_alarm_curve(kind, scaled, n_train, rank)
    c = np.asarray(corr)
    if c.shape != (n_train, n_train):
        raise ConfigError(f"the correlation of {n_train} training cells must be ({n_train}, {n_train}), got {c.shape}")
    if kind == "ca":
        lam = np.clip(np.linalg.eigvalsh(c), 0.0, None)
        return np.exp(-np.log1p(np.multiply.outer(scaled / n_train, lam)).sum(axis=-1))
    z = estimate_draws(kind, c, rank, draws)
    flat = scaled.reshape(-1)
    out = np.empty(flat.shape)
    for i in range(0, len(flat), 64):          # 64 SNRs x the draws at a time (memory)
        out[i:i + 64] = np.exp(-np.multiply.outer(flat[i:i + 64], z)).mean(axis=-1)
    return out.reshape(scaled.shape)
