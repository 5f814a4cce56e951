"""Beam geometry and sensor poses (paper §2.1, §3.4, Fig. 7).

Frames. The radar head frame has x along the boresight, y to the left, z up (right-handed).
A beam at azimuth ``az`` (positive towards +y) and elevation ``el`` (positive up) points along
``(cos el cos az, cos el sin az, sin el)``. The head sits on its stand tilted by ``tilt`` about
its y axis (positive nose up; the paper's depressions are negative). A pose is the 4x4 rigid
transform from the stand (sensor) frame to the world. A beam's world frame is therefore
``pose @ R_tilt @ R_beam``, whose columns are the beam axis u (range direction), the lateral
axis v (azimuth direction) and the elevation axis w.

The beam volume (Fig. 7c, "cylindrical-conical"): a point at beam coordinates (d, y, z)
(d along u) is inside when d > 0 and (y / W_az(d))^2 + (z / W_el(d))^2 <= 1, where
W(d) = max(a, d tan(theta / 2)) with a the antenna's half aperture (eq. 1) in that axis: the
antenna's cross-section near the radar, the half-power cone beyond. The cone takes over at
``cone_start_range`` = a / tan(theta / 2), 13.0 m for the paper's 1 deg azimuth beam, beside
eq. 2's far-field distance of 13.3 m.

Across the beam the evidence is scaled by the normalised two-way pattern, a Gaussian fitted to
Fig. 7b and read as p(alpha | M) (§3.4): ``two_way_weight(rho2) = 4 ** -rho2`` with rho2 the
normalised squared offset above, 1 on the axis and 1/4 at the one-way half-power edge. The
paper disregards evidence outside the half-power volume, and so do we.
"""

import math
import numbers
from dataclasses import dataclass

import numpy as np

from radarcl import physics
from radarcl.errors import ConfigError

# A pose's rotation must be orthonormal to this tolerance (float64 products of a rotation
# built from angles are orthonormal to ~1e-15; a pose read from text with 6 digits, ~1e-6).
ROTATION_TOLERANCE = 1e-5
# Poses beyond this [m] are refused: the kernels hold beam origins relative to the grid in
# float32, which overflows (and long before that, loses the voxel) far out.
MAX_TRANSLATION_M = 1e7


# -- the cylindrical-conical beam (Fig. 7c) and its angular weight (Fig. 7b) ---------------------
def half_aperture(wavelength_m, beamwidth_rad):
    """Antenna half aperture a [m] for a half-power beamwidth, from eq. 1 (D = 1.02 lambda / theta)."""
    return 0.5 * physics.aperture_for_beamwidth(wavelength_m, beamwidth_rad)


def cone_start_range(half_aperture_m, beamwidth_rad):
    """Range [m] where the half-power cone becomes wider than the antenna: a / tan(theta / 2)."""
    return np.asarray(half_aperture_m, dtype=float) / np.tan(0.5 * np.asarray(beamwidth_rad, dtype=float))


def beam_half_width(d_m, half_aperture_m, beamwidth_rad):
    """Half width [m] of the beam at axial distance d: max(a, d tan(theta / 2)) (Fig. 7c).
    With a = 0 this is the plain half-power cone."""
    return np.maximum(half_aperture_m, np.asarray(d_m, dtype=float) * math.tan(0.5 * beamwidth_rad))


def two_way_weight(rho2):
    """Normalised two-way beam pattern at normalised squared offset rho2: 4 ** -rho2.

    A one-way Gaussian pattern at half power on the beam edge (rho2 = 1) is 2 ** -rho2; two
    ways square it. 1 on the axis, 1/4 on the edge (§3.4, Fig. 7b)."""
    return np.exp2(-2.0 * np.asarray(rho2, dtype=float))


