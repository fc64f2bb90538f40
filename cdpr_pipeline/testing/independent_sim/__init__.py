"""An independent data generator for ``cdpr-measured/1``: a test oracle, evidence the
project's own simulator cannot give.

It deliberately shares no code with :mod:`cdpr_pipeline.sim` (nor with the rest of
``cdpr_pipeline``): its own physics formulation, integrator, controller, trajectories and
``cdpr-measured/1`` writer, with only numpy and yaml. A bug in the project's simulator or
reader therefore cannot hide itself by appearing on both sides of a test, and
``tests/test_layers.py`` fails on any import of the project from here. It ships in the
package (as ``numpy.testing`` does) so that the tests and the benchmarks import it as
installed code: ``from cdpr_pipeline.testing.independent_sim import random_rig``.

Kinds
-----
``cdpr``
    Suspended point-mass platform, 3 or 4 cables, rigid (or, with
    ``cable_elasticity``, elastic) cables, hard-sign Coulomb friction with true
    stick-slip; joint-space PD + feedforward controller. See :mod:`.cdpr`.
``axes``
    1 to 6 independent drive axes, inertia 1e-3..1e2, viscous up to 1e4, PD +
    feedforward position loops. See :mod:`.axes`.

Usage::

    from cdpr_pipeline.testing.independent_sim import random_rig, simulate_dataset
    rig = random_rig(seed=3, n_cables=4, rate_hz=250)
    truth = simulate_dataset("out/ds", rig, ["stribeck_friction"], n_runs=5,
                             duration_s=15, seed=3)
    truth.effects[0].to_dict()   # channels and magnitudes; also out/ds.truth.yaml

Hidden effects
--------------
Magnitudes are drawn per channel (winch / cable / axis), then stored in absolute SI
units; each effect hits one, some or all channels (equally likely; ``channels=`` picks
them). ``w_typ`` is the channel's typical speed: ``0.5 m/s / r`` for a winch,
``2 pi f_ref A`` for an axis. Ranges (per affected channel):

============================  =====  ==========================================================
effect                        kinds  magnitude drawn
============================  =====  ==========================================================
stribeck_friction             both   extra ``delta exp(-(w/w_s)^2) sign(w)``; ``delta = F_s - F_c``
                                     in 0.2..0.6 F_c (N m or N), ``w_s`` in 0.1..0.3 ``w_typ``
asymmetric_viscous_friction   both   extra ``c max(w, 0)`` (side +1) or ``c min(w, 0)`` (side -1),
                                     ``c`` in 0.3..0.8 F_v
winch_parameter_error         both   1 or 2 of I, F_v, F_c, d off by +-0.3..0.6 of nominal
                                     (d: of F_c, as a nominal d is often 0)
payload_mass_error            cdpr   platform mass off by +-0.1..0.3 m (kg); all cables
anchor_offset                 cdpr   true anchor moved by a random direction, 0.01..0.04 m
drum_radius_error             cdpr   true radius off by +-0.02..0.05 r (m)
cable_elasticity              cdpr   ``EA`` (N) giving a static stretch of 2..6 mm at the
                                     centre; cables not named stay 50x stiffer than the
                                     stiffest named one. Kelvin-Voigt loss time constant:
                                     each cable's own mode damped at 10 % (1.5-3.5 ms), or
                                     drawn in a range given (``damping_time_s=``)
actuator_lag                  both   first-order lag of the applied torque, time constant
                                     3..15 ms (cdpr), 2..10 ms (axes), at most 0.3 / w_c
quadratic_drag                both   extra ``c w |w|``, ``c`` in 0.3..0.8 F_v / w_typ
                                     (outside the pipeline's vocabulary)
periodic_torque               axes   extra ``A sin(k q + phi)`` on prismatic axes whose pitch
                                     rig.yaml does not state, ``A`` in 0.3..0.8 F_c,
                                     ``k = 2 pi / lambda``, ``lambda`` in 0.2..0.5 amplitude
                                     (outside the pipeline's vocabulary: no motor angle)
cogging                       both   extra ``A sin(N phi + phase)``, ``A`` in 0.3..0.8 F_c,
                                     ``phi`` the motor angle (absolute, 0 at the workspace
                                     centre; a rotary joint's q; ``2 pi q / pitch`` on a
                                     prismatic axis, ``random_axes_rig(pitch=True)``: pitch
                                     0.5..2 amplitude, written as ``pitch_m``); cdpr: ``N``
                                     in 1..4 per motor turn; axes: ``N`` whole periods per
                                     turn (per pitch) giving 1.5..3 periods over the swing,
                                     at least 2 on a rotary joint, at most 48
position_dependent_load       axes   rotary joint: ``a sin q + b cos q = A sin(q + phi)``, ``A``
                                     in 0.3..0.8 of the typical torque, ``|cos phi| >= 0.5``;
                                     prismatic axis: ``k (q - q0)``, ``k A`` in 0.3..0.8 of the
                                     typical force, ``q0`` within the stroke (``random_axes_rig``
                                     ``joint_types=``; rotary joints swing 0.2..1 rad)
============================  =====  ==========================================================

Sensors: mocap noise 1e-4 m (cdpr), torque measurement noise 0.5 % of the static
holding torque (cdpr) or of the typical torque (axes), encoder quantisation 2^16 counts
per turn (cdpr) or 1e-5 of the amplitude (axes); ``noise=False`` switches all off.
"""

from .axes import (
    AXES_FAMILIES,
    AxesPlant,
    AxesRigSpec,
    axes_reference,
    default_axes_families,
    random_axes_rig,
    simulate_axes_dataset,
    simulate_axes_runs,
)
from .cdpr import (
    CDPR_FAMILIES,
    RigSpec,
    SlackCableError,
    default_families,
    desired_trajectory,
    distribute_tensions,
    random_rig,
    simulate_dataset,
    simulate_runs,
    unit_vectors,
)
from .effects import EFFECT_KINDS, OUTSIDE_VOCABULARY, Effect, TrueModel, draw_effect, true_model
from .writer import RunTruth, Truth, truth_path

__all__ = [
    "AXES_FAMILIES",
    "CDPR_FAMILIES",
    "EFFECT_KINDS",
    "OUTSIDE_VOCABULARY",
    "AxesPlant",
    "AxesRigSpec",
    "Effect",
    "RigSpec",
    "RunTruth",
    "SlackCableError",
    "TrueModel",
    "Truth",
    "axes_reference",
    "default_axes_families",
    "default_families",
    "desired_trajectory",
    "distribute_tensions",
    "draw_effect",
    "random_axes_rig",
    "random_rig",
    "simulate_axes_dataset",
    "simulate_axes_runs",
    "simulate_dataset",
    "simulate_runs",
    "true_model",
    "truth_path",
    "unit_vectors",
]
