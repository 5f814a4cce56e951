"""Named configurations the programs start from."""

from radarcl.config import mapconfig


# The paper's own interpreter, eq. 12 (radarcl's default is the detection-statistics model): what
# every "paper constants" map, the tuned constants and the eq. 12 calibration are made with.
EQ12 = {"interpret.model": "paper"}

# The reference scene's seeds: the search of `radarcl tune` (``evaluation.tuning``) sees only the
# tuning seed's noise and speckle, at its voxel; every reported score is of the evaluation seed.
TUNING_SEED = 2
EVALUATION_SEED = 0
TUNING_VOXEL_M = 0.2


def paper_config(voxel_m=0.1, values=None):
    """The paper radar's configuration at ``voxel_m`` with ``values`` {"section.key": value}
    set by the program (the reference scene lies in the paper's grid)."""
    return mapconfig.resolve("paper", program={"grid.voxel_m": voxel_m, **(values or {})})
