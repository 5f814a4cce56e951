"""The render modes, registered in this one place, and the transfer-function settings they share.

Every mode maps a log-odds value v [nat] through the transfer function
clamp -> normalise -> gamma -> colormap:  x = clamp((v - lo) / (hi - lo), 0, 1) ** gamma.

- ``occupancy``: translucent occupancy, front-to-back compositing of x as opacity (per voxel
  length, ``density``) and colormap(x) as colour; early exit at alpha > 0.99.
- ``mip``: maximum-evidence projection, colormap of the largest v along the ray.
- ``iso``: the isosurface v = ``threshold`` (the occupancy threshold), refined by bisection and
  lit by its gradient; coloured by height, or by log-odds where the map is too flat for height
  to tell anything (a planar map: a spinning radar's one layer).
- ``free``: where can I drive: occupancy as above, and free space (v below ``free_threshold``)
  as a blue haze, its own clamp on -v (from the free threshold to the map's 90th percentile of
  the free values). Never skips (the coarse maxima say nothing of free space).
- ``spheres``: the paper's Fig. 11, one instanced sphere per cell with positive log-odds,
  radius proportional to v (half a voxel at ``hi``), coloured by x.

A ray-marched mode names its ``#define`` and the coarse-cell test that lets a ray skip a brick:
the largest value any sample in the brick can read, ``cmax``, must be able to change the pixel.
"""

from dataclasses import dataclass

from radarcl.errors import ConfigError


@dataclass(frozen=True)
class Mode:
    """One render mode: ``name``, its ``key`` in the app, ``program`` (shader file stem),
    ``define`` (the GLSL macro selecting it), ``description``, ``skips`` (empty-space skipping
    applies)."""

    name: str
    key: str
    program: str
    define: str
    description: str
    skips: bool = True


MODES = {m.name: m for m in (
    Mode("occupancy", "1", "volume", "MODE_OCCUPANCY", "translucent occupancy (positive evidence as opacity)"),
    Mode("mip", "2", "volume", "MODE_MIP", "maximum-evidence projection"),
    Mode("iso", "3", "volume", "MODE_ISO", "isosurface at the occupancy threshold, coloured by height (by log-odds "
                                           "for a map too flat for height)"),
    Mode("spheres", "4", "spheres", "MODE_SPHERES", "Fig. 11: a sphere per positive cell, radius ~ log-odds"),
    Mode("free", "5", "volume", "MODE_FREE", "free space (blue haze) and occupancy: where can I drive", False),
)}

COLORMAPS = ("inferno", "viridis", "magma", "turbo", "gray")
HI_PERCENTILE = 90              # the clamp's top: most of what the map holds gets distinct colours


@dataclass(frozen=True)
class Settings:
    """Transfer function and march: ``threshold`` [nat] (isosurface; also ``lo`` unless given),
    ``lo``/``hi`` the clamp [nat] (None: ``threshold`` and the map's ``HI_PERCENTILE``-th
    percentile of the values above it: the colours span what the map holds),
    ``free_threshold`` [nat] (the free mode's haze starts below it), ``gamma``, ``colormap``,
    ``density`` (opacity per voxel of length at
    x = 1), ``step`` [voxels] between samples, ``skip`` empty-space skipping on/off,
    ``clip`` ((x0, x1), (y0, y1), (z0, z1)) fractions of the grid kept (axis-aligned slices),
    ``background`` RGB in [0, 1]."""

    threshold: float = 1.0
    free_threshold: float = -1.0
    lo: float = None
    hi: float = None
    gamma: float = 1.0
    colormap: str = "inferno"
    density: float = 0.5
    step: float = 1.0
    skip: bool = True
    clip: tuple = ((0.0, 1.0), (0.0, 1.0), (0.0, 1.0))
    background: tuple = (0.06, 0.06, 0.08)

    def __post_init__(self):
        import math

        for name in ("threshold", "free_threshold", "lo", "hi", "gamma", "density", "step"):
            v = getattr(self, name)
            if v is None and name in ("lo", "hi"):
                continue
            if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
                raise ConfigError(f"{name} must be a finite number, got {v!r}")
        if abs(self.threshold) > 1e6 or any(v is not None and abs(v) > 1e6 for v in (self.lo, self.hi)):
            raise ConfigError(f"threshold, lo and hi are log-odds [nat]; got {self.threshold}, {self.lo}, {self.hi}")
        if not self.free_threshold < 0:
            raise ConfigError(f"the free threshold is a negative log-odds [nat], got {self.free_threshold}")
        if self.colormap not in COLORMAPS:
            raise ConfigError(f"unknown colormap {self.colormap!r}; expected one of {COLORMAPS}")
        if not 0.05 <= self.step <= 8:
            raise ConfigError(f"step must lie in [0.05, 8] voxels, got {self.step}")
        if not 0.05 <= self.gamma <= 20:
            raise ConfigError(f"gamma must lie in [0.05, 20], got {self.gamma}")
        if self.density <= 0:
            raise ConfigError(f"density must be positive, got {self.density}")
        if self.lo is not None and self.hi is not None and not self.hi > self.lo:
            raise ConfigError(f"the clamp needs hi > lo, got lo={self.lo} hi={self.hi}")
        for a, b in self.clip:
            if not 0.0 <= a < b <= 1.0:
                raise ConfigError(f"clip ranges must satisfy 0 <= a < b <= 1, got {self.clip}")

    def clamp_range(self, volume):
        """(lo, hi) [nat] for ``volume``: the given ones or the defaults described above."""
        lo = self.threshold if self.lo is None else self.lo
        hi = self.hi
        if hi is None:
            hi = volume.percentile_above(lo, HI_PERCENTILE)
            hi = lo + 1.0 if hi is None else hi
        return lo, max(hi, lo + 1e-3)

    def free_clamp(self, volume):
        """(lo, hi) [nat] of the free haze, on -v: from -``free_threshold`` to the map's
        ``HI_PERCENTILE``-th percentile of -v over its free voxels."""
        lo = -self.free_threshold
        hi = volume.percentile_below(self.free_threshold, HI_PERCENTILE)
        return lo, max(lo + 1.0 if hi is None else -hi, lo + 1e-3)


def mode(name):
    """The registered mode ``name``; an unknown one is a ``ConfigError`` listing the others."""
    if name not in MODES:
        raise ConfigError(f"unknown render mode {name!r}; expected one of {', '.join(MODES)}")
    return MODES[name]
