"""Running DVC's command line (``python -m dvc``, the one installed beside this
interpreter) and reading what it reports."""

from __future__ import annotations

import json
import subprocess
import sys
from collections.abc import Mapping
from pathlib import Path
from typing import Any

from cdpr_pipeline.pipeline.mlflow_logging import json_numbers


def run_dvc(*args: str, env: Mapping[str, str] | None = None,
            capture: bool = False) -> subprocess.CompletedProcess:
    """Run ``dvc ARGS`` (never raises on a non-zero exit).

    Parameters
    ----------
    *args : str
        DVC's arguments.
    env : Mapping, optional
        The environment (default: this process's).
    capture : bool
        Capture stdout and stderr instead of passing them through.

    Returns
    -------
    subprocess.CompletedProcess
        The finished process.
    """
    return subprocess.run([sys.executable, "-m", "dvc", *args], env=env, text=True,
                          capture_output=capture, check=False)


def up_to_date(env: Mapping[str, str] | None = None) -> bool:
    """Whether ``dvc status`` reports nothing to reproduce.

    Parameters
    ----------
    env : Mapping, optional
        The environment for DVC.

    Returns
    -------
    bool
        ``True`` only if DVC answered and reported no change.
    """
    status = run_dvc("status", "--json", env=env, capture=True)
    return status.returncode == 0 and status.stdout.strip() in ("{}", "")


def dvc_metrics(shown: Mapping[str, Any]) -> dict[str, float]:
    """``dvc metrics show --json`` (workspace) as flat MLflow metrics ``<file>/<key>``.

    Parameters
    ----------
    shown : Mapping
        DVC's parsed JSON.

    Returns
    -------
    dict
        ``<path without results/ and suffix>/<key>/... -> value``.
    """
    files = (shown.get("") or {}).get("data") or {}
    out: dict[str, float] = {}
    for path, content in files.items():
        stem = str(Path(path).with_suffix("")).replace("results/", "", 1)
        out |= json_numbers(content.get("data") or {}, f"{stem}/")
    return out


def workspace_metrics(env: Mapping[str, str] | None = None) -> dict[str, float]:
    """Every ``dvc metrics`` figure of the workspace (:func:`dvc_metrics`); empty if DVC
    reports none or fails.

    Parameters
    ----------
    env : Mapping, optional
        The environment for DVC.

    Returns
    -------
    dict
        Flat metrics.
    """
    shown = run_dvc("metrics", "show", "--json", env=env, capture=True)
    if shown.returncode == 0 and shown.stdout.strip():
        return dvc_metrics(json.loads(shown.stdout))
    return {}
