"""Start-up: torch, Lightning and MLflow are imported only by what uses them (each costs
seconds), so `cdpr diagnose`, `simulate`, `validate` and `identify` reach their work
without them."""

from __future__ import annotations

import subprocess
import sys

import pytest

HEAVY = ("torch", "lightning", "mlflow")


@pytest.mark.parametrize("stage", ["diagnose", "simulate", "validate", "identify", "report"])
def test_stage_import_leaves_heavy_dependencies_out(stage):
    code = (f"import sys, cdpr_pipeline.cli, cdpr_pipeline.stages.{stage}\n"
            f"print(sorted(m for m in {HEAVY!r} if m in sys.modules))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         check=True).stdout.strip()
    assert out == "[]"


def test_diagnose_settings_build_the_black_box_net_only_when_it_trains():
    code = ("import sys\n"
            "from cdpr_pipeline.config import compose_config\n"
            "from cdpr_pipeline.stages.diagnose import settings_from_config\n"
            "s = settings_from_config(compose_config('diagnose', []))\n"
            "assert s.blackbox is not None and 'torch' not in sys.modules\n"
            "from cdpr_pipeline.models.features import FeatureLayout\n"
            "net = s.blackbox.net_factory(layout=FeatureLayout(('x',), 0, 1, False, 100.0))\n"
            "print(type(net).__name__, 'torch' in sys.modules)")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         check=True).stdout.strip()
    assert out == "TCNTransformer True"
