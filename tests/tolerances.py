"""Named tolerances, each with its reason. Integer results are compared exactly, never here."""

# Range FFT in float32 against the float64 oracle: max |kernel - oracle| / max |oracle| per frame.
# Rounding in an N-point FFT grows like eps32 * log2(N) (eps32 = 6e-8); measured <= 2e-7 for
# N = 1024 with float64-exact twiddles. 2e-6 leaves room up to N = 4096 and for other devices.
RANGE_FFT_RTOL = 2e-6

# A tone 120 dB below a full-scale one, both on bin centres with a rectangular window (no
# leakage): the float32 transform's rounding floor is ~ -140 dB of the peak, so the weak tone's
# bin is recovered to within this relative error.
WEAK_TONE_RTOL = 0.05

# CFAR noise estimates and ratios in float32 against the float64 oracle, relative: a direct sum
# of 2 x train <= 64 cells rounds by at most 64 eps32 = 4e-6 (measured 2e-7 with 32 cells).
CFAR_RTOL = 1e-5

# A detection decision r > alpha n can only differ between float32 and float64 where r lies
# within a few float32 roundings of the threshold: bins closer than this (relative) are not
# compared, and the test asserts that they are rare.
DECISION_MARGIN = 1e-5

# Evidence on pulse bins is k_occ (log10 r - log10 n) x 1024 rounded to an integer: float32 logs
# differ from float64 by ~1e-6 nat, so the rounding may fall one unit apart. Noise bins (E_h,
# E_l, 0) carry no arithmetic and are compared exactly.
EVIDENCE_UNITS_TOL = 1

# Fusion decides in float32 whether a voxel centre is inside a beam (rho2 <= 1, d > 0) and which
# bin its range falls in (rint(r / spacing)). Coordinates of ~100 m carry float32 errors of
# ~1e-5 m, so decisions within this margin (in rho2, and in bins) of their boundary may go either
# way; such voxels are not compared, and the tests assert that they are rare.
FUSION_DECISION_MARGIN = 1e-3

# With the Gaussian weight, an update is rint(e * 4^-rho2): float32 and float64 products agree
# to ~1e-6 relative (e <= 16384 units, so < 0.02 unit), so the rounding may fall one unit apart
# per update: |kernel - oracle| <= this x (updates the voxel received). Uniform weights are exact.
FUSION_UNITS_PER_UPDATE = 1

# Ambiguous voxels (see FUSION_DECISION_MARGIN) must stay below this fraction of the voxels
# some beam reaches, or the comparison would prove little.
FUSION_AMBIGUOUS_MAX = 0.02

# The default model's series in float32 (kernels/interpret_nodes.cl): exp_nb's reduction r = x - n ln 2
# carries ~ulp(n ln 2) / 2, its Taylor series < 6e-9, the product one more rounding: its note
# bounds the whole range [-87, 88] by 4e-6 relative.
EXP_NB_RTOL = 4e-6
# log10_nb: the float32 rounding of exponent x log10(2) plus the mantissa's series, ~4e-6 decades
# at 1e38 (its note), 1e-7 near 1.
LOG10_NB_DECADES = 4e-6
# L = t (1 - q) / (1 - q t), t = exp_nb(e): t's relative error grows by up to 1 / (1 - q t) in
# the denominator; where q t <= 1 - 1e-3 that is <= 1e3 x EXP_NB_RTOL.
LIKELIHOOD_RATIO_RTOL = 4e-3
# The reading of exact integer sums in float64 (a division and an addition): a few ulps.
READ_NATS_TOL = 1e-9
