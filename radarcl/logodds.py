"""The fixed-point log-odds unit shared by the interpreter (eq. 12) and the evidence grid (eq. 9).

Log-odds are natural: L = ln(p / (1 - p)). Inside radarcl they are int32 in units of
``1 / SCALE`` nat, because integer sums do not depend on the order of the additions: a map is
then bit-identical across runs, frame orders, devices and numbers of workers, and tests compare
with ``==`` (../shared/ARCHITECTURE.md, "Fixed-point log-odds").

- ``SCALE`` = 1024 units per nat: a resolution of 0.001 nat, 0.024 % of probability near 0.5,
  far below the noise of any radar evidence.
- One update (one beam's evidence for one bin) is clamped to +-``EVIDENCE_LIMIT_NATS`` = 16 nat
  (p = 1 - 1.1e-7) before rounding, so the log of any finite SNR fits: 256 beams x 16 nat x
  1024 = 4.2e6 units per frame and voxel, 500x below the int32 range.
- The knowledge channel counts looks the same way, in ``KNOWLEDGE_SCALE`` units per look.
- Rounding is to the nearest integer, ties to even: ``np.rint`` here, ``convert_int_rte`` in
  the kernels, so the two agree wherever float32 and float64 round the same way.
"""

import numpy as np

from radarcl.errors import ConfigError

SCALE = 1024                      # fixed-point units per nat
# The knowledge channel (radarcl.sensor_model): per voxel the summed detection opportunity of its
# looks, int32 in units of 1 / KNOWLEDGE_SCALE look; one look's opportunity is in [0, 1], so a
# node of it fits 16 bits, and a voxel saturates (at 2^30 units) after 262,144 full looks.
KNOWLEDGE_SCALE = 4096
EVIDENCE_LIMIT_NATS = 16.0        # |one update| <= this, in nats
EVIDENCE_LIMIT = int(EVIDENCE_LIMIT_NATS * SCALE)   # the same in units


def to_fixed(nats):
    """Log-odds [nat] -> int32 units: clamp to +-EVIDENCE_LIMIT_NATS, scale, round half to even.

    NaN is refused (it has no log-odds); +-inf clamp to the limit."""
    x = np.asarray(nats, dtype=np.float64)
    if np.isnan(x).any():
        raise ConfigError("log-odds must not be NaN")
    return np.rint(np.clip(x, -EVIDENCE_LIMIT_NATS, EVIDENCE_LIMIT_NATS) * SCALE).astype(np.int32)


def to_nats(units):
    """int units -> log-odds [nat], float64."""
    return np.asarray(units, dtype=np.float64) / SCALE


def probability(units):
    """int units -> occupancy probability 1 / (1 + exp(-L)), float64."""
    return 1.0 / (1.0 + np.exp(-to_nats(units)))


def from_probability(p):
    """Occupancy probability in (0, 1) -> int units (probabilities in, log-odds inside)."""
    p = np.asarray(p, dtype=np.float64)
    if not ((p > 0) & (p < 1)).all():
        raise ConfigError(f"probabilities must lie strictly between 0 and 1, got {p}")
    return to_fixed(np.log(p / (1.0 - p)))
