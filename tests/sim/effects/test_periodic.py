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
