"""Errors against a noisy reference that cannot flatter (issue 30).

Given a method's values `a` and the reference's mean `r` with the variance of that mean `var_r` (from
independent runs, as the harness reports), per item (texel, pixel, point; channels flattened):

- raw MSE  = mean((a − r)²), which overstates the error by the reference's noise: E[(a − r)²] =
  (a − r_true)² + Var(r);
- corrected MSE = raw − mean(var_r) (− mean(var_a) when the method is noisy too);
- everything relative to the reference's converged mean level `norm = mean(r)` (never its maximum or a
  percentile, which noise inflates);
- the floor: the smallest relative RMSE the comparison can tell from zero, sqrt(2 · se0) / norm with se0
  the standard error of the corrected MSE of an exact method (the squared Gaussian noise of the n items:
  the reference's, plus the method's own when it is a Monte-Carlo estimate too); a corrected relative
  RMSE below it is reported as "< floor X", never as a smaller number. (The variances come from a few
  independent runs; their own uncertainty is not included.)
"""
import math

import numpy as np


def noise_corrected(a, r, var_r, var_a=None):
    """dict(rel_rmse, floor, below_floor, ci95, raw_rel_rmse, norm, text)."""
    a, r, var_r = (np.asarray(x, float).ravel() for x in (a, r, var_r))
    if a.shape != r.shape or r.shape != var_r.shape:
        raise ValueError(f"shapes differ: method {a.shape}, reference {r.shape}, variance {var_r.shape}")
    norm = float(np.mean(r))
    if not norm > 0.0:
        raise ValueError("the reference's mean is not positive: an error relative to it is meaningless "
                         "(an empty reference judges nothing)")
    raw = float(np.mean((a - r) ** 2))
    if var_a is not None:
        var_a = np.asarray(var_a, float).ravel()
        if var_a.shape != a.shape:
            raise ValueError(f"shapes differ: method {a.shape}, its variance {var_a.shape}")
    # Both sides' noise: independent estimates, so the variances of a − r add.
    var = var_r + var_a if var_a is not None else var_r
    corrected = raw - float(np.mean(var))
    # With no error, (a − r)² is the squared noise: variance 2 var² per item (Gaussian means), so the
    # corrected MSE of an exact method scatters by se0 = sqrt(mean(2 var²) / n).
    se0 = math.sqrt(float(np.mean(2.0 * var**2)) / var.size)
    floor = math.sqrt(2.0 * se0) / norm
    rel = math.sqrt(max(corrected, 0.0)) / norm
    below = rel < floor
    # 95 % interval: per item (a − r)² has variance 2 var² + 4 d² var for a true difference d (Gaussian
    # means), d² estimated by max((a − r)² − var, 0); the corrected MSE's standard error follows.
    d2 = np.maximum((a - r) ** 2 - var, 0.0)
    se = math.sqrt(float(np.sum(2.0 * var**2 + 4.0 * d2 * var))) / var.size
    ci95 = [math.sqrt(max(corrected - 1.96 * se, 0.0)) / norm, math.sqrt(max(corrected + 1.96 * se, 0.0)) / norm]
    text = f"< floor {floor:.3g}" if below else f"{rel:.4g} (floor {floor:.3g})"
    return {"rel_rmse": None if below else rel, "floor": floor, "below_floor": below, "ci95": ci95,
            "raw_rel_rmse": math.sqrt(raw) / norm, "norm": norm, "text": text}
