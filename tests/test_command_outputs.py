"""Every command's ``out_dir`` is written whole, by one process at a time: a run killed
mid-write leaves the previous outputs as they were, and a second run on the same
``out_dir`` fails at once, naming the writer. Nothing else is written: no Hydra run
directory (``outputs/``) in the working directory, the log in ``out_dir``."""

from __future__ import annotations

import contextlib
import json
import os
import re
import signal
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import pytest

from cdpr_pipeline import cli
from cdpr_pipeline.config import compose_config
from cdpr_pipeline.errors import EXIT_USER_ERROR
from cdpr_pipeline.resources import foreign_rig_path

FOREIGN = foreign_rig_path()


@pytest.fixture(autouse=True)
def _cwd(monkeypatch, tmp_path):
    monkeypatch.delenv("CDPR_DEBUG", raising=False)
    monkeypatch.delenv("HYDRA_FULL_ERROR", raising=False)
    monkeypatch.chdir(tmp_path)


#: what a command's console had and must not have (Lightning's device notices, its advert)
_NOISE = ("GPU available", "TPU available", "Tip", "litlogger", "Traceback")


def _message(line: str) -> str:
    """A printed line without the handler's prefix (``[time][logger][LEVEL] - `` of the
    command's log, ``INFO: `` of Lightning's own console), as two handlers would print it."""
    return re.sub(r"^(\[[^]]*\]\[[^]]*\]\[[^]]*\] - |(INFO|WARNING): )", "", line)


@pytest.mark.slow
@pytest.mark.e2e
def test_a_default_diagnose_prints_each_message_once_and_logs_its_final_out_dir(
        tmp_path, new_mlflow_store):
    """The black box on (the default: Lightning trains it), one epoch to keep it short: no
    device notice or advert, no message twice, the log in out_dir, and the MLflow run named
    after the command and the dataset with the final out_dir (not ``.partial``)."""
    uri = new_mlflow_store(tmp_path / "store" / "mlflow.db")
    out = tmp_path / "diag"
    env = dict(os.environ, MLFLOW_TRACKING_URI=uri)
    for name in ("CDPR_DEBUG", "HYDRA_FULL_ERROR"):
        env.pop(name, None)
    done = subprocess.run(
        [sys.executable, "-m", "cdpr_pipeline.cli", "diagnose", f"data.path={FOREIGN}",
         f"out_dir={out}", "blackbox.epochs=1"], env=env, cwd=tmp_path, capture_output=True,
        text=True, timeout=600)
    assert done.returncode == 0, done.stderr
    printed = (done.stdout + done.stderr).splitlines()
    assert "black box: training" in done.stdout       # Lightning did run
    assert not [line for line in printed if any(word in line for word in _NOISE)], printed
    # two handlers print a message twice in a row; the same words may come back later
    # for a reason (the second look on a wider band logs its steps again, and two steps'
    # tables of candidates share rows)
    messages = [_message(line) for line in printed if line.strip()]
    assert [m for m, after in zip(messages, messages[1:], strict=False) if m == after] == []
    assert done.stderr == ""
    assert sorted(p.name for p in tmp_path.iterdir()) == ["diag", "store"]
    assert (out / "diagnose.log").read_text().splitlines() == done.stdout.splitlines()

    from mlflow.tracking import MlflowClient

    client = MlflowClient(uri)
    (run,) = client.search_runs([e.experiment_id for e in client.search_experiments()])
    assert run.info.run_name == f"diagnose:{FOREIGN.name}"
    assert run.data.params["out_dir"] == str(out)
    assert ".partial" not in " ".join(run.data.params.values())


def _previous(out: Path) -> None:
    out.mkdir(parents=True)
    (out / "bands.json").write_text("previous run")
    (out / "only_in_previous.txt").write_text("x")


def _left_beside(out: Path) -> list[str]:
    return sorted(p.name for p in out.parent.iterdir() if p.name != out.name)


def test_a_command_replaces_its_out_dir_whole_and_leaves_nothing_beside(tmp_path):
    out = tmp_path / "w" / "out"
    _previous(out)
    cli.main(["wavelet", f"data.path={FOREIGN}", f"out_dir={out}"])
    assert sorted(p.name for p in out.iterdir()) == ["bands.json", "wavelet.log", "wavelet.npz"]
    assert "wavelet" in json.loads((out / "bands.json").read_text())
    assert _left_beside(out) == []        # no .partial, .lock or .old
    assert sorted(p.name for p in tmp_path.iterdir()) == ["w"]     # no outputs/ from Hydra


def test_the_log_goes_into_out_dir_and_out_dir_is_required(tmp_path, capsys):
    out = tmp_path / "out"
    cli.main(["wavelet", f"data.path={FOREIGN}", f"out_dir={out}"])
    printed = [line for line in capsys.readouterr().out.splitlines() if line.startswith("[")]
    logged = (out / "wavelet.log").read_text().splitlines()
    assert logged == printed and f"wrote {out}" in logged[-1]    # still logging after the swap
    with pytest.raises(SystemExit) as exc:
        cli.main(["wavelet", f"data.path={FOREIGN}"])
    assert exc.value.code == EXIT_USER_ERROR
    assert "cdpr wavelet: error: required: out_dir (e.g. cdpr wavelet out_dir=...)" in \
        capsys.readouterr().err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out"]


