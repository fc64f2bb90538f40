"""The ``cdpr`` command as a user meets it: errors as messages, settings checked (one
line, exit 2, for every command), Ctrl-C, ``--help``.

Called in-process (``cdpr_pipeline.cli.main``), several times in one process, as the
bad-input suite does."""

from __future__ import annotations

import shutil

import pytest
import yaml
from omegaconf import OmegaConf

import cdpr_pipeline
from cdpr_pipeline import cli
from cdpr_pipeline.config import compose_config
from cdpr_pipeline.errors import EXIT_INTERRUPTED, EXIT_USER_ERROR, ConfigError, UserError
from cdpr_pipeline.resources import foreign_rig_path


def _run(capsys, *args: str) -> tuple[int | str | None, str, str]:
    with pytest.raises(SystemExit) as exc:
        cli.main(list(args))
    out, err = capsys.readouterr()
    return exc.value.code, out, err


@pytest.fixture(autouse=True)
def _no_debug(monkeypatch, tmp_path):
    monkeypatch.delenv("CDPR_DEBUG", raising=False)
    monkeypatch.delenv("HYDRA_FULL_ERROR", raising=False)
    monkeypatch.chdir(tmp_path)        # nothing may be written there


def test_missing_data_path_is_named_without_a_traceback_every_time(capsys, tmp_path):
    for sub in ("diagnose", "identify", "validate", "diagnose"):
        code, _, err = _run(capsys, sub)
        assert code == EXIT_USER_ERROR
        assert f"cdpr {sub}: error: required: data.path" in err
        assert "Traceback" not in err
    # nothing read from, or written as, a dataset in the working directory
    assert not (tmp_path / "data").exists()


def test_a_data_error_prints_file_column_and_row(capsys, tmp_path):
    data = tmp_path / "rig"
    shutil.copytree(foreign_rig_path(), data)
    csv = data / "trajectories" / "001_spiral.csv"
    lines = csv.read_text().splitlines()
    header = lines[0].split(",")
    row = lines[4].split(",")
    row[header.index("u1")] = "oops"
    lines[4] = ",".join(row)
    csv.write_text("\n".join(lines) + "\n")
    for sub in ("validate", "identify", "diagnose"):
        extra = [] if sub == "validate" else [f"out_dir={tmp_path / sub}"]
        code, _, err = _run(capsys, sub, f"data.path={data}", *extra)
        assert code == EXIT_USER_ERROR, err
        assert "001_spiral.csv, column 'u1', row 5: non-numeric value 'oops'" in err
        assert "Traceback" not in err
        assert not [p for p in tmp_path.iterdir() if p.name.startswith(sub)]   # nothing


def test_a_bad_override_exits_2_without_a_traceback(capsys):
    code, _, err = _run(capsys, "diagnose", "no_such_key=1")
    assert code == EXIT_USER_ERROR
    assert "no_such_key" in err and "Traceback" not in err


def _leaves(tree, prefix=""):
    """``(dotted key, value)`` of every scalar of a config outside the mappings that build
    an object (``_target_``: ``+key`` may add an argument there)."""
    for key, value in tree.items():
        name = f"{prefix}{key}"
        if isinstance(value, dict) and "_target_" not in value:
            yield from _leaves(value, f"{name}.")
        elif not isinstance(value, dict):
            yield name, value


def _settings(sub: str) -> dict:
    """The composed config of ``cdpr <sub>`` (``stage`` has none: it runs params.yaml)."""
    if sub not in cli.CONFIG_NAMES:
        return {}
    return OmegaConf.to_container(compose_config(cli.CONFIG_NAMES[sub]), resolve=False)


def _refused(capsys, tmp_path, sub: str, *args: str) -> str:
    """Run ``cdpr <sub> args``; assert one line on stderr, exit 2, nothing written; the
    line."""
    code, out, err = _run(capsys, sub, *args)
    assert code == EXIT_USER_ERROR, (out, err)
    assert err.count("\n") == 1 and err.startswith(f"cdpr {sub}: error: "), err
    assert "Traceback" not in err and "HYDRA_FULL_ERROR" not in err and "+" not in \
        err.replace(args[0], "")                  # no advice to add the key with +
    assert out == "" and list(tmp_path.iterdir()) == []
    return err.strip()


