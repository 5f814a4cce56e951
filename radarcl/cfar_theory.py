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
"""

import math

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
