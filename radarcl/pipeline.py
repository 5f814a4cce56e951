"""The only module that chains stages: device buffers flow from one kernel to the next, ordered
by events, with no host round trip in between.

``Detection`` runs range profiles (a Navtech scan, or a frame after the range FFT in power)
through CFAR and the eq. 12 interpreter.
"""

from dataclasses import dataclass

from radarcl.stages.cfar import Cfar, CfarResult
from radarcl.stages.interpret import InterpretResult, Interpreter


@dataclass(frozen=True)
class DetectionResult:
    """CFAR outputs and interpreter outputs of one frame."""

    cfar: CfarResult
    interpret: InterpretResult


class Detection:
    """Range profiles -> CFAR -> interpreter, buffers allocated once.

    runtime: a ``radarcl.cl.Runtime``; batch: beam shape; n_bins: bins per profile;
    bin_spacing_m: range between bins; cfar_config, interpret_config: ``CfarConfig`` and
    ``InterpretConfig`` (defaults: the paper's). Extra keywords go to ``Cfar``.
    """

    def __init__(self, runtime, batch, n_bins, bin_spacing_m, cfar_config=None, interpret_config=None,
                 **cfar_options):
        self.cfar = Cfar(runtime, batch, n_bins, cfar_config, **cfar_options)
        self.interpreter = Interpreter(runtime, batch, n_bins, bin_spacing_m, interpret_config)

    def enqueue(self, profiles_buf, flags_buf=None, wait_for=None):
        """Launch both stages on a device buffer of power profiles; returns the last event."""
        c = self.cfar
        done = c.enqueue(profiles_buf, wait_for=wait_for)
        return self.interpreter.enqueue(profiles_buf, c.noise_buf, c.mask_buf, flags_buf, wait_for=[done])

    def __call__(self, profiles, flags=None):
        """One frame of power profiles (*batch, n_bins) float32 (host) -> DetectionResult."""
        copy = self.cfar.upload(profiles)
        flags_buf = None
        if flags is not None:
            flags_buf = self.cfar.runtime.to_device(self.interpreter.check_flags(flags))
        done = self.enqueue(self.cfar.profiles_buf, flags_buf, wait_for=[copy])
        return DetectionResult(self.cfar.download(wait_for=[done]), self.interpreter.download(wait_for=[done]))
