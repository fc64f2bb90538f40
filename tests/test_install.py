"""The package installs like a library: the wheel carries ``conf/`` and the shipped data,
and an installed ``cdpr`` works from any directory without writing into site-packages."""

from __future__ import annotations

import os
import site
import subprocess
import sys
import zipfile
from pathlib import Path

import pytest

from cdpr_pipeline.config import PROJECT_ROOT

pytestmark = pytest.mark.skipif(not (PROJECT_ROOT / "setup.py").exists(),
                                reason="needs the source tree (setup.py, conf/)")


@pytest.fixture(scope="module")
def wheel(tmp_path_factory) -> Path:
    """The wheel, built from this checkout (no network: the running setuptools)."""
    pytest.importorskip("setuptools", minversion="77")   # wheels on its own, SPDX license
    out = tmp_path_factory.mktemp("wheel")
    build = tmp_path_factory.mktemp("build")
    # a copy of the sources keeps build/ and *.egg-info out of the checkout
    src = build / "src"
    files = subprocess.run(["git", "-C", str(PROJECT_ROOT), "ls-files", "-co",
                            "--exclude-standard"], check=True, capture_output=True,
                           text=True).stdout.split()
    for name in files:
        if (PROJECT_ROOT / name).is_file():
            (src / name).parent.mkdir(parents=True, exist_ok=True)
            (src / name).write_bytes((PROJECT_ROOT / name).read_bytes())
    proc = subprocess.run([sys.executable, "-m", "pip", "wheel", "--no-deps",
                           "--no-build-isolation", "-w", str(out), str(src)],
                          capture_output=True, text=True, timeout=600)
    assert proc.returncode == 0, proc.stdout[-3000:] + proc.stderr[-3000:]
    (path,) = out.glob("cdpr_pipeline-*.whl")
    return path


def test_the_wheel_carries_every_module_config_and_shipped_file(wheel):
    names = set(zipfile.ZipFile(wheel).namelist())
    package = PROJECT_ROOT / "cdpr_pipeline"
    modules = {f"cdpr_pipeline/{p.relative_to(package)}" for p in package.rglob("*.py")}
    assert modules <= names, sorted(modules - names)
    configs = {f"cdpr_pipeline/conf/{p.relative_to(PROJECT_ROOT / 'conf')}"
               for p in (PROJECT_ROOT / "conf").rglob("*.yaml")}
    assert configs and configs <= names, sorted(configs - names)
    shipped = {f"cdpr_pipeline/{p.relative_to(package)}"
               for p in (package / "resources").rglob("*") if p.is_file()
               and "__pycache__" not in p.parts}
    assert shipped <= names, sorted(shipped - names)
    assert not any(n.startswith(("conf/", "tests/")) for n in names)


def _tree(root: Path) -> set[str]:
    return {str(p.relative_to(root)) for p in root.rglob("*")}


@pytest.mark.slow
@pytest.mark.e2e
def test_the_installed_wheel_works_from_an_empty_directory(wheel, tmp_path):
    venv = tmp_path / "venv"
    subprocess.run([sys.executable, "-m", "venv", "--system-site-packages", str(venv)],
                   check=True)
    bin_dir = venv / "bin"
    py = bin_dir / "python"
    target = Path(subprocess.run([py, "-c", "import sysconfig; print(sysconfig.get_paths()"
                                  "['purelib'])"], check=True, capture_output=True,
                                 text=True).stdout.strip())
    env = {k: v for k, v in os.environ.items()
           if k not in ("PYTHONPATH", "MLFLOW_TRACKING_URI", "CDPR_DEBUG")}
    subprocess.run([py, "-m", "pip", "install", "--no-deps", "--no-index", "--quiet",
                    str(wheel)], check=True, timeout=600, env=env)
    # the dependencies: those of the environment running the tests (a venv made from a
    # venv sees only the base interpreter's packages); appended after the new venv's own,
    # and only now, or pip would take that environment's cdpr-pipeline for this one
    (target / "_test_dependencies.pth").write_text("\n".join(site.getsitepackages()) + "\n")
    before = _tree(target)
    work = tmp_path / "empty"
    work.mkdir()
    env["PATH"] = f"{bin_dir}{os.pathsep}{env.get('PATH', '')}"

    def run(*args: str) -> subprocess.CompletedProcess:
        proc = subprocess.run(list(args), cwd=work, env=env, capture_output=True, text=True,
                              timeout=900)
        assert proc.returncode == 0, f"{args}\n{proc.stdout[-3000:]}\n{proc.stderr[-3000:]}"
        return proc

    where = run(str(py), "-c", "import cdpr_pipeline, cdpr_pipeline.config as c; "
                "print(cdpr_pipeline.__file__); print(c.CONFIG_DIR); "
                "print(c.compose_config('diagnose').blackbox.epochs)").stdout.split()
    assert where[0].startswith(str(target)) and where[1] == str(target / "cdpr_pipeline/conf")
    assert where[2] == "5"
    assert "data.path=???" in run("cdpr", "diagnose", "--help").stdout
    lab = work / "lab"
    run("cdpr", "simulate", "trajectory=tiny", "trajectory.duration_s=2.0", "quiet=true",
        f"out_dir={lab}")
    run("cdpr", "validate", f"data.path={lab}")
    run("cdpr", "identify", f"data.path={lab}", "holdout=[spiral]", f"out_dir={work / 'id'}")
    run("cdpr", "train", "model=constant_velocity", f"data.path={lab}", "quiet=true",
        f"out_dir={work / 'train'}")
    run("cdpr", "diagnose", f"data.path={lab}", "blackbox.enabled=false",
        "discovery.closed_loop=false", "discovery.freeform=null", f"out_dir={work / 'diag'}")
    foreign = run(str(py), "-c", "from cdpr_pipeline.resources import foreign_rig_path as f; "
                  "print(f())").stdout.strip()
    run("cdpr", "validate", f"data.path={foreign}")
    assert (work / "diag" / "diagnosis.json").exists()
    assert (work / "id" / "identification.json").exists()
    assert (work / "train" / "forecaster.pt").exists()
    assert (work / "mlflow.db").exists()        # MLflow's default: the working directory
    assert _tree(target) == before, sorted(_tree(target) ^ before)
