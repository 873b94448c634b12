"""The upper quantiles that ptwin's tests reject beyond (χ², Student's t, F, the normal), from ``scipy.special``.

They are what ``scipy.stats`` returns, to the bit: its ``ppf`` and ``isf`` call these same functions (scale 1, loc
0). Importing ``scipy.stats`` costs 0.3 s beside torch, a twentieth of the demo, for four numbers.
"""

from __future__ import annotations

import scipy.special


def chi_square_exceeded(probability: float, dof: float) -> float:
    """The value a χ² on ``dof`` degrees of freedom exceeds with ``probability`` (``scipy.stats.chi2.ppf(1 − p)``)."""
    return float(2 * scipy.special.gammaincinv(dof / 2, 1.0 - probability))


def student_t_exceeded(probability: float, dof: float) -> float:
    """The value Student's t on ``dof`` degrees of freedom exceeds with ``probability`` (``t.ppf(1 − p)``)."""
    return float(scipy.special.stdtrit(dof, 1.0 - probability))


def fisher_exceeded(probability: float, numerator: float, denominator: float) -> float:
    """The value F(``numerator``, ``denominator``) exceeds with ``probability`` (``f.ppf(1 − p)``)."""
    return float(scipy.special.fdtri(numerator, denominator, 1.0 - probability))


def normal_exceeded(probability: float) -> float:
    """The value a standard normal exceeds with ``probability`` (``norm.isf(p)``)."""
    return float(-scipy.special.ndtri(probability))
