"""``cdpr validate data.path=DIR``: check a dataset, and say what each command can do
with it.

Besides the format's checks (``docs/data-format.md``), it asks each command that
analyses the recorded runs the very checks that command makes before its work, with the
command's own configuration (``conf/<command>.yaml``, plus the overrides in
``commands.<command>``): ``identify``
(:func:`~cdpr_pipeline.identification.pipeline.identification_inputs`), ``diagnose``
(:func:`~cdpr_pipeline.discovery.diagnosis.check_diagnosable`) and ``train``
(:func:`~cdpr_pipeline.data.split.window_split`); ``virtual`` and ``repro`` follow from
them, and ``simulate`` reads only ``rig.yaml``. So ``validate`` and a command never
disagree on whether the data can serve it.

It prints each run's length, the runs ``diagnose`` holds out, and per command whether it
can use the data, what it needs, and why not (file, column, row). It exits non-zero on
any format error, and when no command that analyses the runs can use them (their
reasons are then errors).
"""

from __future__ import annotations

import dataclasses
import logging
from collections.abc import Callable, Mapping

from hydra.utils import instantiate
from omegaconf import DictConfig

from cdpr_pipeline.command import hydra_command
from cdpr_pipeline.config import compose_config
from cdpr_pipeline.data.errors import DataValidationError, Problem
from cdpr_pipeline.data.io import Dataset, load_dataset
from cdpr_pipeline.data.reading import resolve_settings
from cdpr_pipeline.data.split import window_split
from cdpr_pipeline.data.validation import (
    TRAJ_DIR,
    CommandVerdict,
    RunLength,
    ValidationReport,
    validate_dataset,
)
from cdpr_pipeline.discovery.diagnosis import (
    check_diagnosable,
    diagnosis_needs,
    diagnosis_split,
)
from cdpr_pipeline.identification.pipeline import identification_inputs, identification_needs
from cdpr_pipeline.sim.plant import plant_kind
from cdpr_pipeline.stages.diagnose import settings_from_config

log = logging.getLogger(__name__)

#: the commands that analyse the recorded runs and make their own checks first
RUN_COMMANDS = ("identify", "diagnose", "train")


def validate(cfg: DictConfig) -> ValidationReport:
    """Validate ``cfg.data.path`` and judge it for every command; log the warnings and
    the summary (``report.errors`` has the errors)."""
    data_cfg = cfg.data
    report = validate_dataset(data_cfg.path, allow_gaps=bool(data_cfg.allow_gaps),
                              min_samples=int(data_cfg.min_samples))
    for problem in report.warnings:
        log.warning("%s", problem)
    if report.ok:
        try:   # what loading adds: runs cut at their gaps, each long enough
            data = load_dataset(data_cfg.path, allow_gaps=bool(data_cfg.allow_gaps),
                                min_samples=int(data_cfg.min_samples))
        except DataValidationError as exc:
            for problem in exc.problems:
                report.add(problem)
        else:
            judge_commands(data, {c: command_config(c, cfg) for c in RUN_COMMANDS}, report)
    if report.runs:
        log.info("%s", report.summary())
    if report.ok:
        log.info("%s: valid cdpr-measured/1 dataset (%d warnings)", data_cfg.path,
                 len(report.warnings))
    return report


def command_config(command: str, cfg: DictConfig) -> DictConfig:
    """``conf/<command>.yaml`` with validate's ``data`` keys and
    ``cfg.commands.<command>`` overrides: what ``cdpr <command>`` would run with."""
    data = cfg.data
    overrides = [f"data.path={data.path}", f"data.allow_gaps={bool(data.allow_gaps)}",
                 f"data.min_samples={int(data.min_samples)}"]
    extra = (cfg.get("commands") or {}).get(command) or []
    return compose_config(command, [*overrides, *(str(o) for o in extra)])


def judge_commands(data: Dataset, configs: Mapping[str, DictConfig],
                   report: ValidationReport) -> None:
    """Fill ``report`` with the runs' lengths, the runs diagnose holds out and each
    command's verdict; the refusals of the commands that read the runs are warnings
    while one of them can use the data, else errors."""
    rate = data.rig.sample_rate_hz
    report.runs = [RunLength(tr.name, tr.n_samples, tr.n_samples / rate) for tr in data]
    verdicts = {
        "identify": _identify(data, configs["identify"]),
        "diagnose": _diagnose(data, configs["diagnose"], report),
        "train": _train(data, configs["train"]),
    }
    verdicts["virtual"] = _virtual(data, verdicts["train"])
    verdicts["repro"] = _repro(verdicts)
    verdicts["simulate"] = _simulate(data)
    report.commands = verdicts
    anyone = any(v.usable for v in verdicts.values() if v.reads_runs)
    for v in verdicts.values():
        for p in v.problems:
            severity = "error" if v.reads_runs and not anyone else "warning"
            tagged = p.message if f"cdpr {v.command}" in p.message else \
                f"`cdpr {v.command}` cannot use the data: {p.message}"
            report.add(dataclasses.replace(p, message=tagged, severity=severity))
    if not anyone:
        log.error("no command can use the data: %s refuse it (see the errors)",
                  ", ".join(RUN_COMMANDS))


