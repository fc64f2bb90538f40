"""The diagnosis's train / held-out split: whole runs by the spec's default, the last
block of the run when there is only one (with the blocks in diagnosis.json)."""

from __future__ import annotations

import json

import pytest

from cdpr_pipeline.data.io import Dataset
from cdpr_pipeline.discovery.diagnosis import diagnose, diagnosis_split
from cdpr_pipeline.stages.diagnose import write_outputs
from cdpr_pipeline.testing.lab_cases import fast_settings


def test_whole_runs_by_default_and_by_name(quiet_lab):
    names = quiet_lab.names
    spirals = [n for n in names if n.endswith("_spiral")]
    split = diagnosis_split(quiet_lab, fast_settings())
    train, held = list(split.train), list(split.heldout)
    assert held == spirals and train == [n for n in names if n not in spirals]
    assert not split.blocks
    assert split.as_dict() == {"train": train, "heldout": held}
    split = diagnosis_split(quiet_lab, fast_settings(heldout=[names[0]]))
    assert split.heldout == (names[0],) and len(split.train) == len(names) - 1
    with pytest.raises(ValueError, match="no run or family named"):
        diagnosis_split(quiet_lab, fast_settings(heldout=["nope"]))


@pytest.mark.parametrize("reading", ["fixed", "command"])
def test_a_single_run_is_diagnosed_on_its_last_block(quiet_lab, tmp_path, reading):
    """Also with the command's reading of the data (cut-off and decimation chosen from
    the data): its held-out block of an 8 s run has 20 statistics rows, and the whiteness
    test asked for 20 lags and raised."""
    from hydra.utils import instantiate

    from cdpr_pipeline.config import compose_config

    one = Dataset("one_run", quiet_lab.rig, quiet_lab.trajectories[:1])
    run = one[0]
    settings = fast_settings(closed_loop=True)
    if reading == "command":
        settings = fast_settings(closed_loop=True, regression=instantiate(
            compose_config("diagnose").regression))
    split = diagnosis_split(one, settings)
    (train,), (held,) = split["train"], split["heldout"]
    assert split.blocks and held.run == train.run == run.name
    # 25 % of 8 s is 2 s; the held-out block gets 3 s, or the fewest samples a block
    # needs for the regression's trims and rows if more, at the end of the run
    from cdpr_pipeline.data.reading import resolve_settings
    from cdpr_pipeline.identification.pipeline import min_block_samples

    rate = one.rig.sample_rate_hz
    fewest = min_block_samples(resolve_settings(settings.regression, [run], one.rig), rate)
    assert held.stop == run.n_samples and held.start == train.stop
    assert held.t_start == pytest.approx(run.t[-1] - max(3.0, fewest / rate), abs=0.01)

    d = diagnose(one, settings)
    assert d.train == tuple(split.train) and d.heldout == tuple(split.heldout)
    assert d.heldout[0].startswith(f"{run.name}@")
    # a block inside a run cannot be re-simulated from rest: skipped with the reason
    assert not d.closed_loop.available and "time blocks" in d.closed_loop.reason
    write_outputs(d, tmp_path, "one_run", split)
    record = json.loads((tmp_path / "diagnosis.json").read_text())
    assert record["split"]["heldout"] == list(d.heldout)
    (block,) = record["split"]["blocks"]["heldout"]
    assert block["run"] == run.name and block["stop"] == run.n_samples
