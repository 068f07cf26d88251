"""The package as a new user gets it: a wheel built without a C compiler, the sdist and its
tests, ``--version`` on every entry point, a closed pipe.

The builds use pip's and setuptools' own isolated build (setuptools >= 77 from the package
index, as ``pip install .`` does), so they take some seconds each.
"""

from __future__ import annotations

import os
import re
import subprocess
import sys
import sysconfig
import tarfile
import zipfile
from pathlib import Path

import pytest

from cmsensord import __version__
from processes import ENV, ROOT, run_module, spawn

KERNEL_LINE = ("WARNING C kernel(s) not built: cmsensord.dsp._akfkernel (the AKF bank), "
               "cmsensord.dsp._trackerkernel (the order tracker), cmsensord._wirekernel (the wire decoder); "
               "the numpy fallback runs instead")


def _env(path: Path | None = None) -> dict[str, str]:
    env = dict(ENV)
    if path is not None:             # the installed tree first, before this checkout
        env["PYTHONPATH"] = str(path)
    return env


def _installed(site: Path, *args: str, cwd: Path) -> subprocess.CompletedProcess:
    """``python -m cmsensord ARGS`` from the tree ``site`` alone, as in a fresh environment: ``-S``
    keeps this environment's editable install of the checkout (a .pth finder) out; its
    site-packages stay on the path for numpy and the other dependencies."""
    path = os.pathsep.join([str(site), sysconfig.get_paths()["purelib"], sysconfig.get_paths()["platlib"]])
    return subprocess.run([sys.executable, "-S", "-m", "cmsensord", *args], capture_output=True, text=True,
                          env=dict(ENV, PYTHONPATH=path), cwd=cwd, timeout=120)


