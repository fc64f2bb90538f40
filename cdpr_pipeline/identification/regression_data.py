"""The rows of a per-winch (per-axis) regression (:class:`WinchRegression`): stacked,
split, fitted and rebuilt with NumPy alone.

:mod:`~cdpr_pipeline.identification.regressors` builds them from the data (filters,
geometry: SciPy and the data package); a process that only receives rows and fits them (the
diagnosis's black box, :mod:`cdpr_pipeline.models.blackbox`) imports this module and pays
for neither (about 130 MB of SciPy and pandas).
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass

import numpy as np

#: regressor columns, in ``WinchParams`` order (inertia, viscous, coulomb, offset)
COLUMNS = ("a", "b", "c", "1")


@dataclass
class WinchRegression:
    """Stacked regression data of one or more runs.

    ``phi`` is ``(N, n, 4)`` (columns ``a, b, c, 1`` per winch), ``target`` ``(N, n)``;
    ``run`` ``(N,)`` says which run each row came from (for held-out splits and block
    bootstraps). ``internal`` ``(N, n, n - 3)``, on a cable robot with more than three
    cables: the winch-torque directions ``R N`` of internal cable forces at each row
    (``N`` the null space of ``K^T``), which the motion cannot tell: the target holds
    ``U* + R N lambda`` with ``lambda`` unknown per row
    (:meth:`without_internal_forces`). Each winch's entry is scaled by its row's kept
    share (the offset column), as its target is.
    """

    phi: np.ndarray
    target: np.ndarray
    run: np.ndarray | None = None
    internal: np.ndarray | None = None
    #: (n, 4), after :meth:`without_internal_forces`: the joint fit's standard deviations
    #: over what each winch's own least squares on the cleaned target reports (which
    #: does not count the internal force fitted per row; 1.1-3x on 4-cable rigs)
    std_scale: np.ndarray | None = None

    @property
    def n(self) -> int:
        return int(self.target.shape[1])

    def __len__(self) -> int:
        return int(self.target.shape[0])

    def least_squares(self) -> np.ndarray:
        """Ordinary least squares per winch; returns ``(n, 4)`` parameters in
        ``WinchParams`` order (``WINCH_KEYS``: inertia, viscous, coulomb, offset)."""
        return np.stack([np.linalg.lstsq(self.phi[:, i], self.target[:, i], rcond=None)[0]
                         for i in range(self.n)])

    def predict(self, params: np.ndarray) -> np.ndarray:
        """``U*`` rebuilt from ``(n, 4)`` parameters."""
        return np.einsum("tnk,nk->tn", self.phi, np.asarray(params, float))

    def rows(self, mask: np.ndarray) -> WinchRegression:
        return WinchRegression(self.phi[mask], self.target[mask],
                               None if self.run is None else self.run[mask],
                               None if self.internal is None else self.internal[mask])

    def without_internal_forces(self, params: np.ndarray | None = None) -> WinchRegression:
        """The regression with the internal cable forces taken out of the target.

        How much internal force a redundant rig holds is its controller's choice (a
        pretension, a lower tension bound), which rig.yaml does not state, so the
        least-norm tensions leave ``R N lambda`` in every winch's target: a smooth,
        motion-locked torque no winch parameter causes, which biased the per-winch fits
        (independent-simulator 4-cable rigs: inertia up to 22 % off). Like the diagnosis
        (:func:`~cdpr_pipeline.discovery.signals.internal_force_projection`), ``lambda``
        is a nuisance fitted per row: the winch parameters of every winch jointly by
        least squares on the projected equations ``P (U* - Phi theta) = 0``, ``P`` the
        projector off ``R N``; then ``lambda`` from their residual, and the target
        without ``R N lambda``. Every winch's own least squares on that target gives
        the joint solution back (its normal equations are the joint ones), so any
        identifier fits it per winch. ``params`` (n, 4): take ``lambda`` given these
        (held-out rows) instead of fitting them. Without :attr:`internal`: unchanged.
        """
        if self.internal is None:
            return self
        b, phi, y = self.internal, self.phi, self.target
        n = self.n
        proj = np.eye(n) - np.einsum("kia,kab,kjb->kij", b,
                                     np.linalg.pinv(np.einsum("kia,kib->kab", b, b)), b)
        std_scale = design = scale = None
        if params is None:
            design = np.einsum("kij,kjc->kijc", proj, phi).reshape(len(y) * n, n * 4)
            scale = np.linalg.norm(design, axis=0)
            scale = np.where(scale > 0, scale, 1.0)
            design = design / scale
            params = (np.linalg.lstsq(design, np.einsum("kij,kj->ki", proj, y).ravel(),
                                      rcond=None)[0] / scale).reshape(n, 4)
        resid = y - self.predict(params)
        projected = np.einsum("kij,kj->ki", proj, resid)
        if design is not None:
            std_scale = self._joint_std_scale(design, scale, projected)
        # the target less R N lambda: what each winch's own fit then leaves is `projected`
        return WinchRegression(phi, y - (resid - projected), self.run, None, std_scale)

    def _joint_std_scale(self, design: np.ndarray, scale: np.ndarray,
                         projected: np.ndarray) -> np.ndarray:
        """:attr:`std_scale`: the joint least squares' white-residual standard deviations
        (each row keeps ``n - r`` equations) over each winch's own on the cleaned
        target (whose residual is ``projected``)."""
        n, rows = self.n, len(self)
        dof = max(rows * (n - self.internal.shape[2]) - 4 * n, 1)
        s2 = float(np.sum(projected ** 2)) / dof
        joint = np.sqrt(np.clip(np.diag(np.linalg.pinv(design.T @ design)), 0, None)
                        * s2).reshape(n, 4) / scale.reshape(n, 4)
        own = np.empty((n, 4))
        for i in range(n):
            x = self.phi[:, i]
            s2_i = float(projected[:, i] @ projected[:, i]) / max(rows - 4, 1)
            own[i] = np.sqrt(np.clip(np.diag(np.linalg.pinv(x.T @ x)), 0, None) * s2_i)
        return np.where(own > 0, joint / np.where(own > 0, own, 1.0), 1.0)

    @staticmethod
    def concatenate(parts: Iterable[WinchRegression]) -> WinchRegression:
        parts = list(parts)
        runs, offset = [], 0
        for p in parts:    # run indices stay distinct across parts
            r = np.zeros(len(p), int) if p.run is None else np.asarray(p.run, int)
            runs.append(r + offset)
            offset += int(r.max()) + 1 if len(r) else 0
        internal = [p.internal for p in parts]
        if any(i is None for i in internal):
            if any(i is not None for i in internal):
                raise ValueError("regressions with and without internal-force directions "
                                 "cannot be stacked (take them out of each first)")
            internal = None
        else:
            internal = np.concatenate(internal)
        return WinchRegression(np.concatenate([p.phi for p in parts]),
                               np.concatenate([p.target for p in parts]), np.concatenate(runs),
                               internal)
