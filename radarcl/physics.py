"""FMCW radar physics as named functions, one per equation of Foessel-Bunting (paper §2, §3.2).

All quantities are SI: metres, seconds, hertz, radians. The paper rounds the speed of light to
3e8 m/s; we use the exact value, which moves the paper's figures by 0.07 % (its 0.5 m range
resolution is 0.4997 m here).
"""

import numpy as np

from radarcl.errors import ConfigError

SPEED_OF_LIGHT = 299_792_458.0  # [m/s], exact (SI definition)


def wavelength(carrier_hz):
    """Wavelength [m] of a carrier [Hz]: lambda = c / f (77 GHz -> 3.89 mm, paper §2.3)."""
    return SPEED_OF_LIGHT / np.asarray(carrier_hz, dtype=float)


def beamwidth(wavelength_m, aperture_m):
    """Half-power beamwidth [rad] of an aperture D, eq. 1: theta = 1.02 lambda / D."""
    return 1.02 * np.asarray(wavelength_m, dtype=float) / np.asarray(aperture_m, dtype=float)


def aperture_for_beamwidth(wavelength_m, beamwidth_rad):
    """Aperture D [m] that gives a half-power beamwidth, eq. 1 solved for D.

    At 77 GHz a 1 deg beam needs 0.227 m (the paper quotes 224 mm, i.e. eq. 1 without 1.02).
    """
    return 1.02 * np.asarray(wavelength_m, dtype=float) / np.asarray(beamwidth_rad, dtype=float)


def far_field_distance(aperture_m, wavelength_m):
    """Start of the antenna far field [m], eq. 2: R_nf = D^2 / lambda.

    For the paper's 1 deg aperture (0.227 m at 77 GHz) this is 13.3 m; the paper quotes 13.6 m.
    """
    return np.asarray(aperture_m, dtype=float) ** 2 / np.asarray(wavelength_m, dtype=float)


def range_resolution(bandwidth_hz):
    """Down-range resolution [m] of a sweep of bandwidth B, eq. 7: dR = c / (2 B)."""
    return SPEED_OF_LIGHT / (2.0 * np.asarray(bandwidth_hz, dtype=float))


def beat_frequency(range_m, bandwidth_hz, sweep_time_s):
    """Beat frequency [Hz] of a target at range r, eq. 6a with t' = 2 r / c: f = 2 B r / (c T).

    Evaluated at the maximum range of interest this is eq. 10, the largest frequency the ADC
    must sample (``max_beat_frequency``).
    """
    return 2.0 * np.asarray(bandwidth_hz, dtype=float) * np.asarray(range_m, dtype=float) / (
        SPEED_OF_LIGHT * np.asarray(sweep_time_s, dtype=float))


def max_beat_frequency(range_max_m, bandwidth_hz, sweep_time_s):
    """Eq. 10: Delta f_max = 2 B r_max / (c T); Nyquist asks f_samp > 2 Delta f_max (real ADC)."""
    return beat_frequency(range_max_m, bandwidth_hz, sweep_time_s)


def range_of_beat_frequency(freq_hz, bandwidth_hz, sweep_time_s):
    """Inverse of eq. 6a: the range [m] whose echo beats at ``freq_hz``: r = f c T / (2 B)."""
    return np.asarray(freq_hz, dtype=float) * SPEED_OF_LIGHT * np.asarray(sweep_time_s, dtype=float) / (
        2.0 * np.asarray(bandwidth_hz, dtype=float))


def bin_spacing(bandwidth_hz, sweep_time_s, sample_rate_hz, n_fft):
    """Range [m] between FFT bins after zero padding to ``n_fft`` (paper §4.1, eq. 11).

    Bin k sits at beat frequency k fs / N, hence range k * fs c T / (2 B N). Without padding
    (N = fs T samples) this equals the resolution c / 2B; padding samples the same
    spectrum more densely but does not improve the resolution (§4.1).
    """
    return range_of_beat_frequency(np.asarray(sample_rate_hz, dtype=float) / n_fft,
                                   bandwidth_hz, sweep_time_s)


# Width of a point target's pulse at the CFAR threshold, in resolution cells c/2B: the -6 dB
# mainlobe width of the Hann window is 2.00 bins of the unpadded FFT (Harris, Proc. IEEE 66(1),
# 1978, table I), and a threshold some 10-20 dB above the noise cuts a strong pulse near there.
HANN_PULSE_WIDTH_CELLS = 2.0


def ground_echo_extent(sensor_height_m, elevation_rad, beamwidth_el_rad):
    """Down-range extent [m] of flat ground lit by a beam (paper §3.3, Fig. 5).

    A beam whose axis points ``elevation_rad`` (< 0: down) with half-power width
    ``beamwidth_el_rad`` from ``sensor_height_m`` above flat ground lights the ground from
    h / sin(-e + b/2) to h / sin(-e - b/2). Infinite when the upper beam edge does not reach the
    ground (-e <= b/2): the echo then runs to the end of the profile.
    """
    h = float(sensor_height_m)
    near_angle = -float(elevation_rad) + 0.5 * float(beamwidth_el_rad)
    far_angle = -float(elevation_rad) - 0.5 * float(beamwidth_el_rad)
    if h <= 0 or near_angle <= 0:
        raise ConfigError(f"the beam must point at the ground from above it: height {sensor_height_m} m, "
                         f"elevation {elevation_rad} rad, beamwidth {beamwidth_el_rad} rad")
    if far_angle <= 0:
        return float("inf")
    return h / np.sin(far_angle) - h / np.sin(near_angle)


def wide_pulse_width(sensor_height_m, lowest_elevation_rad, beamwidth_el_rad, range_resolution_m,
                     pulse_width_cells=HANN_PULSE_WIDTH_CELLS):
    """The paper's wide-pulse rule (§3.3) as a width [m] at the CFAR threshold.

    "A pulse is considered wide if the extension at the CFAR threshold is equal to or more than
    the extension of the distributed echo of flat terrain at the lowest elevation of the radar
    (-14 deg)": the ground extent at that elevation (``ground_echo_extent``), seen through the
    radar's own pulse, which adds ``pulse_width_cells`` resolution cells (a point target is that
    wide at the threshold, so only echoes longer than the steepest ground return count as wide).
    """
    return (ground_echo_extent(sensor_height_m, lowest_elevation_rad, beamwidth_el_rad)
            + float(pulse_width_cells) * float(range_resolution_m))
