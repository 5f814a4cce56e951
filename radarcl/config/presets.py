"""Named configurations the programs start from."""

from radarcl.config import mapconfig


def paper_config(voxel_m=0.1, values=None):
    """The paper radar's configuration at ``voxel_m`` with ``values`` {"section.key": value}
    set by the program (the reference scene lies in the paper's grid)."""
    return mapconfig.resolve("paper", program={"grid.voxel_m": voxel_m, **(values or {})})
