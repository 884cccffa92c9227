"""The play operator's per-sample recursion, the reference the vectorized plays are tested against."""

import numpy as np


def per_sample_plays(u, r, y0):
    """Plays of thresholds ``r`` on the drive ``u`` sample by sample: ``y = max(u - r, min(u + r, y))``.

    Parameters
    ----------
    u : (n,) array, the drive [V or FS].
    r : (m,) array of constant thresholds, or (n, m) thresholds per sample [same unit as u].
    y0 : (m,) array, the plays' initial outputs.

    Returns
    -------
    (n, m) array, the plays' outputs.
    """
    r = np.asarray(r, float)
    y = np.array(y0, float)
    out = np.empty((u.size, y.size))
    for k in range(u.size):
        rk = r[k] if r.ndim == 2 else r
        y = np.maximum(u[k] - rk, np.minimum(u[k] + rk, y))
        out[k] = y
    return out