@dataclass(frozen=True)
class BeamModel:
    """The beam volume of one radar: half-power beamwidths, half apertures, and switches.

    near_field: use the cylinder of the antenna's cross-section near the radar (Fig. 7c);
        off, the beam is a pure cone from the antenna.
    gaussian: scale evidence by ``two_way_weight`` across the beam; off, uniform inside.
    """

    beamwidth_az_rad: float
    beamwidth_el_rad: float
    half_aperture_az_m: float
    half_aperture_el_m: float
    near_field: bool = True
    gaussian: bool = True

    def __post_init__(self):
        for name in ("beamwidth_az_rad", "beamwidth_el_rad", "half_aperture_az_m", "half_aperture_el_m"):
            value = getattr(self, name)
            if isinstance(value, (bool, str, bytes)) or not isinstance(value, numbers.Real):
                raise ConfigError(f"{name} must be a number, got {value!r} ({type(value).__name__})")
        for name in ("near_field", "gaussian"):
            if not isinstance(getattr(self, name), (bool, np.bool_)):
                raise ConfigError(f"{name} must be True or False, got {getattr(self, name)!r}")
        for name in ("beamwidth_az_rad", "beamwidth_el_rad"):
            value = getattr(self, name)
            if not (math.isfinite(value) and 0 < value < math.pi):
                raise ConfigError(f"{name} must lie in (0, pi), got {value!r}")
        for name in ("half_aperture_az_m", "half_aperture_el_m"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value >= 0):
                raise ConfigError(f"{name} must be finite and >= 0, got {value!r}")

    @classmethod
    def from_radar(cls, radar, near_field=True, gaussian=True):
        """The model of a ``RadarConfig``: its beamwidths, apertures from eq. 1."""
        az, el = math.radians(radar.beamwidth_az_deg), math.radians(radar.beamwidth_el_deg)
        lam = radar.wavelength_m
        return cls(az, el, float(half_aperture(lam, az)), float(half_aperture(lam, el)),
                   bool(near_field), bool(gaussian))

    @property
    def apertures(self):
        """(a_az, a_el) in use: zero when the near-field cylinder is off."""
        if not self.near_field:
            return 0.0, 0.0
        return self.half_aperture_az_m, self.half_aperture_el_m

    def rho2(self, d, y, z):
        """Normalised squared offset of beam coordinates (d, y, z); inf where d <= 0."""
        a_az, a_el = self.apertures
        d = np.asarray(d, dtype=float)
        w_az = beam_half_width(d, a_az, self.beamwidth_az_rad)
        w_el = beam_half_width(d, a_el, self.beamwidth_el_rad)
        with np.errstate(divide="ignore", invalid="ignore"):
            r2 = (np.asarray(y) / w_az) ** 2 + (np.asarray(z) / w_el) ** 2
        return np.where(d > 0, r2, np.inf)

    def weight(self, rho2):
        """Evidence factor at rho2 inside the beam: ``two_way_weight`` or 1."""
        return two_way_weight(rho2) if self.gaussian else np.ones_like(np.asarray(rho2, dtype=float))


# The beam volumes compared (``bench quality``): the axis alone (what a point cloud sees), a
# uniform cone, a cone weighted by the two-way Gaussian, and the paper's cylindrical-conical
# volume with the Gaussian (Fig. 7c).
BEAM_MODELS = ("axis", "uniform-cone", "gaussian-cone", "cylindrical-conical")
AXIS_BEAMWIDTH_RAD = 1e-6        # "axis": a cylinder of half a voxel around the beam axis


def beam_model(name, beamwidth_az_rad, beamwidth_el_rad, wavelength_m, voxel_m):
    """The ``BeamModel`` called ``name`` (one of BEAM_MODELS) for a radar with these
    half-power beamwidths and wavelength (apertures from eq. 1), mapping at ``voxel_m``."""
    a_az, a_el = (float(half_aperture(wavelength_m, b)) for b in (beamwidth_az_rad, beamwidth_el_rad))
    if name == "axis":
        return BeamModel(AXIS_BEAMWIDTH_RAD, AXIS_BEAMWIDTH_RAD, 0.5 * voxel_m, 0.5 * voxel_m, True, False)
    if name == "uniform-cone":
        return BeamModel(beamwidth_az_rad, beamwidth_el_rad, a_az, a_el, near_field=False, gaussian=False)
    if name == "gaussian-cone":
        return BeamModel(beamwidth_az_rad, beamwidth_el_rad, a_az, a_el, near_field=False, gaussian=True)
    if name == "cylindrical-conical":
        return BeamModel(beamwidth_az_rad, beamwidth_el_rad, a_az, a_el, near_field=True, gaussian=True)
    raise ConfigError(f"beam model must be one of {', '.join(BEAM_MODELS)}, got {name!r}")


