"""The two cases of the paper's Fig. 10 (§4.2), simulated through the paper's radar (1024-point
FFT, 512 bins of 0.125 m) and run through the CFAR and interpreter kernels with the default
configuration (CA-CFAR 16 + 16 cells, P_fa 1e-3; k_occ 1, E_h -1, E_l -0.1).
"""

import numpy as np
import pytest

from radarcl import logodds
from radarcl.config.stage_config import PAPER_RADAR, InterpretConfig
from radarcl.pipeline import Detection
from radarcl.scene import echoes

SPACING = PAPER_RADAR.bin_spacing_m(1024)
E_HIGH, E_LOW = (int(v) for v in logodds.to_fixed([-1.0, -0.1]))


def detect(runtime, profile):
    result = Detection(runtime, (1,), profile.size, SPACING)(profile[None].astype(np.float32))
    return result.cfar.mask[0], result.interpret.evidence[0], \
        result.interpret.pulses[0, :result.interpret.n_pulses[0]]


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_fig10a_wide_ground_return(runtime, seed):
    """-9 deg beam: strong empty before the ground, strong occupied on it, weaker after."""
    profile, (near, far) = echoes.fig10_ground_beam(seed)
    mask, evidence, pulses = detect(runtime, profile)
    first, last = InterpretConfig().bin_interval(SPACING, profile.size)
    ground = [p for p in pulses if p[0] * SPACING <= far and p[1] * SPACING >= near]
    assert len(ground) == 1, pulses
    start, end, peak, wide = ground[0]
    assert wide == 1 and near - 1.0 <= start * SPACING and end * SPACING <= far + 1.0
    before, after = np.arange(first, start), np.arange(end + 1, last + 1)
    assert np.all(evidence[before][~mask[before]] == E_HIGH)      # strong empty
    assert np.all(evidence[after][~mask[after]] == E_LOW)         # weaker, behind the surface
    peak_nats = logodds.to_nats(evidence[start:end + 1]).max()
    print(f"seed {seed}: ground pulse {start * SPACING:.2f}-{end * SPACING:.2f} m "
          f"(ground {near:.2f}-{far:.2f} m), peak evidence {peak_nats:+.2f} nat")
    assert 1.0 <= peak_nats <= 3.5                               # the paper: "close to +2"
    assert np.all(evidence[start:end + 1] > 0)


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_fig10b_fence_and_tree(runtime, seed):
    """Beam almost parallel to the ground: two narrow pulses, strong empty everywhere else."""
    fence, tree = 14.0, 23.0
    profile = echoes.fig10_fence_and_tree(seed, fence_m=fence, tree_m=tree)
    mask, evidence, pulses = detect(runtime, profile)
    first, last = InterpretConfig().bin_interval(SPACING, profile.size)
    assert not np.any(pulses[:, 3]), "no pulse may be wide"
    for target in (fence, tree):
        hits = [p for p in pulses if p[0] * SPACING <= target <= p[1] * SPACING]
        assert len(hits) == 1 and abs(hits[0][2] * SPACING - target) <= 0.5 * PAPER_RADAR.range_resolution_m
    inside = np.arange(first, last + 1)
    assert np.all(evidence[inside][~mask[inside]] == E_HIGH)
    assert np.all(evidence[inside][mask[inside]] > 0)
    print(f"seed {seed}: pulses {[(float(p[0] * SPACING), float(p[1] * SPACING)) for p in pulses]} m")
