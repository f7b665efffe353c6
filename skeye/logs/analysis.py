"""IMU figures from samples: Allan deviation, spectrum, and the in-flight vibration level.

How this works, on a uniformly sampled series (rate taken as the median of the logged one):

- :func:`allan_deviation`: the overlapping Allan deviation (IEEE Std 952 annex C) of a rate
  signal at octave-spaced averaging times, from the cumulative sum: for white noise of density
  N it falls as N / sqrt(tau) with N in Kalibr's convention (continuous-time, two-sided: a
  sample at rate f carries N sqrt(f); EuRoC's ``sensor.yaml``), so ``adev(1 s)`` reads such a
  density; a data sheet's one-sided density N gives N / sqrt(2 tau).
- :func:`spectrum`: Welch's averaged periodogram (Hann window, half-overlapping segments),
  one-sided, as an amplitude spectral density (units / sqrt(Hz)).
- :func:`band_rms`: the RMS of the content from ``low_hz`` to Nyquist (the spectrum
  integrated), the figure issue 33 compares: a hovering multirotor's vibration above 10 Hz.
"""

from __future__ import annotations

import math

import numpy as np


def allan_deviation(x: np.ndarray, rate_hz: float, points: int = 24
                    ) -> tuple[np.ndarray, np.ndarray]:
    """Overlapping Allan deviation of a 1-D rate series: (taus s, adev), octave-spaced taus
    from one sample up to a ninth of the series."""
    x = np.asarray(x, dtype=float)
    n = len(x)
    dt = 1.0 / rate_hz
    theta = np.concatenate(([0.0], np.cumsum(x) * dt))
    m_max = max(1, n // 9)
    ms = np.unique(np.round(np.logspace(0, math.log10(m_max), points)).astype(int))
    taus, devs = [], []
    for m in ms:
        d = theta[2 * m:] - 2.0 * theta[m:-m] + theta[:-2 * m]
        if len(d) == 0:
            continue
        tau = m * dt
        taus.append(tau)
        devs.append(math.sqrt(float(np.mean(d * d)) / (2.0 * tau * tau)))
    return np.array(taus), np.array(devs)


def adev_at(x: np.ndarray, rate_hz: float, tau_s: float) -> float:
    """The Allan deviation at ``tau_s`` (interpolated on log axes; on a linear one where it is
    0 at some tau: a constant series, a dead sensor's axis, has no logarithm, and numpy's
    "divide by zero" warning went to stderr under the table)."""
    taus, devs = allan_deviation(x, rate_hz, points=40)
    if not np.all(devs > 0.0):
        return float(np.interp(math.log(tau_s), np.log(taus), devs))
    return float(np.exp(np.interp(math.log(tau_s), np.log(taus), np.log(devs))))


def spectrum(x: np.ndarray, rate_hz: float, segment: int = 1024
             ) -> tuple[np.ndarray, np.ndarray]:
    """One-sided amplitude spectral density of a 1-D series: (frequencies Hz, units/sqrt(Hz))."""
    x = np.asarray(x, dtype=float)
    seg = min(segment, len(x))
    window = np.hanning(seg)
    step = max(1, seg // 2)
    scale = 1.0 / (rate_hz * float(np.sum(window * window)))
    psd = np.zeros(seg // 2 + 1)
    count = 0
    for start in range(0, len(x) - seg + 1, step):
        chunk = x[start:start + seg]
        f = np.fft.rfft((chunk - chunk.mean()) * window)
        psd += (np.abs(f) ** 2) * scale
        count += 1
    psd /= max(1, count)
    psd[1:-1] *= 2.0  # one-sided
    return np.fft.rfftfreq(seg, 1.0 / rate_hz), np.sqrt(psd)


def band_rms(x: np.ndarray, rate_hz: float, low_hz: float = 10.0) -> float:
    """RMS of the content from ``low_hz`` to Nyquist."""
    freqs, asd = spectrum(x, rate_hz)
    df = freqs[1] - freqs[0]
    keep = freqs >= low_hz
    return math.sqrt(float(np.sum(asd[keep] ** 2) * df))


def samples_above(rate_hz: float, low_hz: float) -> bool:
    """Whether a series at ``rate_hz`` samples anything above ``low_hz``: its Nyquist frequency
    is above it by more than 1 % (a rate read from a log's stamps carries their rounding: a
    20 Hz EuRoC log's read 20.00005 Hz, its one spectral bin at 10 Hz the whole "band")."""
    return rate_hz > lowest_rate_hz(low_hz)


def lowest_rate_hz(low_hz: float) -> float:
    """The rate a series must be over to sample anything above ``low_hz`` (see
    :func:`samples_above`)."""
    return 2.0 * low_hz * 1.01


def imu_figures(gyro: np.ndarray, accel: np.ndarray, rate_hz: float,
                low_hz: float = 10.0) -> dict[str, float]:
    """Per-axis-averaged figures: vibration RMS above ``low_hz`` and ADEV at 1 s (where white
    noise dominates, its density in Kalibr's convention: see :func:`allan_deviation`), for the
    gyro and the accelerometer. The vibration is left out where the Nyquist frequency is not
    above ``low_hz`` (nothing above it is sampled: it read 0), the ADEV where the series is
    shorter than 9 s."""
    out: dict[str, float] = {}
    for name, data in (("gyro", gyro), ("accel", accel)):
        if samples_above(rate_hz, low_hz):
            out[f"{name}_band_rms"] = float(np.mean([band_rms(data[:, i], rate_hz, low_hz)
                                                     for i in range(3)]))
        if len(data) >= 9 * rate_hz:
            out[f"{name}_adev_1s"] = float(np.mean([adev_at(data[:, i], rate_hz, 1.0)
                                                    for i in range(3)]))
    return out