@pytest.mark.parametrize("sub", sorted(cli.SUBCOMMANDS))
def test_a_misspelt_setting_is_one_line_naming_the_closest(capsys, tmp_path, sub):
    """The issue's typo, for every command: a real key of the command with a letter
    dropped (``blackbox.enabld``), and the same with ``+``, which adds nothing."""
    leaves = [k for k, _ in _leaves(_settings(sub)) if len(k.rpartition(".")[2]) > 3]
    key = leaves[0] if leaves else "blackbox.enabled"
    typo = key[:-2] + key[-1]
    for arg in (f"{typo}=1", f"+{typo}=1"):
        err = _refused(capsys, tmp_path, sub, arg)
        assert f"unknown setting {typo} " in err
        if leaves:
            assert err.endswith(f"(did you mean {key}?)"), err


@pytest.mark.parametrize("sub", sorted(cli.CONFIG_NAMES))
def test_booleans_and_numbers_are_read_strictly(capsys, tmp_path, sub):
    """``flase`` for a boolean, ``1O`` for an integer, ``fast`` for a float: refused with
    the key named, for every command that has such a setting."""
    by_type = {}
    for key, value in _leaves(_settings(sub)):
        by_type.setdefault(type(value), key)
    bad = {bool: "flase", int: "1O", float: "fast"}
    cases = [(by_type[kind], text) for kind, text in bad.items() if kind in by_type]
    assert cases or sub in ("convert", "report"), f"cdpr {sub} has no boolean or number"
    for key, text in cases:
        err = _refused(capsys, tmp_path, sub, f"{key}={text}")
        assert err.startswith(f"cdpr {sub}: error: {key}={text}: expected "), err


@pytest.mark.parametrize("args, message", [
    (["diagnose", "blackbox.enabled=flase"],
     "blackbox.enabled=flase: expected true or false"),
    (["diagnose", "blackbox.enabld=false"],
     "unknown setting blackbox.enabld (did you mean blackbox.enabled?)"),
    (["diagnose", "+blackbox.enabld=false"],
     "unknown setting blackbox.enabld (did you mean blackbox.enabled?)"),
    (["diagnose", "+blackbox.enabled=false"],
     "blackbox.enabled is a setting already: blackbox.enabled=VALUE sets it (without +)"),
    (["diagnose", "blackbox.model=tcn"], "blackbox.model holds settings"),
    # +key into an object: only an argument its constructor takes
    (["diagnose", "+discovery.unexplained_noise_rato=5"],
     "unknown setting discovery.unexplained_noise_rato (did you mean "
     "discovery.unexplained_noise_ratio?)"),
    (["train", "+optimizer.weight_decy=1e-4"],
     "unknown setting optimizer.weight_decy (did you mean optimizer.weight_decay?)"),
    (["train", "model=tcnx"], "unknown option model=tcnx (choices: arx, "),
    (["train", "trainer.max_epochs=2.5"], "trainer.max_epochs=2.5: expected an integer"),
    (["train", "trainer.deterministic=flase"],
     "trainer.deterministic=flase: expected true or false"),
    (["identify", "seed=0,1"], "seed=0,1: several values need -m"),
    (["identify", "hydra.run.dri=x"], "unknown setting hydra.run.dri (did you mean "
                                      "hydra.run.dir?)"),
    (["validate", "a b=c"], "cannot read the setting 'a b=c'"),
    (["validate", "--bogus"], "unrecognized arguments: --bogus"),
    (["stage", "diagnose", "blackbox.enabld=false"], "unknown setting blackbox.enabld"),
])
def test_settings_refused_before_anything_runs(capsys, tmp_path, args, message):
    code, out, err = _run(capsys, *args)
    assert code == EXIT_USER_ERROR
    assert err.count("\n") == 1 and f"cdpr {args[0]}: error: {message}" in err, err
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize("args, shown", [
    (["train", "+trainer.limit_train_batches=2"], ("trainer", "limit_train_batches", 2)),
    (["train", "+optimizer.weight_decay=1e-4"], ("optimizer", "weight_decay", 1e-4)),
    (["diagnose", "++blackbox.enabled=false"], ("blackbox", "enabled", False)),
    (["diagnose", "blackbox.epochs=null"], ("blackbox", "epochs", None)),
    (["train", "optimizer.lr=1"], ("optimizer", "lr", 1)),
    (["train", "trainer.devices=auto"], ("trainer", "devices", "auto")),      # Lightning's
    (["train", "trainer.devices=[0,1]"], ("trainer", "devices", [0, 1])),     # other types
    (["train", "trainer.deterministic=warn"], ("trainer", "deterministic", "warn")),
    (["simulate", "+effects=[anchor_offset]", "effects.anchor_offset.cable=2"],
     ("effects", "anchor_offset", {"cable": 2})),
])
def test_arguments_for_an_object_and_set_values_pass(capsys, args, shown):
    """``+key`` adds an argument to a mapping that builds an object (``_target_``: the
    trainer's, the optimizer's), whose arguments may also take a word or a list where the
    default is an integer or a boolean; ``++key`` and ``null`` set a key that is there."""
    cli.main([*args, "--cfg", "job"])
    cfg = yaml.safe_load(capsys.readouterr().out)
    group, key, value = shown
    if isinstance(value, dict):
        assert value.items() <= cfg[group][key].items()
    else:
        assert cfg[group][key] == value