# -- the frame's beam lattice ------------------------------------------------------------------------
@dataclass(frozen=True)
class BeamLattice:
    """Beam directions of one frame: n_az x n_el, azimuth major (beam index i * n_el + k).

    az_i = az0 + i az_step, el_k = el0 + k el_step [rad], in the head frame; ``tilt_rad`` is
    the head's tilt on its stand. A lattice whose azimuths span a full turn (a spinning radar)
    wraps around.
    """

    n_az: int
    n_el: int
    az0_rad: float
    az_step_rad: float
    el0_rad: float = 0.0
    el_step_rad: float = 0.0
    tilt_rad: float = 0.0

    def __post_init__(self):
        for name in ("n_az", "n_el"):
            v = getattr(self, name)
            if not (isinstance(v, (int, np.integer)) and v >= 1):
                raise ConfigError(f"{name} must be a positive integer, got {v!r}")
        for name in ("az0_rad", "az_step_rad", "el0_rad", "el_step_rad", "tilt_rad"):
            if not math.isfinite(getattr(self, name)):
                raise ConfigError(f"{name} must be finite, got {getattr(self, name)!r}")
        if self.n_az > 1 and not self.az_step_rad > 0:
            raise ConfigError(f"az_step_rad must be positive, got {self.az_step_rad!r}")
        if self.n_el > 1 and not self.el_step_rad > 0:
            raise ConfigError(f"el_step_rad must be positive, got {self.el_step_rad!r}")
        if self.n_az * self.az_step_rad > 2 * math.pi * (1 + 1e-9):
            raise ConfigError(f"{self.n_az} azimuths {self.az_step_rad!r} rad apart span more than a turn")
        els = self.elevations
        if np.abs(els).max() >= math.pi / 2:
            raise ConfigError(f"beam elevations must stay within +-90 deg, got {np.degrees(els)}")

    @classmethod
    def from_radar(cls, radar, tilt_deg=0.0):
        """The paper's stacked-beam lattice of a ``RadarConfig``, centred on the boresight."""
        az_step, el_step = math.radians(radar.azimuth_step_deg), math.radians(radar.elevation_step_deg)
        return cls(radar.n_azimuth, radar.n_elevation, -0.5 * (radar.n_azimuth - 1) * az_step, az_step,
                   -0.5 * (radar.n_elevation - 1) * el_step, el_step, math.radians(tilt_deg))

    @classmethod
    def spinning(cls, n_az, az0_rad=0.0):
        """A spinning radar's full turn of n_az azimuths, one elevation (Navtech)."""
        return cls(int(n_az), 1, float(az0_rad), 2 * math.pi / n_az)

    @property
    def n_beams(self):
        """Beams per frame."""
        return self.n_az * self.n_el

    @property
    def batch(self):
        """The frame's beam shape: (n_az, n_el), or (n_az,) for a single elevation."""
        return (self.n_az,) if self.n_el == 1 else (self.n_az, self.n_el)

    @property
    def wraps(self):
        """True when the azimuths cover a full turn."""
        return abs(self.n_az * self.az_step_rad - 2 * math.pi) < 1e-6

    @property
    def azimuths(self):
        """(n_az,) beam azimuths [rad]."""
        return self.az0_rad + self.az_step_rad * np.arange(self.n_az)

    @property
    def elevations(self):
        """(n_el,) beam elevations [rad] in the head frame."""
        return self.el0_rad + self.el_step_rad * np.arange(self.n_el)

    def head_rotation(self):
        """3x3 rotation head -> stand: the tilt about y, positive nose up."""
        c, s = math.cos(self.tilt_rad), math.sin(self.tilt_rad)
        return np.array([[c, 0.0, -s], [0.0, 1.0, 0.0], [s, 0.0, c]])

    def beam_rotations(self):
        """(n_beams, 3, 3) rotations beam -> stand; columns u (axis), v (azimuth), w (elevation)."""
        az = np.repeat(self.azimuths, self.n_el)
        el = np.tile(self.elevations, self.n_az)
        ca, sa, ce, se = np.cos(az), np.sin(az), np.cos(el), np.sin(el)
        u = np.stack([ce * ca, ce * sa, se], axis=-1)
        v = np.stack([-sa, ca, np.zeros_like(sa)], axis=-1)
        w = np.stack([-se * ca, -se * sa, ce], axis=-1)
        return self.head_rotation() @ np.stack([u, v, w], axis=-1)