#: per command, a cheap run that fails once it has started (a missing input), with and
#: without out_dir; ``params`` succeeds (it writes params.yaml, its output)
_FAILING = {
    "compare": ["data.path=missing"],
    "convert": ["src=missing"],
    "dataset": ["source=ingest", "path=missing"],
    "diagnose": ["data.path=missing"],
    "identify": ["data.path=missing"],
    "params": ["dataset.source=ingest", "dataset.path=missing"],
    "reconstruct": ["data.path=missing", "identification_json=missing.json"],
    "report": ["dataset=missing", "stages.dataset=missing"],
    "repro": ["dvc_args=[--no-such-flag]"],
    "simulate": ["model_file=missing.yaml"],
    "stage": [],
    "train": ["data.path=missing"],
    "validate": ["data.path=missing"],
    "virtual": ["data.path=missing", "forecaster=missing.pt"],
    "wavelet": ["data.path=missing"],
}


def test_every_command_has_a_cheap_run():
    assert set(_FAILING) == set(cli.SUBCOMMANDS)


@pytest.mark.parametrize("sub", sorted(cli.SUBCOMMANDS))
def test_no_command_leaves_hydra_outputs_in_the_working_directory(
        tmp_path, monkeypatch, new_mlflow_store, sub):
    """The issue's clutter: every command, failed ones included and even with out_dir,
    left outputs/<date>/<time>/ (Hydra's run directory) in the working directory."""
    monkeypatch.setenv("MLFLOW_TRACKING_URI", new_mlflow_store(tmp_path / "store" / "m.db"))
    args = [sub, *(["diagnose"] if sub == "stage" else []), *_FAILING[sub]]
    runs = [args]
    if sub in cli.CONFIG_NAMES and "out_dir" in compose_config(cli.CONFIG_NAMES[sub]):
        runs.append([*args, f"out_dir={tmp_path / 'out'}"])
    for run in runs:
        with contextlib.suppress(SystemExit):
            cli.main(run)
        left = sorted(p.name for p in tmp_path.iterdir())
        assert "outputs" not in left and ".hydra" not in left and not \
            [p for p in left if p.endswith(".log")], (run, left)


def test_a_real_run_without_out_dir_writes_nothing_into_the_working_directory(tmp_path):
    cli.main(["validate", f"data.path={FOREIGN}", "quiet=true"])
    assert list(tmp_path.iterdir()) == []


_KILLED_WRITER = textwrap.dedent("""
    import os, signal, sys
    from pathlib import Path
    from omegaconf import OmegaConf
    from cdpr_pipeline.command import run_staged

    def work(cfg):
        out = Path(cfg.out_dir)
        (out / "bands.json").write_text("new run, half written")
        os.kill(os.getpid(), signal.SIGKILL if sys.argv[2] == "kill" else signal.SIGCONT)
        (out / "wavelet.npz").write_text("new run, rest")

    run_staged(work, OmegaConf.create({"out_dir": sys.argv[1], "data": {"path": None}}))
""")