@pytest.fixture(scope="module")
def no_compiler_install(tmp_path_factory) -> tuple[Path, Path]:
    """(the wheel, the directory it is installed in) of ``CC=false pip wheel .``."""
    base = tmp_path_factory.mktemp("wheel")
    r = subprocess.run([sys.executable, "-m", "pip", "wheel", "--no-deps", "-q", "-w", str(base / "dist"),
                        str(ROOT)], capture_output=True, text=True, env=dict(ENV, CC="false"), timeout=600)
    assert r.returncode == 0, r.stderr
    wheel, = (base / "dist").glob("cmsensord-*.whl")
    r = subprocess.run([sys.executable, "-m", "pip", "install", "-q", "--no-deps", "--target",
                        str(base / "site"), str(wheel)], capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, r.stderr
    return wheel, base / "site"


def test_the_wheel_carries_license_metadata_and_the_default_config(no_compiler_install):
    wheel, _ = no_compiler_install
    with zipfile.ZipFile(wheel) as z:
        names = z.namelist()
        meta = z.read(next(n for n in names if n.endswith(".dist-info/METADATA"))).decode()
    assert "cmsensord/config/default.yaml" in names
    assert any(n.endswith(".dist-info/licenses/LICENSE") for n in names)
    assert not [n for n in names if n.endswith(".so")]          # CC=false: no kernel built
    assert "License-Expression: MIT" in meta.splitlines()
    assert "Classifier: Programming Language :: Python :: 3" in meta.splitlines()
    assert re.search(r"^Project-URL: Homepage, ", meta, re.M)


def test_without_a_compiler_the_daemon_names_the_missing_kernels(no_compiler_install, tmp_path):
    _, site = no_compiler_install
    r = _installed(site, "--simulate", "--duration", "60", "--out", str(tmp_path), cwd=tmp_path)
    assert r.returncode == 0, r.stderr
    lines = r.stderr.splitlines()
    assert [line for line in lines if "kernel" in line and not line.startswith("[")] == [
        next(line for line in lines if line.startswith(KERNEL_LINE))]
    status = [line for line in lines if line.startswith("[")]
    assert status and all(line.endswith("| numpy fallback: no _akfkernel, _trackerkernel, _wirekernel")
                          for line in status)


def test_the_built_daemon_says_nothing_of_kernels(tmp_path):
    r = subprocess.run([sys.executable, "-m", "cmsensord", "--simulate", "--duration", "20", "--out",
                        str(tmp_path)], capture_output=True, text=True, env=ENV, timeout=120)
    assert r.returncode == 0 and "kernel" not in r.stderr and "numpy fallback" not in r.stderr


def test_config_default_prints_the_file_also_from_the_wheel(no_compiler_install, tmp_path):
    _, site = no_compiler_install
    expected = (ROOT / "config" / "default.yaml").read_text(encoding="utf-8")
    r = _installed(site, "config", "--default", cwd=tmp_path)
    assert r.returncode == 0 and r.stdout == expected
    r = _installed(site, "--version", cwd=tmp_path)
    assert r.stdout == f"cmsensord {__version__}\n"
    r = subprocess.run([sys.executable, "-m", "cmsensord", "config", "--default"], capture_output=True,
                       text=True, env=ENV, timeout=60)
    assert r.returncode == 0 and r.stdout == expected
    r = subprocess.run([sys.executable, "-m", "cmsensord", "--help"], capture_output=True, text=True,
                       env=ENV, timeout=60)
    assert "`cmsensord config --default`" in r.stdout


def test_version_on_every_entry_point():
    for module, name in (("cmsensord", "cmsensord"), ("firmware_sim", "firmware_sim"),
                         ("cmsensord.acoustic_calib", "cmsensord.acoustic_calib")):
        r = run_module(module, "--version")
        assert r.returncode == 0 and r.stdout.startswith(name) and __version__ in r.stdout, (module, r)
    scripts = Path(sys.executable).parent
    for script in ("cmsensord", "firmware-sim"):
        if (scripts / script).exists():          # the console scripts of this environment
            r = subprocess.run([str(scripts / script), "--version"], capture_output=True, text=True,
                               env=ENV, timeout=60)
            assert r.returncode == 0 and __version__ in r.stdout, script


def test_simulate_into_a_closed_pipe_exits_quietly(tmp_path):
    """``cmsensord --simulate 2>&1 | head -1``: the status lines meet a closed pipe; the run
    ends with the MCAP file finished and exit status 141, as after SIGPIPE, no traceback."""
    r_fd, w_fd = os.pipe()
    proc = spawn([sys.executable, "-m", "cmsensord", "--simulate", "--duration", "60",
                             "--out", str(tmp_path)], stdout=w_fd, stderr=w_fd, env=ENV)
    os.close(w_fd)
    with os.fdopen(r_fd, "rb") as pipe:
        first = pipe.readline()
    assert first.startswith(b"simulated board")
    assert proc.wait(timeout=60) == 141
    assert len(list(tmp_path.glob("*.mcap"))) == 1 and not list(tmp_path.glob("*.part"))


def test_the_sdist_holds_what_its_tests_import_and_they_pass(tmp_path):
    tools = tmp_path / "tools"
    r = subprocess.run([sys.executable, "-m", "pip", "install", "-q", "--target", str(tools),
                        "setuptools>=77", "wheel"], capture_output=True, text=True, timeout=600)
    assert r.returncode == 0, r.stderr
    r = subprocess.run([sys.executable, "-c", "import sys; from setuptools import build_meta; "
                        "print(build_meta.build_sdist(sys.argv[1]))", str(tmp_path / "dist")],
                       capture_output=True, text=True, cwd=ROOT, env=dict(ENV, PYTHONPATH=str(tools)),
                       timeout=600)
    assert r.returncode == 0, r.stderr
    sdist = tmp_path / "dist" / r.stdout.split()[-1]
    with tarfile.open(sdist) as tar:
        if hasattr(tarfile, "data_filter"):
            tar.extractall(tmp_path / "src", filter="data")
        else:                                   # pragma: no cover - Python before 3.11.4
            tar.extractall(tmp_path / "src")
        top = f"cmsensord-{__version__}/"
        names = {n.removeprefix(top) for n in tar.getnames()}
    tracked = subprocess.run(["git", "ls-files", "tests", "config", "LICENSE"], capture_output=True,
                             text=True, cwd=ROOT).stdout.split()
    assert tracked and set(tracked) <= names, sorted(set(tracked) - names)
    assert {"tests/stream.py", "tests/fuzz.py", "tests/conftest.py", "cmsensord/dsp/_akfkernel.c"} <= names
    src = tmp_path / "src" / top
    r = subprocess.run([sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider", "--collect-only",
                        "tests"], capture_output=True, text=True, cwd=src, env=_env(src), timeout=600)
    assert r.returncode == 0 and "ERROR" not in r.stdout, r.stdout[-2000:]
    r = subprocess.run([sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider", "-x",
                        "tests/test_protocol.py", "tests/test_raw_mode.py"], capture_output=True, text=True,
                       cwd=src, env=_env(src), timeout=600)
    assert r.returncode == 0, r.stdout[-2000:]
