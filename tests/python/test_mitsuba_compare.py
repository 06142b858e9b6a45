"""`mitsuba_ref.compare`: the noise correction recovers a known error from noisy references, and an
error hidden by the reference's noise is reported as "< floor", never as a smaller number."""
import pathlib
import sys

import numpy as np
import pytest

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parents[2] / "python"))
from mitsuba_ref.compare import noise_corrected  # noqa: E402


def test_known_error_is_recovered_under_reference_noise():
    rng = np.random.default_rng(1)
    truth = rng.uniform(0.5, 1.5, 20000)
    a = truth * 1.05  # a 5 % error (relative RMSE 0.05 × rms(truth)/mean(truth))
    sigma = 0.2  # reference noise 4× larger than the error per item
    r = truth + rng.normal(0, sigma, truth.size)
    out = noise_corrected(a, r, np.full(truth.size, sigma**2))
    want = np.sqrt(np.mean((0.05 * truth) ** 2)) / np.mean(truth)
    assert out["raw_rel_rmse"] > 3 * want  # the uncorrected number would mislead
    assert out["rel_rmse"] == pytest.approx(want, rel=0.1)
    assert not out["below_floor"]


def test_a_noisy_method_has_its_own_noise_subtracted_too():
    # An internal reference judged by Mitsuba is a Monte-Carlo estimate itself: with its variance given,
    # its 5 % bias is recovered under both sides' noise, and without it the error would read as its noise.
    rng = np.random.default_rng(3)
    truth = rng.uniform(0.5, 1.5, 20000)
    sa, sr = 0.15, 0.1
    a = truth * 1.05 + rng.normal(0, sa, truth.size)
    r = truth + rng.normal(0, sr, truth.size)
    want = np.sqrt(np.mean((0.05 * truth) ** 2)) / np.mean(truth)
    out = noise_corrected(a, r, np.full(truth.size, sr**2), np.full(truth.size, sa**2))
    assert out["rel_rmse"] == pytest.approx(want, rel=0.15)
    assert out["ci95"][0] <= want <= out["ci95"][1]
    only_r = noise_corrected(a, r, np.full(truth.size, sr**2))
    assert only_r["rel_rmse"] > 2.5 * want  # the method's noise counted as its error
    # The floor counts both sides' noise: larger than with the reference's alone.
    assert out["floor"] > only_r["floor"]
    with pytest.raises(ValueError, match="its variance"):
        noise_corrected(a, r, np.full(truth.size, sr**2), np.ones(3))


def test_error_below_the_noise_floor_is_reported_as_a_floor():
    rng = np.random.default_rng(2)
    truth = np.ones(50)
    r = truth + rng.normal(0, 0.3, truth.size)
    out = noise_corrected(truth * 1.001, r, np.full(truth.size, 0.09))
    assert out["below_floor"] and out["rel_rmse"] is None
    # 50 items with noise 0.3 each: the MSE is known to ± ~0.018, so errors below ~0.19 are hidden.
    assert out["text"] == f"< floor {out['floor']:.3g}" and 0.1 < out["floor"] < 0.3


def test_empty_reference_is_refused():
    with pytest.raises(ValueError, match="empty reference"):
        noise_corrected([1.0, 2.0], [0.0, 0.0], [0.0, 0.0])


def test_confidence_interval_covers_the_true_error_about_95_percent_of_the_time():
    # 400 independent noisy references of one method with a known 8 % error: the 95 % interval must
    # contain the true relative RMSE in about 95 % of them (binomial: 380 ± 9; accept 360 to 395).
    rng = np.random.default_rng(3)
    truth = rng.uniform(0.5, 1.5, 2000)
    a = truth * 1.08
    want = np.sqrt(np.mean((0.08 * truth) ** 2)) / np.mean(truth)
    sigma = 0.1
    hits = 0
    for _ in range(400):
        r = truth + rng.normal(0, sigma, truth.size)
        lo, hi = noise_corrected(a, r, np.full(truth.size, sigma**2))["ci95"]
        hits += lo <= want <= hi
    assert 360 <= hits <= 395, hits