def test_the_api_checks_settings_as_the_command_does():
    with pytest.raises(ConfigError, match="expected true or false"):
        cdpr_pipeline.command_config("diagnose", "blackbox.enabled=flase")
    with pytest.raises(ConfigError, match=r"did you mean blackbox\.enabled\?"):
        cdpr_pipeline.command_config("diagnose", blackbox={"enabld": False})


def test_unknown_subcommand(capsys):
    code, _, err = _run(capsys, "diagnos")
    assert code == EXIT_USER_ERROR and "unknown subcommand 'diagnos'" in err


def _fail_with(monkeypatch, err: BaseException, written=None):
    """Make `cdpr wavelet`'s work write a file into its out_dir, then raise ``err``."""
    from cdpr_pipeline.stages import wavelet

    def broken(cfg):
        from pathlib import Path

        Path(cfg.out_dir).mkdir(parents=True, exist_ok=True)
        (Path(cfg.out_dir) / "bands.json").write_text(written or "half")
        raise err

    monkeypatch.setattr(wavelet, "decompose", broken)


def _previous_output(tmp_path):
    out = tmp_path / "out"
    out.mkdir()
    (out / "bands.json").write_text("previous run")
    return out


def test_ctrl_c_exits_quietly_with_the_outputs_as_they_were(capsys, monkeypatch, tmp_path):
    out = _previous_output(tmp_path)
    _fail_with(monkeypatch, KeyboardInterrupt())
    code, _, err = _run(capsys, "wavelet", f"data.path={foreign_rig_path()}", f"out_dir={out}")
    assert code == EXIT_INTERRUPTED
    assert err.strip() == "cdpr wavelet: interrupted (outputs left as they were)"
    assert [p.name for p in out.iterdir()] == ["bands.json"]
    assert (out / "bands.json").read_text() == "previous run"


def test_an_unexpected_error_is_one_line_and_the_debug_flag_shows_the_traceback(
        capsys, monkeypatch, tmp_path):
    out = _previous_output(tmp_path)
    _fail_with(monkeypatch, ZeroDivisionError("float division by zero"))
    code, _, err = _run(capsys, "wavelet", f"data.path={foreign_rig_path()}", f"out_dir={out}")
    assert code == 1
    assert "cdpr wavelet: internal error: ZeroDivisionError: float division by zero" in err
    assert "Traceback" not in err
    monkeypatch.setenv("CDPR_DEBUG", "1")
    _, _, err = _run(capsys, "wavelet", f"data.path={foreign_rig_path()}", f"out_dir={out}")
    assert "Traceback" in err and "ZeroDivisionError" in err
    assert (out / "bands.json").read_text() == "previous run"


def test_a_user_error_raised_anywhere_is_reported_as_one(capsys, monkeypatch, tmp_path):
    _fail_with(monkeypatch, UserError("gain of winch 2 is negative (rig.yaml, key 'winch')"))
    code, _, err = _run(capsys, "wavelet", f"data.path={foreign_rig_path()}",
                        f"out_dir={tmp_path / 'o'}")
    assert code == EXIT_USER_ERROR
    assert err == "cdpr wavelet: error: gain of winch 2 is negative (rig.yaml, key 'winch')\n"


@pytest.mark.parametrize("sub", sorted(cli.CONFIG_NAMES))
def test_help_says_what_the_subcommand_does_and_lists_its_keys(capsys, sub):
    cli.main([sub, "--help"])
    out = capsys.readouterr().out
    assert out.startswith(f"cdpr {sub}: ")
    assert "main keys (conf/" in out
    keys = [line.split("=")[0].strip() for line in out.splitlines()
            if line.startswith("  ") and "=" in line]
    assert keys, out
    if sub in ("diagnose", "identify", "validate", "train", "wavelet", "virtual"):
        assert "data.path=???" in out
    if sub not in ("validate", "params", "repro"):
        assert "out_dir" in keys
