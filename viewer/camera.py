"""An orbit camera in the grid's world frame (metres, z up): it looks at ``target`` from
``distance`` metres, turned ``azimuth_deg`` about z from +x and raised ``elevation_deg`` above
the xy plane. Matrices are numpy float64, column vectors (GL's convention); ``project`` maps
world points to pixels with the same matrices the shaders use, so tests can say where a voxel
must appear."""

import math
from dataclasses import dataclass, replace

import numpy as np

from radarcl.errors import ConfigError

PRESETS = {"iso": (-135.0, 35.0), "top": (-90.0, 89.0), "front": (180.0, 5.0), "side": (-90.0, 5.0)}


@dataclass(frozen=True)
class Camera:
    """Orbit camera: ``target`` (x, y, z) [m], ``distance`` [m], ``azimuth_deg``,
    ``elevation_deg`` (clamped to +-89 so the up vector stays defined), ``fov_deg`` vertical."""

    target: tuple
    distance: float
    azimuth_deg: float = -135.0
    elevation_deg: float = 35.0
    fov_deg: float = 40.0

    def __post_init__(self):
        target = tuple(float(v) for v in np.asarray(self.target, dtype=float).reshape(-1))
        if len(target) != 3 or not all(map(math.isfinite, target)):
            raise ConfigError(f"camera target must be 3 finite numbers, got {self.target!r}")
        if not (math.isfinite(self.distance) and self.distance > 0):
            raise ConfigError(f"camera distance must be a positive number of metres, got {self.distance!r}")
        if not 1.0 <= self.fov_deg <= 170.0:
            raise ConfigError(f"field of view must lie in [1, 170] deg, got {self.fov_deg!r}")
        if not (math.isfinite(self.azimuth_deg) and math.isfinite(self.elevation_deg)):
            raise ConfigError(f"camera azimuth and elevation must be finite degrees, got "
                              f"{self.azimuth_deg!r}, {self.elevation_deg!r}")
        object.__setattr__(self, "target", target)
        object.__setattr__(self, "elevation_deg", float(np.clip(self.elevation_deg, -89.0, 89.0)))

    @classmethod
    def fit(cls, spec, preset="iso", region=None, aspect=1.0, points=None, direction=None):
        """A camera from a preset direction (``PRESETS``) that frames the world box ``region``
        (lo, hi) (default: the whole grid ``spec``) grown to hold ``points`` (n, 3) (the sensor's
        poses), as tightly as a viewport of width / height ``aspect`` allows: every corner of the
        box inside the view with 4 % to spare. ``direction`` (azimuth, elevation) [deg] replaces
        the preset's."""
        if direction is None and preset not in PRESETS:
            raise ConfigError(f"unknown camera preset {preset!r}; expected one of {sorted(PRESETS)}")
        lo, hi = box(spec) if region is None else (np.asarray(region[0], float), np.asarray(region[1], float))
        if points is not None and len(points):
            pts = np.asarray(points, float).reshape(-1, 3)
            lo, hi = np.minimum(lo, pts.min(axis=0)), np.maximum(hi, pts.max(axis=0))
        fov = 40.0
        az, el = PRESETS[preset] if direction is None else (float(direction[0]), float(direction[1]))
        target = (lo + hi) / 2
        probe = cls(tuple(target), 1.0, az, el, fov)
        v = probe.view()[:3, :3]                        # rows: right, up, backward
        corners = np.array([[x, y, z] for x in (lo[0], hi[0]) for y in (lo[1], hi[1]) for z in (lo[2], hi[2])])
        rel = corners - target
        right, up, ahead = rel @ v[0], rel @ v[1], -(rel @ v[2])        # ahead: towards the target
        tan_v = math.tan(math.radians(fov / 2))
        tan_h = tan_v * max(float(aspect), 1e-3)
        need = np.maximum(np.abs(right) / tan_h, np.abs(up) / tan_v) - ahead
        distance = max(float(need.max()) * 1.04, 1e-3 + float(np.linalg.norm(hi - lo)) * 1e-3)
        return cls(tuple(target), distance, az, el, fov)

    @classmethod
    def parse(cls, text, spec, region=None, aspect=1.0, points=None):
        """From the command line: a preset name (iso, top, front, side) or
        ``AZ,EL[,DIST[,X,Y,Z]]`` (degrees, metres; the target defaults to the centre of
        ``region`` or of the grid, the distance to one that fits it)."""
        if text in PRESETS:
            return cls.fit(spec, text, region, aspect, points)
        try:
            parts = [float(v) for v in text.split(",")]
        except ValueError:
            parts = []
        if len(parts) not in (2, 3, 6):
            raise ConfigError(f"--camera {text!r}: expected a preset ({', '.join(PRESETS)}) or "
                              f"AZ,EL[,DIST[,X,Y,Z]] in degrees and metres")
        cam = cls.fit(spec, region=region, aspect=aspect, points=points, direction=parts[:2])
        if len(parts) >= 3:
            cam = replace(cam, distance=parts[2])
        if len(parts) == 6:
            cam = replace(cam, target=tuple(parts[3:]))
        return cam

    @property
    def eye(self):
        """Camera position [m]."""
        az, el = math.radians(self.azimuth_deg), math.radians(self.elevation_deg)
        offset = np.array([math.cos(el) * math.cos(az), math.cos(el) * math.sin(az), math.sin(el)])
        return np.asarray(self.target) + self.distance * offset

    def view(self):
        """World -> eye matrix (4 x 4), looking at the target with z up."""
        eye = self.eye
        f = np.asarray(self.target) - eye
        f /= np.linalg.norm(f)
        s = np.cross(f, (0.0, 0.0, 1.0))
        s /= np.linalg.norm(s)
        u = np.cross(s, f)
        m = np.eye(4)
        m[0, :3], m[1, :3], m[2, :3] = s, u, -f
        m[:3, 3] = -m[:3, :3] @ eye
        return m

    def projection(self, aspect, near=None, far=None):
        """Perspective matrix; near and far planes follow the distance unless given."""
        near = near or self.distance * 1e-3
        far = far or self.distance * 10.0
        t = 1.0 / math.tan(math.radians(self.fov_deg) / 2)
        m = np.zeros((4, 4))
        m[0, 0], m[1, 1] = t / aspect, t
        m[2, 2], m[2, 3] = (far + near) / (near - far), 2 * far * near / (near - far)
        m[3, 2] = -1.0
        return m

    def mvp(self, width, height):
        """Projection @ view for a viewport of ``width`` x ``height`` pixels."""
        return self.projection(width / height) @ self.view()

    def project(self, points, width, height):
        """World points (n, 3) -> pixel coordinates (n, 2), (column, row) with row 0 at the top,
        as in the image ``Renderer.image`` returns."""
        p = np.c_[np.asarray(points, dtype=float).reshape(-1, 3), np.ones(len(np.reshape(points, (-1, 3))))]
        clip = p @ self.mvp(width, height).T
        ndc = clip[:, :2] / clip[:, 3:4]
        return np.c_[(ndc[:, 0] + 1) * width / 2, (1 - ndc[:, 1]) * height / 2]

    # interaction: each returns a new camera
    def orbit(self, d_azimuth_deg, d_elevation_deg):
        """Turned about the target."""
        return replace(self, azimuth_deg=self.azimuth_deg + d_azimuth_deg,
                       elevation_deg=self.elevation_deg + d_elevation_deg)

    def zoom(self, factor):
        """Distance multiplied by ``factor``."""
        return replace(self, distance=max(self.distance * factor, 1e-3))

    def pan(self, dx, dy):
        """Target moved by (dx, dy) fractions of the view's height across and up the screen."""
        v = self.view()
        extent = 2 * self.distance * math.tan(math.radians(self.fov_deg) / 2)
        move = (-dx * v[0, :3] + dy * v[1, :3]) * extent
        return replace(self, target=tuple(np.asarray(self.target) + move))


def box(spec):
    """World corners (lo, hi) of a grid: [origin, origin + shape * voxel]."""
    lo = np.asarray(spec.origin_m, dtype=float)
    return lo, lo + np.asarray(spec.shape, dtype=float) * spec.voxel_m

