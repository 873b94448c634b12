"""Where a curve's contact point is unknown (``contact_point: estimate``, vendor imports):
its estimate, and the baseline offset and tilt removed from its force.

1. A first baseline: a straight line force(z) over the first fifth of the travel; the
   contact guess is where the force leaves it for good (more than ``DEPARTURE`` robust
   standard deviations above it from there on).
2. The baseline: the line refitted over the first 75% of the travel before that guess
   (clear of the long-range forces just before contact); its offset and tilt (virtual
   deflection) are removed from the whole curve.
3. The refinement: with the baseline removed, the depth w = z − F/k_s, and the contact
   w0 where F = c·(w − w0)^1.5 fits the start of the indentation best (the Hertz shape of
   a sphere; a coarse grid then a fine one, c by linear least squares at each w0).

Why not nanite's estimators (``nanite.poc``): its Fréchet-distance guess lands well inside
contact when the baseline is short against the indentation (1.1 µm into a 4 µm Hertzian
indent after 1 µm of baseline, which spoilt the baseline line fitted before it), and its
fitted estimators take ~0.2 s a curve (too slow for force maps) with a shape-free
polynomial where a sphere's contact has a known shape. The fit refines each curve's
contact again, jointly with the physics (``ptwin.physics.contact``).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

DEPARTURE = 5.0  # robust standard deviations above the first baseline where contact has begun
SCAN = 101  # candidate contact depths per grid of the refinement


@dataclass(frozen=True)
class Baseline:
    """One curve's estimated contact and the baseline removed from its force."""

    contact_z: float  # the file's z at the contact [m]: z − contact_z is the travel past contact
    offset: float  # the baseline's force at the contact [N]
    tilt: float  # its slope dF/dz [N/m] (virtual deflection)

    def remove(self, z: np.ndarray, force: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(z from the contact, force without the baseline) [m, N]."""
        travel = z - self.contact_z
        return travel, force - (self.offset + self.tilt * travel)


class NoBaseline(ValueError):
    """The approach starts in contact: no free travel to take a baseline from."""


def estimate_baseline(z: np.ndarray, force: np.ndarray, spring_constant: float) -> Baseline:
    """The contact and baseline of an approach (``z`` increasing into the sample [m], ``force`` [N])."""
    first = z <= z[0] + 0.2 * (z[-1] - z[0])
    if first.sum() < 10:
        raise NoBaseline("fewer than 10 samples in the first fifth of the travel")
    tilt, intercept = np.polyfit(z[first], force[first], 1)
    excess = force - (intercept + tilt * z)
    spread = 1.4826 * np.median(np.abs(excess[first] - np.median(excess[first])))
    below = np.flatnonzero(excess <= DEPARTURE * spread)
    guess = int(below[-1]) + 1 if below.size else 0
    free = z <= z[0] + 0.75 * (z[min(guess, z.size - 1)] - z[0])
    if free.sum() < 10:
        raise NoBaseline("the force leaves the baseline within the first 10 samples")
    tilt, intercept = np.polyfit(z[free], force[free], 1)
    excess = force - (intercept + tilt * z)
    depth = z - excess / spring_constant
    contact_z = _hertz_contact(depth, excess, depth[min(guess, z.size - 1)])  # F = 0 there, so z = w
    return Baseline(float(contact_z), float(intercept + tilt * contact_z), float(tilt))


def _hertz_contact(depth: np.ndarray, force: np.ndarray, guess: float) -> float:
    """w0 minimising Σ (F − c·(w − w0)₊^1.5)² over the approach up to half its largest force."""
    stop = max(int(np.argmax(force >= 0.5 * force.max())), 20)
    w, f = depth[:stop], force[:stop]
    spacing = max(w[-1] - w[0], 1e-12) / (SCAN - 1)  # of the coarse grid
    best = guess
    for half_width in (0.5 * (SCAN - 1) * spacing, 4 * spacing):  # coarse, then fine around the best
        best = _best_contact(w, f, np.linspace(best - half_width, best + half_width, SCAN))
    return best


def _best_contact(w: np.ndarray, f: np.ndarray, candidates: np.ndarray) -> float:
    shape = np.clip(w[None, :] - candidates[:, None], 0.0, None) ** 1.5
    norm = np.einsum("ij,ij->i", shape, shape)
    scale = np.where(norm > 0, shape @ f / np.where(norm > 0, norm, 1.0), 0.0)
    misfit = np.sum((f[None, :] - scale[:, None] * shape) ** 2, axis=1)
    misfit[scale <= 0] = np.inf
    return float(candidates[int(np.argmin(misfit))])