def _judged(command: str, needs: str, check: Callable[[], object]) -> CommandVerdict:
    """Run a command's own check; its DataValidationError is the verdict's reasons."""
    try:
        check()
    except DataValidationError as exc:
        return CommandVerdict(command, False, needs, list(exc.problems))
    return CommandVerdict(command, True, needs)


def needs_text(needs: Mapping[str, int], rate_hz: float, why: str) -> str:
    """Fewest samples per run in words: one figure per distinct minimum, with its runs."""
    by_need: dict[int, list[str]] = {}
    for name, n in needs.items():
        by_need.setdefault(int(n), []).append(name)
    parts = []
    for n, names in sorted(by_need.items(), reverse=True):
        who = "every run" if len(by_need) == 1 else ", ".join(names)
        parts.append(f"{who}: >= {n} samples ({n / rate_hz:.3g} s)")
    return "; ".join(parts) + f" ({why})"


def _identify(data: Dataset, cfg: DictConfig) -> CommandVerdict:
    log.info("how `cdpr identify` reads the runs:")
    settings = resolve_settings(instantiate(cfg.regression), data.trajectories, data.rig)
    needs, why = identification_needs(data, settings)
    holdout = list(cfg.holdout) if cfg.get("holdout") else None
    runs = list(cfg.runs) if cfg.get("runs") else None
    extra = [load_dataset(p, allow_gaps=cfg.data.allow_gaps, min_samples=cfg.data.min_samples)
             for p in (cfg.get("extra_data") or [])]
    return _judged("identify", needs_text(needs, data.rig.sample_rate_hz, why) +
                   "; motion both ways on every channel in the fitted runs",
                   lambda: identification_inputs(data, settings, holdout, runs, extra))


def _diagnose(data: Dataset, cfg: DictConfig, report: ValidationReport) -> CommandVerdict:
    settings = settings_from_config(cfg)
    log.info("how `cdpr diagnose` reads the runs:")
    settings = dataclasses.replace(settings, regression=resolve_settings(
        settings.regression, data.trajectories, data.rig))
    needs, why = diagnosis_needs(data, settings)
    try:
        report.heldout = list(diagnosis_split(data, settings).heldout)
    except ValueError as exc:   # a run too short for a block: the verdict says which
        log.debug("no diagnosis split: %s", exc)
    return _judged("diagnose", needs_text(needs, data.rig.sample_rate_hz, why),
                   lambda: check_diagnosable(data, settings))


def _train(data: Dataset, cfg: DictConfig) -> CommandVerdict:
    d = cfg.data
    window = int(d.window)
    need = window + 3
    rate = data.rig.sample_rate_hz
    needs = (f"training, validation and test parts (whole runs, else time blocks of each "
             f"run with gaps of {window} samples), each run or block >= {need} samples "
             f"({need / rate:.3g} s) for windows of {window} samples (data.window)")
    return _judged("train", needs, lambda: window_split(
        data.trajectories, window, val_fraction=float(d.val_fraction),
        test_fraction=float(d.test_fraction), test_families=list(d.test_families),
        seed=int(d.split_seed), gap=d.get("gap"), min_samples=int(d.min_samples),
        source=str(data.root)))


def _virtual(data: Dataset, train: CommandVerdict) -> CommandVerdict:
    desired = data.rig.signal("desired")
    needs = (f"a predictor trained by `cdpr train`, and the desired columns "
             f"{desired.describe()} in every run to drive it along")
    lacking = [tr.name for tr in data if tr.desired is None]
    problems = [Problem(f"{TRAJ_DIR}/{name}.csv", desired.names(data.rig.n)[0], 1,
                        f"no desired columns ({desired.describe()}): `cdpr virtual` has "
                        "nothing to drive a predictor along", "warning", "no_desired")
                for name in lacking[:1]]
    return CommandVerdict("virtual", train.usable and not problems, needs, problems)


def _repro(verdicts: Mapping[str, CommandVerdict]) -> CommandVerdict:
    refusing = [c for c in RUN_COMMANDS if not verdicts[c].usable]
    needs = ("what " + ", ".join(RUN_COMMANDS) + " need (its stages run them; the "
             "pipeline's profile may size them differently)"
             + (f": {', '.join(refusing)} cannot" if refusing else ""))
    return CommandVerdict("repro", not refusing, needs)


def _simulate(data: Dataset) -> CommandVerdict:
    needs = ("only rig.yaml (rig.file=DIR/rig.yaml); for drive axes a controller in the "
             "position_loop schema")
    controller = data.rig.controller
    why = None
    if not plant_kind(data.rig).cables:
        why = "rig.yaml has no controller" if controller is None else controller.why_not
    if why is None:
        return CommandVerdict("simulate", True, needs, reads_runs=False)
    return CommandVerdict("simulate", False, needs, [Problem(
        "rig.yaml", "controller", None, f"the virtual lab runs drive axes under a "
        f"position_loop controller: {why} (cdpr simulate model_file=M data.path=DIR still "
        "compares a model with the runs, n steps ahead)", "warning", "not_simulated")],
        reads_runs=False)


@hydra_command("validate", writes=False)
def main(cfg: DictConfig) -> None:
    # errors: DataValidationError, which the command prints (every problem, with file,
    # column and row) on stderr with a non-zero exit
    validate(cfg).raise_for_errors()