def test_a_run_killed_mid_write_leaves_the_previous_outputs(tmp_path):
    out = tmp_path / "r" / "out"
    _previous(out)
    proc = subprocess.run([sys.executable, "-c", _KILLED_WRITER, str(out), "kill"],
                          capture_output=True, text=True, timeout=120)
    assert proc.returncode == -signal.SIGKILL, proc.stderr
    assert sorted(p.name for p in out.iterdir()) == ["bands.json", "only_in_previous.txt"]
    assert (out / "bands.json").read_text() == "previous run"
    # the dead writer's lock is taken over, its partial work dropped: a whole new output
    proc = subprocess.run([sys.executable, "-c", _KILLED_WRITER, str(out), "live"],
                          capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0, proc.stderr
    assert sorted(p.name for p in out.iterdir()) == ["bands.json", "wavelet.npz"]
    assert _left_beside(out) == []


_LOCK_HOLDER = textwrap.dedent("""
    import sys, time
    from pathlib import Path
    from cdpr_pipeline.outputs import output_lock

    with output_lock(Path(sys.argv[1])):
        print("locked", flush=True)
        time.sleep(120)
""")


def test_a_second_run_on_the_same_out_dir_fails_at_once_naming_the_writer(tmp_path, capsys):
    out = tmp_path / "r" / "out"
    _previous(out)
    holder = subprocess.Popen([sys.executable, "-c", _LOCK_HOLDER, str(out)],
                              stdout=subprocess.PIPE, text=True)
    try:
        assert holder.stdout.readline().strip() == "locked"
        with pytest.raises(SystemExit) as exc:
            cli.main(["wavelet", f"data.path={FOREIGN}", f"out_dir={out}"])
        err = capsys.readouterr().err
    finally:
        holder.kill()
        holder.wait()
    assert exc.value.code == EXIT_USER_ERROR
    assert f"{out} is being written by pid {holder.pid}" in err and "Traceback" not in err
    assert (out / "bands.json").read_text() == "previous run"


def test_a_lock_left_by_a_dead_process_is_taken_over(tmp_path):
    out = tmp_path / "r" / "out"
    out.parent.mkdir()
    out.with_name("out.lock").write_text("pid 999999999\n")   # no process holds it
    cli.main(["wavelet", f"data.path={FOREIGN}", f"out_dir={out}"])
    assert (out / "bands.json").exists() and _left_beside(out) == []


def test_a_dataset_writer_refuses_to_overwrite_when_told_not_to(tmp_path, capsys):
    out = tmp_path / "emps"
    _previous(out)
    with pytest.raises(SystemExit) as exc:
        cli.main(["convert", "format=emps", "src=/nonexistent", f"out_dir={out}",
                  "overwrite=false"])
    assert exc.value.code == EXIT_USER_ERROR
    assert "exists; overwrite=true replaces it" in capsys.readouterr().err
    assert (out / "bands.json").read_text() == "previous run"


@pytest.mark.slow
@pytest.mark.e2e
def test_diagnose_killed_after_writing_diagnosis_json_leaves_the_previous_outputs(tmp_path):
    """The issue's case: killed once diagnosis.json was written, the folder mixed two
    datasets' results. Now the new results are only in the partial directory."""
    out = tmp_path / "diag"
    _previous(out)
    env = dict(os.environ, MLFLOW_TRACKING_URI=f"sqlite:///{tmp_path / 'mlflow.db'}")
    proc = subprocess.Popen(
        [sys.executable, "-m", "cdpr_pipeline.cli", "diagnose", f"data.path={FOREIGN}",
         "blackbox.enabled=false", f"out_dir={out}"], env=env, cwd=tmp_path,
        stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    written = out.with_name("diag.partial") / "diagnosis.json"
    for _ in range(6000):     # polls; the diagnosis itself ends the wait
        if written.exists() or proc.poll() is not None:
            break
        time.sleep(0.05)
    proc.send_signal(signal.SIGKILL)
    proc.wait()
    assert written.exists(), "the diagnosis finished before it could be killed"
    assert sorted(p.name for p in out.iterdir()) == ["bands.json", "only_in_previous.txt"]


@pytest.mark.slow
@pytest.mark.e2e
def test_ctrl_c_during_diagnose_exits_130_in_one_line_with_the_outputs_as_they_were(
        tmp_path, default_sigint):
    out = tmp_path / "diag"
    _previous(out)
    env = dict(os.environ, MLFLOW_TRACKING_URI=f"sqlite:///{tmp_path / 'mlflow.db'}")
    env.pop("CDPR_DEBUG", None)
    env.pop("HYDRA_FULL_ERROR", None)
    proc = subprocess.Popen(
        [sys.executable, "-m", "cdpr_pipeline.cli", "diagnose", f"data.path={FOREIGN}",
         "blackbox.enabled=false", f"out_dir={out}"], env=env, cwd=tmp_path,
        stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
    partial = out.with_name("diag.partial")
    for _ in range(6000):     # polls; the diagnosis itself ends the wait
        if partial.exists() or proc.poll() is not None:
            break
        time.sleep(0.05)
    proc.send_signal(signal.SIGINT)
    _, err = proc.communicate(timeout=300)
    assert proc.returncode == 130, err
    assert err.strip().splitlines() == ["cdpr diagnose: interrupted (outputs left as they were)"]
    assert sorted(p.name for p in out.iterdir()) == ["bands.json", "only_in_previous.txt"]


def test_simulate_replaces_the_dataset_and_its_truth_beside_it(tmp_path):
    import yaml

    out = tmp_path / "r" / "lab"
    for seed in (3, 4):
        cli.main(["simulate", "trajectory=tiny", "trajectory.duration_s=0.5", "quiet=true",
                  f"seed={seed}", f"out_dir={out}"])
        truth = yaml.safe_load(out.with_name("lab.truth.yaml").read_text())
        assert truth["seed"] == seed and truth["dataset"] == "lab"
    assert sorted(p.name for p in out.parent.iterdir()) == ["lab", "lab.truth.yaml"]
    assert sorted(p.name for p in out.iterdir()) == ["rig.yaml", "trajectories"]


@pytest.mark.parametrize("out_dir", [".", "..", "/"])
def test_an_out_dir_holding_the_working_directory_is_refused(tmp_path, capsys, out_dir):
    (tmp_path / "keep.txt").write_text("mine")
    with pytest.raises(SystemExit) as exc:
        cli.main(["wavelet", f"data.path={FOREIGN}", f"out_dir={out_dir}"])
    assert exc.value.code == EXIT_USER_ERROR
    assert "is the working directory or holds it" in capsys.readouterr().err
    assert (tmp_path / "keep.txt").read_text() == "mine"