# -- poses -------------------------------------------------------------------------------------------------
def real_array(values, what):
    """``values`` as a float64 array, or ConfigError when they are not real numbers (a complex
    pose would lose its imaginary part silently; text or objects are not numbers)."""
    try:
        a = np.asarray(values)
    except (ValueError, TypeError) as exc:
        raise ConfigError(f"{what} must be an array of real numbers ({exc})") from None
    if a.dtype.kind not in "iuf":
        raise ConfigError(f"{what} must be real numbers, got {a.dtype} {a.shape}")
    return a.astype(np.float64)


def check_pose(pose, what="pose"):
    """A 4x4 rigid transform as float64, or ConfigError saying what is wrong with it."""
    T = real_array(pose, what)
    if T.shape != (4, 4):
        raise ConfigError(f"{what} must be a 4x4 rigid transform, got shape {T.shape}")
    if not np.isfinite(T).all():
        raise ConfigError(f"{what} holds NaN or Inf: {T.tolist()}")
    if np.abs(T[:3, 3]).max() > MAX_TRANSLATION_M:
        raise ConfigError(f"{what}'s translation {T[:3, 3].tolist()} m lies beyond +-{MAX_TRANSLATION_M:g} m "
                          "(express poses in a local frame near the map)")
    if not np.array_equal(T[3], [0.0, 0.0, 0.0, 1.0]):
        raise ConfigError(f"{what}'s last row must be [0, 0, 0, 1], got {T[3].tolist()}")
    R = T[:3, :3]
    err = float(np.abs(R.T @ R - np.eye(3)).max())
    if err > ROTATION_TOLERANCE or np.linalg.det(R) < 0:
        raise ConfigError(f"{what}'s rotation is not a proper rotation (|R^T R - I| = {err:.2g}, "
                          f"det = {np.linalg.det(R):.6g}; expected orthonormal with det +1)")
    return T


def check_poses(poses, n_beams):
    """One pose (4, 4), or one per beam (n_beams, 4, 4); returns a (1 or n_beams, 4, 4) array."""
    P = real_array(poses, "poses")
    if P.shape == (4, 4):
        return check_pose(P)[None]
    if P.shape != (n_beams, 4, 4):
        raise ConfigError(f"poses must be (4, 4) or ({n_beams}, 4, 4), got {P.shape}")
    # One vectorised pass; the first bad pose, if any, is named by check_pose's own message.
    R = P[:, :3, :3]
    err = np.abs(np.swapaxes(R, 1, 2) @ R - np.eye(3)).max(axis=(1, 2))
    with np.errstate(invalid="ignore"):
        far = ~(np.abs(P[:, :3, 3]) <= MAX_TRANSLATION_M).all(axis=1)
    bad = (far | ~np.isfinite(P).all(axis=(1, 2)) | (P[:, 3] != [0.0, 0.0, 0.0, 1.0]).any(axis=1)
           | ~(err <= ROTATION_TOLERANCE) | ~(np.linalg.det(np.nan_to_num(R)) >= 0))
    if bad.any():
        b = int(np.flatnonzero(bad)[0])
        check_pose(P[b], f"pose of beam {b}")
    return P


