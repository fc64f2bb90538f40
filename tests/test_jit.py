"""The compiled kernels' cache: in the user's cache folder, or none where it cannot be
written; never beside the modules, and numba's own setting left as it was."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

from cdpr_pipeline import jit


def _add(a, b):
    return a + b


def test_the_cache_folder_follows_numba_cache_dir_then_xdg(monkeypatch, tmp_path):
    monkeypatch.delenv("NUMBA_CACHE_DIR", raising=False)
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "xdg"))
    assert jit.cache_dir() == tmp_path / "xdg" / "cdpr_pipeline" / "numba"
    monkeypatch.setenv("NUMBA_CACHE_DIR", str(tmp_path / "mine"))
    assert jit.cache_dir() == tmp_path / "mine"
    assert jit.writable_cache_dir() == tmp_path / "mine"
    assert (tmp_path / "mine").is_dir()


def test_a_folder_that_cannot_be_created_means_no_cache(monkeypatch, tmp_path):
    blocker = tmp_path / "a_file"
    blocker.write_text("not a folder")
    monkeypatch.setenv("NUMBA_CACHE_DIR", str(blocker / "numba"))
    assert jit.writable_cache_dir() is None


def test_a_kernel_is_cached_in_the_folder_and_numbas_setting_is_put_back(monkeypatch,
                                                                        tmp_path):
    numba = jit.numba_module()
    # numba re-reads NUMBA_CACHE_DIR itself (its own, process-wide); without it the
    # folder is the user's cache folder, numba's setting only while locating
    monkeypatch.delenv("NUMBA_CACHE_DIR", raising=False)
    monkeypatch.setattr(numba.config, "CACHE_DIR", "")
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "xdg"))
    kernel = jit.compile_kernel(_add)
    assert kernel(2.0, 3.5) == 5.5
    assert numba.config.CACHE_DIR == ""
    folder = tmp_path / "xdg" / "cdpr_pipeline" / "numba"
    assert list(folder.rglob("*.nbi")), "the kernel's index is in the user's cache folder"


def test_an_unwritable_cache_compiles_without_writing_beside_the_module(tmp_path):
    # a fresh process, as a user's: numba would otherwise fall back to the folder of
    # the kernel's module (here the test's own, copied into tmp_path)
    module = tmp_path / "kernels_here.py"
    module.write_text("def add(a, b):\n    return a + b\n")
    blocker = tmp_path / "a_file"
    blocker.write_text("not a folder")
    script = ("import kernels_here\n"
              "from cdpr_pipeline.jit import compile_kernel\n"
              "print(compile_kernel(kernels_here.add)(2.0, 3.5))\n")
    done = subprocess.run([sys.executable, "-c", script], cwd=tmp_path, text=True,
                          capture_output=True, check=False,
                          env={**_environment(), "NUMBA_CACHE_DIR": str(blocker / "numba"),
                               "PYTHONPATH": _python_path(tmp_path)})
    assert done.returncode == 0, done.stderr
    assert float(done.stdout) == 5.5
    written = [p.name for p in tmp_path.rglob("*") if p.suffix in (".nbi", ".nbc")]
    assert written == []


def _environment() -> dict[str, str]:
    return {k: v for k, v in os.environ.items() if k != "NUMBA_CACHE_DIR"}


def _python_path(folder: Path) -> str:
    return os.pathsep.join([str(folder), *sys.path[1:]])
