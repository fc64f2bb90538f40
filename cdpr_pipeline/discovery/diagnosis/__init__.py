"""``cdpr diagnose``: show what the simulation gets wrong, name the cause, extend the
model and measure the gain (``docs/diagnosis-format.md``, format ``cdpr-diagnosis/1``).

The diagnosis is a sequence of named steps (:data:`~cdpr_pipeline.discovery.diagnosis.
run.STEPS`, in the order docs/method.md section 3 draws them), one module each, each a
thin layer over the algorithm module it runs:

========================  ==============================================================
step                      module (algorithm)
========================  ==============================================================
``signals``               :mod:`.signals` (:mod:`cdpr_pipeline.discovery.signals`)
``candidates``            :mod:`.candidates` (:mod:`cdpr_pipeline.discovery.selection`)
``free-form``             :mod:`.freeform` (:mod:`cdpr_pipeline.discovery.freeform`)
``selection``             :mod:`.selection` (:mod:`cdpr_pipeline.discovery.selection`)
``never worse``           :mod:`.never_worse` (:mod:`cdpr_pipeline.discovery.never_worse`)
``validity``              :mod:`.validity` (:mod:`cdpr_pipeline.discovery.adequacy`)
``second look``           :mod:`.second_look` (:mod:`cdpr_pipeline.discovery.adequacy`)
``closed loop``           :mod:`.closed_loop` (:mod:`cdpr_pipeline.discovery.closed_loop`)
``black box``             :mod:`.blackbox` (a strategy passed in: no torch here)
``sizes``                 :mod:`.sizes` (:mod:`cdpr_pipeline.discovery.sizes`)
========================  ==============================================================

Beside them: :mod:`.settings` (what the diagnosis needs besides the data),
:mod:`.admission` (the split, and what is refused before any analysis), :mod:`.state`
(what the steps hand on), :mod:`.residual_tests` (what the validity step measures),
:mod:`.result` (:class:`Diagnosis` and its file layout) and :mod:`.run`
(:func:`diagnose`: the steps in order).
"""

from cdpr_pipeline.discovery.diagnosis.admission import (
    check_diagnosable,
    diagnosis_needs,
    diagnosis_split,
)
from cdpr_pipeline.discovery.diagnosis.blackbox import blackbox_share
from cdpr_pipeline.discovery.diagnosis.residual_tests import (
    discrepancies,
    fit_noise,
    model_metrics,
)
from cdpr_pipeline.discovery.diagnosis.result import FORMAT, Diagnosis
from cdpr_pipeline.discovery.diagnosis.run import STEPS, Step, diagnose
from cdpr_pipeline.discovery.diagnosis.settings import BlackBox, DiagnosisSettings
from cdpr_pipeline.discovery.summary import summary_sentence

__all__ = ["FORMAT", "STEPS", "BlackBox", "Diagnosis", "DiagnosisSettings", "Step",
           "blackbox_share", "check_diagnosable", "diagnose", "diagnosis_needs",
           "diagnosis_split", "discrepancies", "fit_noise", "model_metrics",
           "summary_sentence"]