def pose_from_xyz_rpy(x=0.0, y=0.0, z=0.0, roll=0.0, pitch=0.0, yaw=0.0):
    """4x4 pose from a translation [m] and roll, pitch, yaw [rad] (R = Rz(yaw) Ry(pitch) Rx(roll))."""
    values = real_array([x, y, z, roll, pitch, yaw], "a pose's x, y, z, roll, pitch, yaw")
    if not np.isfinite(values).all():
        raise ConfigError(f"a pose's x, y, z, roll, pitch, yaw must be finite, got {values.tolist()}")
    x, y, z, roll, pitch, yaw = (float(v) for v in values)
    cr, sr, cp, sp, cy, sy = (math.cos(roll), math.sin(roll), math.cos(pitch), math.sin(pitch),
                              math.cos(yaw), math.sin(yaw))
    T = np.eye(4)
    T[:3, :3] = [[cy * cp, cy * sp * sr - sy * cr, cy * sp * cr + sy * sr],
                 [sy * cp, sy * sp * sr + cy * cr, sy * sp * cr - cy * sr],
                 [-sp, cp * sr, cp * cr]]
    T[:3, 3] = (x, y, z)
    return T


def se2_pose(x, y, yaw, z=0.0):
    """4x4 pose of a planar motion: translation (x, y) [m], rotation yaw [rad] about z."""
    return pose_from_xyz_rpy(x, y, z, yaw=yaw)


def interpolate_se2(start, end, fractions):
    """Poses at ``fractions`` in [0, 1] of the planar motion from pose ``start`` to ``end``:
    the relative motion's (x, y, yaw) scaled linearly (first order; exact for straight motion)."""
    start, end = check_pose(start, "start pose"), check_pose(end, "end pose")
    rel = np.linalg.inv(start) @ end
    dx, dy, dyaw = rel[0, 3], rel[1, 3], math.atan2(rel[1, 0], rel[0, 0])
    return np.stack([start @ se2_pose(f * dx, f * dy, f * dyaw) for f in np.asarray(fractions, float)])


# -- SE(3) interpolation -------------------------------------------------------------------------------
def interpolate_pose(times_ns, poses, t_ns):
    """The pose at ``t_ns``: positions interpolated linearly, rotations by slerp of the two
    nearest poses' quaternions; held at the ends."""
    i = int(np.searchsorted(times_ns, t_ns))
    if i <= 0 or i >= len(times_ns):
        return poses[0 if i <= 0 else -1]
    a = (t_ns - times_ns[i - 1]) / max(1, times_ns[i] - times_ns[i - 1])
    out = np.eye(4)
    out[:3, 3] = (1 - a) * poses[i - 1][:3, 3] + a * poses[i][:3, 3]
    q0, q1 = _quaternion(poses[i - 1][:3, :3]), _quaternion(poses[i][:3, :3])
    if q0 @ q1 < 0:
        q1 = -q1
    theta = np.arccos(np.clip(q0 @ q1, -1, 1))
    q = q0 if theta < 1e-9 else (np.sin((1 - a) * theta) * q0 + np.sin(a * theta) * q1) / np.sin(theta)
    out[:3, :3] = _rotation(q / np.linalg.norm(q))
    return out


def _quaternion(r):
    w = np.sqrt(max(0.0, 1 + np.trace(r))) / 2
    if w > 1e-6:
        return np.array([w, (r[2, 1] - r[1, 2]) / (4 * w), (r[0, 2] - r[2, 0]) / (4 * w), (r[1, 0] - r[0, 1]) / (4 * w)])
    k = int(np.argmax(np.diag(r)))                 # a half turn: from the largest diagonal term
    i, j = (k + 1) % 3, (k + 2) % 3
    q = np.zeros(4)
    q[1 + k] = np.sqrt(max(0.0, 1 + r[k, k] - r[i, i] - r[j, j])) / 2
    q[1 + i] = (r[i, k] + r[k, i]) / (4 * q[1 + k])
    q[1 + j] = (r[j, k] + r[k, j]) / (4 * q[1 + k])
    q[0] = (r[j, i] - r[i, j]) / (4 * q[1 + k])
    return q


def _rotation(q):
    w, x, y, z = q
    return np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
                     [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
                     [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)]])
