"""Correlation-based model validity tests (Billings & Voon) and resampling helpers.

A model is adequate when its one-step residual ``e`` is unpredictable from past
residuals and inputs ``u``. Billings & Voon (1983, 1986) turn that into five
normalised correlation functions that must vanish (or be a delta at lag 0):

==========  =====================================  ============================
name        function                               judged on lags
==========  =====================================  ============================
``ee``      phi_ee(k) = delta(k)                   1 .. max_lag
``ue``      phi_ue(k) = 0                          -max_lag .. max_lag
``e_eu``    phi_e(eu)(k) = 0                       0 .. max_lag-1
``u2e``     phi_(u^2)'e(k) = 0                     -max_lag .. max_lag
``u2e2``    phi_(u^2)'(e^2)'(k) = 0                -max_lag .. max_lag
==========  =====================================  ============================

with the lag convention of :func:`correlation`: ``phi_xy(k)`` pairs ``x(t)`` with
``y(t+k)``, so a positive lag in ``ue`` means the input *leads* the residual
(``e(t) = u(t-3)`` peaks at ``k = +3``). ``e_eu`` follows SysIdentPy / Billings:
``phi_e(eu)(k) = corr(e(t), e(t-1-k) u(t-1-k))`` for ``k >= 0``. The linear tests
(``ee``, ``ue``) miss even-order nonlinearity; the squared-input tests catch it.

The 95 % band is ``1.96 / sqrt(N)``. A test passes when both

* the number of judged lags outside the band is not significantly larger than
  the 5 % expected of white noise (one-sided binomial test), which catches broad
  structure such as a slowly decaying autocorrelation, and
* the largest ``|r|`` stays inside the simultaneous (Bonferroni) band over the
  judged lags, which catches a single strong spike, e.g. one missing delay term
  or a missing ``u^2`` term: one lag out of 41 is within the count margin however
  large it is.

Each check runs at ``alpha / 2`` (default ``alpha = 0.01``), so white noise fails
any one test only about 1 % of the time instead of almost always over 41 lags.

Examples
--------
>>> import numpy as np
>>> rng = np.random.default_rng(0)
>>> u, e = rng.standard_normal(2000), rng.standard_normal(2000)
>>> correlation_tests(e, u).passed
True
>>> bool(correlation_tests(e + 0.5 * np.roll(u, 3), u).ue.passed)
False
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass, field, fields
from typing import Any

import numpy as np
from scipy import signal, stats

__all__ = [
    "CorrelationTest",
    "ValidityTests",
    "block_bootstrap",
    "block_sum_bootstrap",
    "bootstrap_draws",
    "correlation",
    "correlation_tests",
    "ljung_box_pvalue",
    "split_blocks",
]

_Z95 = 1.96  # two-sided 95 % normal quantile, the band used throughout the literature
_EXPECTED_OUTSIDE = 0.05  # share of lags white noise puts outside a 95 % band


def _as_1d(x, name: str) -> np.ndarray:
    a = np.asarray(x, dtype=float)
    if a.ndim != 1:
        raise ValueError(f"{name} must be 1-D, got shape {a.shape}")
    if not np.all(np.isfinite(a)):
        raise ValueError(f"{name} contains NaN or inf")
    return a


def correlation(x, y, max_lag: int) -> tuple[np.ndarray, np.ndarray]:
    """Normalised cross-correlation of two signals after removing their means.

    ``r[k] = sum_t x'(t) y'(t+k) / sqrt(sum x'^2 * sum y'^2)`` for
    ``k = -max_lag .. max_lag``, where ``'`` marks the mean-removed signal. The sum
    runs over the overlapping samples but the normaliser over all ``N`` (the usual
    biased estimator, whose variance at nonzero lags is about ``1/N``).

    Parameters
    ----------
    x, y : array-like of shape (N,)
        Signals of equal length.
    max_lag : int
        Largest lag, ``0 <= max_lag < N``.

    Returns
    -------
    lags : ndarray of int, shape (2 * max_lag + 1,)
        ``-max_lag .. max_lag``. Positive ``k``: ``x`` leads ``y`` by ``k`` samples.
    r : ndarray of shape (2 * max_lag + 1,)
        Correlation coefficients in ``[-1, 1]``.

    Raises
    ------
    ValueError
        On shape mismatch, non-finite values or a constant signal (zero variance
        leaves the coefficient undefined).

    Examples
    --------
    >>> x = np.array([1.0, 2.0, 3.0, 4.0])
    >>> lags, r = correlation(x, x, 1)
    >>> lags.tolist(), np.round(r, 2).tolist()
    ([-1, 0, 1], [0.25, 1.0, 0.25])
    """
    xs, ys = _as_1d(x, "x"), _as_1d(y, "y")
    n = xs.shape[0]
    if ys.shape[0] != n:
        raise ValueError(f"lengths differ: {n} vs {ys.shape[0]}")
    max_lag = int(max_lag)
    if not 0 <= max_lag < n:
        raise ValueError(f"max_lag must be in [0, {n - 1}], got {max_lag}")
    xs, ys = xs - xs.mean(), ys - ys.mean()
    denom = np.sqrt(np.dot(xs, xs) * np.dot(ys, ys))
    if denom == 0.0:
        raise ValueError("a signal is constant; its correlation is undefined")
    # scipy picks FFT for long signals; full[n-1+k] = sum_t x(t) y(t+k)
    full = signal.correlate(ys, xs, mode="full", method="auto")
    r = full[n - 1 - max_lag : n + max_lag] / denom
    return np.arange(-max_lag, max_lag + 1), np.clip(r, -1.0, 1.0)


@dataclass(frozen=True)
class CorrelationTest:
    """One correlation test: the judged lags, their values and the verdict.

    Attributes
    ----------
    name : str
        ``"ee"``, ``"ue"``, ``"e_eu"``, ``"u2e"`` or ``"u2e2"``.
    lags, values : ndarray
        The judged lags and the correlation at each (empty when ``note`` says the
        test was not applicable).
    band : float
        Half-width of the 95 % band, ``1.96 / sqrt(N)``.
    n_outside : int
        Judged lags with ``|r| > band``.
    fraction_outside : float
        ``n_outside / len(lags)``.
    allowed : float
        Largest ``fraction_outside`` that still passes.
    max_abs : float
        Largest ``|r|`` over the judged lags.
    max_band : float
        Largest ``max_abs`` that still passes (simultaneous band over the lags).
    lag_at_max : int or None
        Lag where ``max_abs`` occurs.
    passed : bool
        ``fraction_outside <= allowed and max_abs <= max_band``.
    input_index : int or None
        For input tests, the input column reported (the worst one).
    note : str
        Why a test was skipped, else empty.
    """

    name: str
    lags: np.ndarray
    values: np.ndarray
    band: float
    n_outside: int
    fraction_outside: float
    allowed: float
    max_abs: float
    max_band: float
    lag_at_max: int | None
    passed: bool
    input_index: int | None = None
    note: str = ""

    def as_dict(self, full: bool = False) -> dict[str, Any]:
        """JSON-able summary; the lag and value arrays only when ``full``."""
        d: dict[str, Any] = {
            "band": float(self.band),
            "fraction_outside": float(self.fraction_outside),
            "n_outside": int(self.n_outside),
            "n_lags": int(len(self.lags)),
            "allowed": float(self.allowed),
            "max_abs": float(self.max_abs),
            "max_band": float(self.max_band),
            "lag_at_max": None if self.lag_at_max is None else int(self.lag_at_max),
            "passed": bool(self.passed),
            "input_index": self.input_index,
        }
        if self.note:
            d["note"] = self.note
        if full:
            d["lags"] = [int(k) for k in self.lags]
            d["values"] = [float(v) for v in self.values]
        return d


@dataclass(frozen=True)
class ValidityTests:
    """The five Billings & Voon tests of one residual against its inputs.

    Attributes
    ----------
    ee, ue, e_eu, u2e, u2e2 : CorrelationTest
        See the module docstring. Input tests report the worst input column.
    n_samples : int
        Residual length ``N``.
    max_lag : int
        Lag range used.
    """

    ee: CorrelationTest
    ue: CorrelationTest
    e_eu: CorrelationTest
    u2e: CorrelationTest
    u2e2: CorrelationTest
    n_samples: int = field(default=0)
    max_lag: int = field(default=0)

    @property
    def tests(self) -> dict[str, CorrelationTest]:
        """The five tests by name, in the order ee, ue, e_eu, u2e, u2e2."""
        return {
            f.name: getattr(self, f.name)
            for f in fields(self)
            if isinstance(getattr(self, f.name), CorrelationTest)
        }

    @property
    def passed(self) -> bool:
        """True when all five tests pass."""
        return all(t.passed for t in self.tests.values())

    def as_dict(self, full: bool = False) -> dict[str, Any]:
        """JSON-able summary: overall verdict plus one entry per test.

        ``{"passed", "n_samples", "max_lag", "ee": {...}, "ue": {...}, ...}`` where
        each test entry is :meth:`CorrelationTest.as_dict`.
        """
        d: dict[str, Any] = {
            "passed": self.passed,
            "n_samples": int(self.n_samples),
            "max_lag": int(self.max_lag),
        }
        d.update({name: t.as_dict(full=full) for name, t in self.tests.items()})
        return d


def _allowed_count(n_lags: int, alpha: float) -> int:
    """Most lags outside the band that a one-sided binomial test at ``alpha`` accepts.

    Same verdict as ``scipy.stats.binomtest(c, n, 0.05, "greater").pvalue >= alpha``,
    computed once for all ``c`` instead of per test.
    """
    counts = np.arange(n_lags + 1)
    p_at_least = stats.binom.sf(counts - 1, n_lags, _EXPECTED_OUTSIDE)
    return int(counts[p_at_least >= alpha].max())


def _judge(
    name: str,
    lags: np.ndarray,
    values: np.ndarray,
    n_samples: int,
    allowed: float | None,
    alpha: float,
    input_index: int | None = None,
) -> CorrelationTest:
    n_lags = len(lags)
    band = _Z95 / np.sqrt(n_samples)
    n_out = int(np.count_nonzero(np.abs(values) > band))
    # half the level to each check keeps the white-noise false alarm near alpha
    if allowed is None:
        ok_count = _allowed_count(n_lags, alpha / 2)
        allowed_frac = ok_count / n_lags
        count_ok = n_out <= ok_count  # integer compare: no float round-off at the edge
    else:
        allowed_frac = float(allowed)
        count_ok = n_out / n_lags <= allowed_frac
    # r(k) ~ N(0, 1/N) per lag for white noise; Bonferroni over the two-sided lags
    max_band = float(stats.norm.isf(alpha / 2 / (2 * n_lags)) / np.sqrt(n_samples))
    i = int(np.argmax(np.abs(values)))
    max_abs = float(np.abs(values[i]))
    return CorrelationTest(
        name=name,
        lags=lags,
        values=values,
        band=band,
        n_outside=n_out,
        fraction_outside=n_out / n_lags,
        allowed=allowed_frac,
        max_abs=max_abs,
        max_band=max_band,
        lag_at_max=int(lags[i]),
        passed=bool(count_ok and max_abs <= max_band),
        input_index=input_index,
    )


def _skipped(name: str, n_samples: int, input_index: int, note: str) -> CorrelationTest:
    empty = np.zeros(0)
    return CorrelationTest(
        name=name,
        lags=empty.astype(int),
        values=empty,
        band=_Z95 / np.sqrt(n_samples),
        n_outside=0,
        fraction_outside=0.0,
        allowed=_EXPECTED_OUTSIDE,
        max_abs=0.0,
        max_band=0.0,
        lag_at_max=None,
        passed=True,
        input_index=input_index,
        note=note,
    )


def _worst(candidates: list[CorrelationTest]) -> CorrelationTest:
    # a failing column beats a passing one; then more lags outside, then larger |r|
    return max(candidates, key=lambda t: (not t.passed, t.fraction_outside, t.max_abs))


def correlation_tests(
    residual,
    inputs,
    max_lag: int = 20,
    allowed: float | None = None,
    alpha: float = 0.01,
) -> ValidityTests:
    """Run the five Billings & Voon correlation tests on a model residual.

    Parameters
    ----------
    residual : array-like of shape (N,)
        One-step-ahead (or simulation) residual ``e = y - yhat``.
    inputs : array-like of shape (N,) or (N, m)
        Model inputs ``u``. With several columns the four input tests run per
        column and the worst column is reported (its index in ``input_index``).
    max_lag : int, default 20
        Lag range, ``1 <= max_lag < N``.
    allowed : float, optional
        Fixed largest share of judged lags outside the band that still passes.
        Default: the binomial margin over 5 % (see ``alpha``).
    alpha : float, default 0.01
        Level at which white noise may fail a test: ``alpha / 2`` for the
        one-sided binomial test on the count outside the band (when ``allowed`` is
        None) and ``alpha / 2`` for the simultaneous band on ``max_abs``.

    Returns
    -------
    ValidityTests
        ``.passed`` is True when all five pass.

    Notes
    -----
    ``u2e`` and ``u2e2`` are skipped (passed, with a ``note``) for an input whose
    square is constant, e.g. a binary PRBS: ``u^2`` carries no information then.
    The bands assume ``r(k) ~ N(0, 1/N)``; for heavy-tailed residuals the fourth-order
    ``u2e2`` test rejects white noise more often than ``alpha`` (about 9 % for
    Student-t(5) residuals at ``N = 2000``).

    Examples
    --------
    >>> rng = np.random.default_rng(1)
    >>> u = rng.standard_normal(2000)
    >>> e = u**2 - 1 + 0.1 * rng.standard_normal(2000)   # missed even nonlinearity
    >>> res = correlation_tests(e, u)
    >>> res.ue.passed, res.u2e.passed
    (True, False)
    """
    e = _as_1d(residual, "residual")
    n = e.shape[0]
    u = np.asarray(inputs, dtype=float)
    if u.ndim == 1:
        u = u[:, None]
    if u.ndim != 2 or u.shape[0] != n:
        raise ValueError(f"inputs must have shape ({n},) or ({n}, m), got {np.shape(inputs)}")
    if u.shape[1] == 0:
        raise ValueError("inputs has no columns")
    if not np.all(np.isfinite(u)):
        raise ValueError("inputs contains NaN or inf")
    max_lag = int(max_lag)
    if not 1 <= max_lag < n:
        raise ValueError(f"max_lag must be in [1, {n - 1}], got {max_lag}")

    mid = max_lag  # index of lag 0 in a correlation() result

    lags, r = correlation(e, e, max_lag)
    ee = _judge("ee", lags[mid + 1 :], r[mid + 1 :], n, allowed, alpha)

    e2 = e**2
    ue_c, e_eu_c, u2e_c, u2e2_c = [], [], [], []
    for j in range(u.shape[1]):
        uj = u[:, j]
        lags, r = correlation(uj, e, max_lag)
        ue_c.append(_judge("ue", lags, r, n, allowed, alpha, j))
        # corr(e(t), e(t-1-k) u(t-1-k)) is corr(eu, e) at lag k+1 in our convention
        lags, r = correlation(e * uj, e, max_lag)
        e_eu_c.append(_judge("e_eu", lags[mid + 1 :] - 1, r[mid + 1 :], n, allowed, alpha, j))
        u2 = uj**2
        if np.ptp(u2) == 0.0:
            note = "u^2 is constant (binary input): test not informative"
            u2e_c.append(_skipped("u2e", n, j, note))
            u2e2_c.append(_skipped("u2e2", n, j, note))
            continue
        # correlation() removes the means, giving (u^2)' and (e^2)'
        lags, r = correlation(u2, e, max_lag)
        u2e_c.append(_judge("u2e", lags, r, n, allowed, alpha, j))
        lags, r = correlation(u2, e2, max_lag)
        u2e2_c.append(_judge("u2e2", lags, r, n, allowed, alpha, j))

    return ValidityTests(
        ee=ee,
        ue=_worst(ue_c),
        e_eu=_worst(e_eu_c),
        u2e=_worst(u2e_c),
        u2e2=_worst(u2e2_c),
        n_samples=n,
        max_lag=max_lag,
    )


def ljung_box_pvalue(residual, lags: int = 20) -> float:
    """Ljung-Box portmanteau p-value for whiteness of a residual.

    ``Q = N (N + 2) sum_{k=1..h} r_k^2 / (N - k)``, ``p = chi2.sf(Q, h)`` with ``r_k``
    the autocorrelation of the mean-removed residual. Small p: not white.

    Parameters
    ----------
    residual : array-like of shape (N,)
    lags : int, default 20
        Number of lags ``h``, ``1 <= h < N``.

    Returns
    -------
    float
        p-value in ``[0, 1]``.

    Examples
    --------
    >>> rng = np.random.default_rng(0)
    >>> ljung_box_pvalue(rng.standard_normal(2000)) > 0.01
    True
    """
    e = _as_1d(residual, "residual")
    n, h = e.shape[0], int(lags)
    if not 1 <= h < n:
        raise ValueError(f"lags must be in [1, {n - 1}], got {h}")
    _, r = correlation(e, e, h)
    rk = r[h + 1 :]
    q = n * (n + 2) * np.sum(rk**2 / (n - np.arange(1, h + 1)))
    return float(stats.chi2.sf(q, h))


def split_blocks(arrays, block_len: int) -> list[tuple[np.ndarray, ...]]:
    """Cut aligned arrays into consecutive blocks of ``block_len`` rows.

    Blocks of consecutive samples keep the serial correlation inside each block,
    which a sample-wise bootstrap would destroy.

    Parameters
    ----------
    arrays : ndarray or sequence of ndarray
        1-D or 2-D arrays with the same length along axis 0 (a single array is
        treated as a one-element sequence).
    block_len : int
        Rows per block, ``>= 1``.

    Returns
    -------
    list of tuple of ndarray
        One tuple per block, one entry per input array, in order. A last partial
        block is kept when it has at least ``block_len / 2`` rows, else dropped.

    Examples
    --------
    >>> blocks = split_blocks((np.arange(7), np.arange(7) * 10), 3)
    >>> [b[0].tolist() for b in blocks]
    [[0, 1, 2], [3, 4, 5]]
    >>> [b[0].tolist() for b in split_blocks([np.arange(8) * 10], 3)]
    [[0, 10, 20], [30, 40, 50], [60, 70]]
    """
    seq = [arrays] if isinstance(arrays, np.ndarray) else list(arrays)
    if not seq:
        raise ValueError("no arrays given")
    seq = [np.asarray(a) for a in seq]
    if any(a.ndim not in (1, 2) for a in seq):
        raise ValueError("arrays must be 1-D or 2-D")
    n = seq[0].shape[0]
    if any(a.shape[0] != n for a in seq):
        raise ValueError(f"arrays differ in length: {[a.shape[0] for a in seq]}")
    block_len = int(block_len)
    if block_len < 1:
        raise ValueError(f"block_len must be >= 1, got {block_len}")
    starts = list(range(0, n, block_len))
    if starts and n - starts[-1] < block_len / 2:
        starts.pop()  # too short a tail would give a block of different weight
    if not starts:
        raise ValueError(f"{n} rows make no block of {block_len} rows")
    return [tuple(a[s : s + block_len] for a in seq) for s in starts]


def _checked_draws(n_boot: int, level: float) -> int:
    """``n_boot`` as an int, with ``level`` and it checked (both bootstraps)."""
    if not 0.0 < level < 1.0:
        raise ValueError(f"level must be in (0, 1), got {level}")
    if int(n_boot) < 1:
        raise ValueError(f"n_boot must be >= 1, got {n_boot}")
    return int(n_boot)


def _scalar_or_array(v: np.ndarray) -> Any:
    """A float for a scalar statistic, the array for a vector one."""
    return float(v) if np.ndim(v) == 0 else v


def block_bootstrap(
    statistic: Callable[..., Any],
    blocks: Sequence[tuple[np.ndarray, ...]],
    n_boot: int = 1000,
    level: float = 0.95,
    rng: np.random.Generator | int | None = None,
) -> tuple[Any, Any, Any]:
    """Block-bootstrap percentile interval of a statistic of one or more series.

    Each draw resamples ``len(blocks)`` blocks with replacement, concatenates each
    tuple position across the drawn blocks (along axis 0) and evaluates
    ``statistic(*concatenated)``. A statistic of sums over the rows has a fast path,
    :func:`block_sum_bootstrap`.

    Parameters
    ----------
    statistic : callable
        ``statistic(a0, a1, ...) -> float`` (or array) for one array per tuple slot.
    blocks : sequence of tuple of ndarray
        E.g. from :func:`split_blocks`; a bare array per block is accepted too.
    n_boot : int, default 1000
        Bootstrap draws.
    level : float, default 0.95
        Coverage of the percentile interval.
    rng : numpy.random.Generator or int, optional
        Random source or seed; default seed 0 so reruns give the same interval.

    Returns
    -------
    estimate, lo, hi
        ``statistic`` on all blocks in order, and the ``(1 - level) / 2`` and
        ``(1 + level) / 2`` percentiles of the bootstrap draws. Floats for a scalar
        statistic, arrays (elementwise interval) for an array one.

    Examples
    --------
    >>> rng = np.random.default_rng(0)
    >>> blocks = split_blocks(rng.normal(1.0, 1.0, 1000), 20)
    >>> est, lo, hi = block_bootstrap(np.mean, blocks, n_boot=200)
    >>> bool(lo < 1.0 < hi), bool(lo > 0.0)
    (True, True)
    """
    tuples = [(b,) if isinstance(b, np.ndarray) else tuple(b) for b in blocks]
    if len(tuples) < 2:
        raise ValueError("need at least 2 blocks to bootstrap")
    width = len(tuples[0])
    if width == 0 or any(len(t) != width for t in tuples):
        raise ValueError("all blocks must hold the same, nonzero number of arrays")
    n_boot = _checked_draws(n_boot, level)
    gen = np.random.default_rng(0 if rng is None else rng)

    def _stat(idx) -> np.ndarray:
        cols = [np.concatenate([tuples[i][p] for i in idx], axis=0) for p in range(width)]
        return np.asarray(statistic(*cols), dtype=float)

    n_blocks = len(tuples)
    estimate = _stat(range(n_blocks))
    draws = gen.integers(0, n_blocks, size=(n_boot, n_blocks))
    boot = np.stack([_stat(idx) for idx in draws])
    lo, hi = np.quantile(boot, [(1.0 - level) / 2.0, (1.0 + level) / 2.0], axis=0)

    return _scalar_or_array(estimate), _scalar_or_array(lo), _scalar_or_array(hi)


#: the most block indices one chunk of :func:`block_sum_bootstrap`'s draws holds at once
#: (8 MiB; the chunks draw the same integers as one call would)
_DRAW_CHUNK = 1 << 20


def bootstrap_draws(level: float, tail_draws: int) -> int:
    """Bootstrap draws for a percentile interval at ``level`` whose ends rest on
    ``tail_draws`` draws beyond each of them: ``ceil(tail_draws / ((1 - level) / 2))``.

    A percentile interval's end is an extreme order statistic of the draws: with a
    Bonferroni-corrected level the lower quantile of a few hundred draws is about their
    smallest, so the end (and a decision on it) scatters with the bootstrap's seed. Its
    Monte-Carlo error shrinks as the draws beyond it grow (the count beyond a fixed
    quantile is binomial: a relative spread of about ``1 / sqrt(tail_draws)`` in the tail
    mass the end stands for).

    Parameters
    ----------
    level : float
        Coverage of the interval, in (0, 1).
    tail_draws : int
        Draws expected beyond each end, ``>= 1``.

    Returns
    -------
    int

    Examples
    --------
    >>> bootstrap_draws(0.95, 50)
    2000
    >>> bootstrap_draws(1 - 2 * 0.05 / 24, 50)
    24000
    """
    if not 0.0 < level < 1.0:
        raise ValueError(f"level must be in (0, 1), got {level}")
    if int(tail_draws) < 1:
        raise ValueError(f"tail_draws must be >= 1, got {tail_draws}")
    # rounded first: 1 - level carries rounding (0.05 / 0.025 = 2000.0000000000002)
    return int(np.ceil(round(int(tail_draws) / ((1.0 - level) / 2.0), 6)))


def block_sum_bootstrap(
    statistic: Callable[[np.ndarray], Any],
    block_sums: np.ndarray,
    n_boot: int,
    level: float = 0.95,
    rng: np.random.Generator | int | None = None,
) -> tuple[Any, Any, Any]:
    """Block-bootstrap percentile interval of a statistic of sums over the rows.

    The fast path of :func:`block_bootstrap` for a statistic that depends on the rows
    only through sums over them (a ratio of sums of squares): each draw resamples
    ``len(block_sums)`` blocks with replacement, as :func:`block_bootstrap` does, and
    adds up their per-block sums, so a draw costs ``n_blocks * k`` additions however
    long the blocks are, and tens of thousands of draws are cheap (:func:`bootstrap_draws`).

    Parameters
    ----------
    statistic : callable
        ``statistic(totals) -> ndarray``: for totals of shape ``(n, k)`` (one row per
        draw, one column per summed quantity), the statistic of each row, shape ``(n,)``
        or ``(n, j)``.
    block_sums : ndarray of shape (n_blocks, k)
        Each block's sums (e.g. of the rows of :func:`split_blocks`' blocks).
    n_boot : int
        Bootstrap draws.
    level : float, default 0.95
        Coverage of the percentile interval.
    rng : numpy.random.Generator or int, optional
        Random source or seed; default seed 0 so reruns give the same interval.

    Returns
    -------
    estimate, lo, hi
        ``statistic`` of the sums over all blocks, and the ``(1 - level) / 2`` and
        ``(1 + level) / 2`` percentiles of the draws. Floats for a scalar statistic,
        arrays (elementwise interval) for a vector one.

    Examples
    --------
    >>> rng = np.random.default_rng(0)
    >>> before = rng.normal(0.0, 1.0, 2000)
    >>> after = 0.5 * before + 0.1 * rng.normal(0.0, 1.0, 2000)
    >>> sums = np.array([[np.sum(b ** 2), np.sum(a ** 2)]
    ...                  for b, a in split_blocks((before, after), 50)])
    >>> est, lo, hi = block_sum_bootstrap(lambda t: 1 - t[:, 1] / t[:, 0], sums, 2000)
    >>> bool(lo < est < hi), bool(0.7 < lo < hi < 0.8)
    (True, True)
    """
    sums = np.asarray(block_sums, dtype=float)
    if sums.ndim != 2:
        raise ValueError(f"block_sums must be 2-D (n_blocks, k), got shape {sums.shape}")
    n_blocks = sums.shape[0]
    if n_blocks < 2:
        raise ValueError("need at least 2 blocks to bootstrap")
    n_boot = _checked_draws(n_boot, level)
    gen = np.random.default_rng(0 if rng is None else rng)
    estimate = np.asarray(statistic(sums.sum(axis=0)[None, :]), dtype=float)[0]
    chunk = max(1, _DRAW_CHUNK // n_blocks)
    boot = []
    for start in range(0, n_boot, chunk):
        draws = gen.integers(0, n_blocks, size=(min(chunk, n_boot - start), n_blocks))
        # one quantity at a time, each draw's sum along contiguous memory (15 times faster
        # than reducing a (draws, blocks, k) gather over its middle axis), and by numpy's
        # reduction, not a BLAS product of counts: the same on every BLAS kernel
        totals = np.stack([np.take(col, draws).sum(axis=1) for col in sums.T], axis=1)
        boot.append(np.asarray(statistic(totals), dtype=float))
    lo, hi = np.quantile(np.concatenate(boot), [(1.0 - level) / 2.0, (1.0 + level) / 2.0],
                         axis=0)

    return _scalar_or_array(estimate), _scalar_or_array(lo), _scalar_or_array(hi)


@dataclass
class NoiseModel:
    """Autoregressive model of measurement noise, per column, to prewhiten residuals.

    Filtered sensor noise is coloured (encoder quantisation through a second derivative
    is blue, motion-capture noise through the low-pass is red), so even the true model
    fails whiteness tests on raw residual rows. The correlation tests are run on
    innovations instead: ``e_w(t) = e(t) - sum_k a_k e(t-k)``, with ``a`` fitted (order by
    BIC, at most ``max_order``) on the training residual of the *final* model, whose
    residual is the best estimate of the noise. A model that still misses structure
    leaves it in the innovations, where the input tests find it.

    Examples
    --------
    >>> import numpy as np
    >>> rng = np.random.default_rng(0)
    >>> w = rng.normal(size=4000)
    >>> e = np.zeros(4000)
    >>> for t in range(1, 4000):
    ...     e[t] = -0.6 * e[t - 1] + w[t]
    >>> nm = NoiseModel().fit([e[:, None]])
    >>> round(float(nm.coefficients[0][0]), 1)
    -0.6
    >>> ljung_box_pvalue(nm.whiten(e[:, None])[:, 0]) > 0.01
    True
    """

    max_order: int = 10
    coefficients: list[np.ndarray] = field(default_factory=list)

    def fit(self, runs: Sequence[np.ndarray]) -> NoiseModel:
        """``runs``: residual rows (rows, n) of each training run (lags stay in a run)."""
        n = runs[0].shape[1]
        self.coefficients = []
        for i in range(n):
            best, best_bic = np.zeros(0), np.inf
            for p in range(self.max_order + 1):
                X, y = self._lagged([r[:, i] for r in runs], p)
                if len(y) <= p + 1:
                    break
                a = np.linalg.lstsq(X, y, rcond=None)[0] if p else np.zeros(0)
                rss = float(np.sum((y - (X @ a if p else 0.0)) ** 2))
                bic = len(y) * np.log(max(rss, 1e-300) / len(y)) + p * np.log(len(y))
                if bic < best_bic:
                    best, best_bic = a, bic
            self.coefficients.append(best)
        return self

    def _lagged(self, series: Sequence[np.ndarray], p: int) -> tuple[np.ndarray, np.ndarray]:
        # the same rows for every order, so BIC compares like with like
        xs, ys = [], []
        for s in series:
            m = self.max_order
            if len(s) <= m:
                continue
            ys.append(s[m:])
            xs.append(np.stack([s[m - k:len(s) - k] for k in range(1, p + 1)], axis=1)
                      if p else np.zeros((len(s) - m, 0)))
        if not ys:
            return np.zeros((0, p)), np.zeros(0)
        return np.concatenate(xs), np.concatenate(ys)

    def whiten(self, residual: np.ndarray) -> np.ndarray:
        """Innovations (rows, n) of one run's residual (the first rows use fewer lags)."""
        out = np.array(residual, dtype=float, copy=True)
        for i, a in enumerate(self.coefficients):
            for k, ak in enumerate(a, start=1):
                out[k:, i] -= ak * residual[:-k, i]
        return out
