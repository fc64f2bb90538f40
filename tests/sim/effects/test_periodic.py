"""The position harmonics' periodogram (``harmonic_shares``) of the cogging effect and
the free-form search's periodic peaks."""

import numpy as np

from cdpr_pipeline.sim.effects.periodic import harmonic_shares


def test_shares_over_many_wavenumbers_are_each_ones_own():
    # more wavenumbers than are taken at once: every block gives each its own share,
    # and the true wavenumber explains the residual
    seed = 4
    print(f"seed {seed}")
    rng = np.random.default_rng(seed)
    angle = np.cumsum(rng.normal(0.0, 0.05, 3000))
    k = np.arange(1.0, 40.0, 0.25)                    # 156 wavenumbers
    residual = 0.7 * np.sin(13.5 * angle + 0.3) + 0.05 * rng.normal(size=angle.size)
    shares = harmonic_shares(angle, residual, k)
    alone = np.array([harmonic_shares(angle, residual, k[j:j + 1])[0]
                      for j in range(k.size)])
    assert np.allclose(shares, alone, rtol=1e-10, atol=1e-12)
    assert k[int(np.argmax(shares))] == 13.5
    assert shares.max() > 0.98


def test_a_residual_weighted_down_at_reversals_is_scanned_with_its_weights():
    """A hard sign law weights the torque residual down around every reversal (friction
    unknown there); compared with unweighted harmonics, the mask ranks the counts as
    much as the torque does. A joint swinging 0.4 rad with 24 periods per revolution and
    most of its rows weighted down (the draw of seed 277656582 of test_cogging's
    axes-rotary: the true count came fourth, and 25 was named): with the weights taken
    on the harmonics, the true count explains the residual exactly, and first."""
    t = np.linspace(0.0, 20.0, 4000)
    angle = 0.2 * np.sin(2 * np.pi * 0.3 * t) + 0.01 * np.sin(2 * np.pi * 1.1 * t)
    speed = np.gradient(angle, t)
    # weight 0 where the joint turns slowly (near the reversals), 1 elsewhere, smooth
    weight = np.clip((np.abs(speed) / np.abs(speed).max() - 0.3) / 0.4, 0.0, 1.0)
    residual = weight * 16.7 * np.sin(24 * angle + 5.85)
    counts = np.arange(2.0, 49.0)
    weighted = harmonic_shares(angle, residual, counts, weight)
    assert counts[int(np.argmax(weighted))] == 24 and weighted.max() > 1 - 1e-9
    assert np.sort(weighted)[-2] < 0.995            # the neighbours fall behind
    # unweighted, the mask limits every count alike: five counts within 2 % of the best,
    # none explaining most of the residual (a screen keeping three can miss the truth)
    plain = harmonic_shares(angle, residual, counts)
    assert plain.max() < 0.7 and np.sort(plain)[-5] > 0.98 * plain.max()
