"""Whether an implicit quadric's curvature is confirmed by the height quadric over its points.

On a clean cloud the implicit quadric over 24 neighbors is exact on quadrics, but on other
surfaces it is only close to the points, and with 10 coefficients over 13 to 25 points it can
be close to them while bending far more than they do: where a surface's curvature changes sign
(an inflection line, sampled at random) a hyperbolic quadric threads the points with a vertex
beside the anchor. Noise-free, on a sine wave of 20 spacings' wavelength (k up to 3.1) 0.2 to
0.5 % of the points read 7 to 48 that way (docs/accuracy.md, section 9, step 44). The height
(Monge) quadric over the same points has 6 coefficients and no second sheet: it is biased by
the surface's cubic terms, but never by much where the points are smooth. So a fit is not used
where the two disagree by more than the height fit's own bias allows:

- by more than ``AGREE`` over the points' RMS distance ``h`` from the anchor, plus the height
  quadric's bias on a tight bend (its relative error grows as ``(k h)^2``, so
  ``(k h)^3 / h``), or
- by more than ``CLOSE / h`` where the implicit quadric reads over ``RATIO`` times the height
  quadric's largest curvature (an overshoot: the blow-ups read several times it).
"""

from __future__ import annotations

import numpy as np

#: Disagreement (times h, radians of normal turn across the patch) always left unused. At
#: 0.15 the wave kept 17 of its 32 blow-ups (seed 6); at 0.1 without the bend allowance the
#: filleted cylinder's toroidal fillet (k 6.7, a few spacings) lost 33 good fits (0.21 -> 0.29).
AGREE = 0.1
#: ... and the disagreement left unused where the implicit fit overshoots by RATIO.
CLOSE = 0.03
RATIO = 1.5


def unconfirmed(k1, k2, m1, m2, h):
    """Where an implicit fit's curvatures disagree with the height fit's (module docstring).

    Parameters
    ----------
    k1, k2 : ndarray, shape (m,)
        The implicit fit's principal curvatures (either sign convention).
    m1, m2 : ndarray, shape (m,)
        The height fit's over the same points (NaN where it failed: never unconfirmed).
    h : ndarray, shape (m,)
        RMS distance of the points from the anchor.

    Returns
    -------
    ndarray, shape (m,), bool
    """
    a1, a2 = np.minimum(k1, k2), np.maximum(k1, k2)
    b1, b2 = np.minimum(m1, m2), np.maximum(m1, m2)
    # The two fits' normals may point either way: the smaller of the two pairings.
    dk = np.minimum(np.maximum(np.abs(a1 - b1), np.abs(a2 - b2)),
                    np.maximum(np.abs(a2 + b1), np.abs(a1 + b2)))
    big_m = np.maximum(np.abs(b1), np.abs(b2))
    big_k = np.maximum(np.abs(a1), np.abs(a2))
    off = (dk * h > AGREE + (big_m * h) ** 3) | ((dk * h > CLOSE) & (big_k > RATIO * big_m))
    return off & np.isfinite(dk)
