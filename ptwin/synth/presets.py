"""Named experiment settings for ``Experiment(**preset, ...)``: what real recordings look like."""

from __future__ import annotations

# A soft cantilever on a soft gel, like public PAAm recordings (Abuhattum et al., iScience 2022): 10 µm
# bead, 0.088 N/m, 5/10/15 µm/s, 13 pN of AR(1) noise at 2 kHz, 0.7 µm deep, contacts to estimate under
# a tilted, offset baseline.
SOFT_CANTILEVER = {
    "probe_radius": 5e-6,
    "spring_constant": 0.088,
    "effective_modulus": 5e3,
    "base_speeds": (5e-6, 10e-6, 15e-6),
    "z_start": -1.5e-6,
    "z_end": 0.8e-6,
    "sample_rate": 2000.0,
    "noise_std": 1.3e-11,
    "noise_correlation": 0.3,
    "contact_point": "estimate",
    "contact_error": 1e-7,
    "baseline_offset": 2e-10,
    "tilt": 5e-4,
}
