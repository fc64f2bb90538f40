"""The ``cdpr`` command as a user meets it: errors as messages, Ctrl-C, ``--help``.

Called in-process (``cdpr_pipeline.cli.main``), several times in one process, as the
bad-input suite does."""

from __future__ import annotations

import shutil

import pytest

from cdpr_pipeline import cli
from cdpr_pipeline.errors import EXIT_INTERRUPTED, EXIT_USER_ERROR, UserError
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
    monkeypatch.chdir(tmp_path)        # Hydra's run directories go there


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
