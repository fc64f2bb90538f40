"""``cdpr stage NAME``'s work: run one section of ``params.yaml`` as a pipeline stage.

- Outputs are written to ``<out_dir>.partial`` and swapped in only when the stage ends,
  so a failure or an interruption never leaves half an output; an interrupted stage
  resumes from its partial directory (Lightning's ``last.ckpt``) when rerun with the same
  params and inputs; a lock refuses a second run on the same output directory.
- The stage is one MLflow run, nested under the pipeline's parent run.
- A failure names the declared input it came from (:class:`StageFailed`).
- A stage that cannot apply (it raises
  :class:`~cdpr_pipeline.pipeline.skip.StageNotApplicable`, or an input it needs was
  skipped) is skipped: its declared outputs become skip markers, its run is tagged
  ``cdpr_skipped``, and one log line says why.
"""

from __future__ import annotations

import hashlib
import json
import logging
from pathlib import Path
from typing import Any

from hydra.utils import get_method
from omegaconf import OmegaConf

from cdpr_pipeline.outputs import empty_dir, inputs_state, rebase_paths, staged_output
from cdpr_pipeline.pipeline.inputs import (
    SkippedInputs,
    blame,
    check_skipped_inputs,
    input_paths,
)
from cdpr_pipeline.pipeline.mlflow_logging import log_skipped, log_stage_outputs
from cdpr_pipeline.pipeline.params import PARAMS_FILE, read_section
from cdpr_pipeline.pipeline.skip import Skipped, StageNotApplicable, write_skip_markers
from cdpr_pipeline.tracking import flatten_params, stage_run

log = logging.getLogger(__name__)


class StageFailed(RuntimeError):
    """A pipeline stage raised; the message names the stage and the input at fault."""


def run_stage(key: str, params_file: str | Path = PARAMS_FILE) -> Any:
    """Run the ``params.yaml`` section ``key`` (see the module docstring).

    Parameters
    ----------
    key : str
        ``NAME`` or ``NAME.ITEM``.
    params_file : str or Path
        The params file. A section's ``inputs``, ``outputs`` and ``on_skipped_input``
        default to none, none and ``skip``.

    Returns
    -------
    Any
        What the stage function returns, or :class:`~cdpr_pipeline.pipeline.skip.Skipped`
        if the stage was skipped.

    Raises
    ------
    StageFailed
        If the stage function raised; the message names the input at fault.
    KeyError
        If the params file has no such stage, or the stage declares an input its config
        lacks.
    """
    section = read_section(key, params_file)
    config = section["config"]
    out_dir = Path(config["out_dir"])
    func = get_method(section["function"])
    declared = list(section.get("inputs") or [])
    try:
        inputs = input_paths(config, declared)
    except KeyError as err:
        raise KeyError(f"{params_file}: stage {key} declares input {err} that its config "
                       "lacks") from None
    # a partial output is resumed only with the same params and the same inputs
    digest = hashlib.sha256(json.dumps([section, inputs_state(inputs)], sort_keys=True)
                            .encode()).hexdigest()[:16]
    tracking = config.get("tracking") or {}
    experiment = tracking.get("experiment") or "cdpr-pipeline"
    # the lock, the partial directory and the swap when the block ends (cdpr_pipeline.outputs)
    with staged_output(out_dir, digest) as partial:
        checked = (check_skipped_inputs(config, declared)
                   if section.get("on_skipped_input", "skip") == "skip"
                   else SkippedInputs(config))
        for entry in checked.left_out:
            log.info("stage %s: leaving out input %s (skipped)", key, entry)
        reason = checked.reason
        cfg = OmegaConf.create(rebase_paths(checked.config, str(out_dir), str(partial)))
        with stage_run(key, experiment, tracking.get("uri"),
                       tags={"cdpr_stage_function": section["function"],
                             "params_digest": digest}) as (runs, run_id):
            result = None
            if reason is None:
                try:
                    result = func(cfg)
                except StageNotApplicable as err:
                    reason = " ".join(str(err).split()) or type(err).__name__
                except Exception as err:
                    raise StageFailed(f"stage {key} failed: {type(err).__name__}: {err}\n"
                                      f"  {blame(err, inputs)}; the inputs are untouched and "
                                      f"{out_dir} was not replaced (its work so far is in "
                                      f"{partial})") from err
            runs.log_run(run_id, params=flatten_params(config))
            if reason is None:
                log_stage_outputs(runs, run_id, partial)
            else:
                # what the stage wrote before it found it cannot apply is no output
                empty_dir(partial)
                write_skip_markers(partial, list(section.get("outputs") or []), reason, key)
                log_skipped(runs, run_id, reason, partial)
    if reason is not None:
        log.info("stage %s skipped: %s", key, reason)
        return Skipped(reason)
    log.info("stage %s: wrote %s", key, out_dir)
    return result
