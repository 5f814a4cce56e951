"""The few exceptions radarcl raises.

Every error says what was wrong and what was expected. They derive from the builtin they
refine (ValueError, RuntimeError) so callers that catch those keep working.
"""


class RadarclError(Exception):
    """Base of every radarcl error."""


class ConfigError(RadarclError, ValueError):
    """A configuration that is impossible or outside what radarcl supports."""


class ShapeError(RadarclError, ValueError):
    """An array of the wrong shape or dtype for the plan it was given to."""


class FrameFormatError(RadarclError, ValueError):
    """A recording, file or byte stream that does not follow its format."""


class NoOpenCLError(RadarclError, RuntimeError):
    """No OpenCL platform or device could be found."""


class KernelBuildError(RadarclError, RuntimeError):
    """An OpenCL program failed to build; the message carries file, options and log."""


class DeviceCapabilityError(RadarclError, RuntimeError):
    """The chosen OpenCL device lacks something a kernel needs."""


class Terminated(BaseException):
    """SIGTERM, raised in the main thread by the CLI's handler: it unwinds like Ctrl-C (temporary
    files are removed, a live map is saved) and the CLI exits 143 with one line."""
