"""Named tolerances, each with its reason. Integer results are compared exactly, never here."""

# Range FFT in float32 against the float64 oracle: max |kernel - oracle| / max |oracle| per frame.
# Rounding in an N-point FFT grows like eps32 * log2(N) (eps32 = 6e-8); measured <= 2e-7 for
# N = 1024 with float64-exact twiddles. 2e-6 leaves room up to N = 4096 and for other devices.
RANGE_FFT_RTOL = 2e-6

# A tone 120 dB below a full-scale one, both on bin centres with a rectangular window (no
# leakage): the float32 transform's rounding floor is ~ -140 dB of the peak, so the weak tone's
# bin is recovered to within this relative error.
WEAK_TONE_RTOL = 0.05
