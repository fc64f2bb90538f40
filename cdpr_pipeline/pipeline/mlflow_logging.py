"""What the pipeline logs to MLflow beyond what a stage logs itself: a stage's small output
files and their numbers, the skip tag of a skipped stage, and JSON figures as flat
metrics (also for the parent run's ``dvc metrics``)."""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Any

from cdpr_pipeline.pipeline.skip import SKIP_MARKER

#: output files the runner logs to MLflow for a stage that logged none itself
ARTIFACT_SUFFIXES = (".json", ".yaml", ".csv", ".md", ".png", ".html")
MAX_ARTIFACT_BYTES = 5_000_000
#: the tag a skipped stage's run carries, its value the reason
SKIPPED_TAG = "cdpr_skipped"
#: MLflow's limit on a tag value (the smallest across its stores)
MAX_TAG_CHARS = 5000


def json_numbers(tree: Any, prefix: str) -> dict[str, float]:
    """The finite numbers of a JSON tree as flat metrics ``<prefix><key>/<key>...``.

    Parameters
    ----------
    tree : Any
        Parsed JSON.
    prefix : str
        Prepended to every key (ends with ``/``).

    Returns
    -------
    dict
        ``key -> value``; booleans, strings and non-finite numbers are left out.
    """
    if isinstance(tree, dict):
        return {k: v for key, sub in tree.items()
                for k, v in json_numbers(sub, f"{prefix}{key}/").items()}
    if isinstance(tree, list):
        return {k: v for i, sub in enumerate(tree)
                for k, v in json_numbers(sub, f"{prefix}{i}/").items()}
    if isinstance(tree, (int, float)) and not isinstance(tree, bool) and math.isfinite(tree):
        return {prefix.rstrip("/"): float(tree)}
    return {}


def log_stage_outputs(runs, run_id: str, out_dir: Path) -> None:
    """Log a stage's small top-level output files and their numbers, unless the stage
    logged its own (then the stage chose what matters).

    Parameters
    ----------
    runs : LocalRuns or RemoteRuns
        What the stage run is written through (:func:`~cdpr_pipeline.tracking.open_runs`).
    run_id : str
        The stage run.
    out_dir : Path
        Where the stage wrote.
    """
    if runs.has_logged(run_id):
        return
    files = [p for p in sorted(out_dir.iterdir()) if p.is_file()
             and p.suffix in ARTIFACT_SUFFIXES and p.stat().st_size <= MAX_ARTIFACT_BYTES]
    metrics: dict[str, float] = {}
    for p in files:
        runs.log_artifact(run_id, str(p))
        if p.suffix == ".json":
            metrics |= json_numbers(json.loads(p.read_text()), p.stem + "/")
    runs.log_run(run_id, metrics=metrics)


def log_skipped(runs, run_id: str, reason: str, out_dir: Path) -> None:
    """Mark a stage run as skipped: the tag ``cdpr_skipped=<reason>`` and the marker.

    Parameters
    ----------
    runs : LocalRuns or RemoteRuns
        What the stage run is written through (:func:`~cdpr_pipeline.tracking.open_runs`).
    run_id : str
        The stage run.
    reason : str
        Why the stage was skipped.
    out_dir : Path
        Where the runner wrote the skip markers (its ``SKIPPED.json`` is logged; the other
        markers stand in for outputs and say nothing more).
    """
    runs.set_tag(run_id, SKIPPED_TAG, reason[:MAX_TAG_CHARS])
    runs.log_artifact(run_id, str(out_dir / SKIP_MARKER))
