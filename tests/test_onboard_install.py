"""The on-board install: ``pip install hrlsac`` (no extras) into a clean virtual environment gives a runtime that
loads and checks a policy artifact and flies a mission against a MAVLink vehicle, without gymnasium, OpenCV,
tensorboard or matplotlib; the learning commands say which extra they need.

matplotlib is still *installed* there: filterpy (the estimator's Kalman filter) declares it as a dependency,
though nothing on the runtime's path imports it; the test checks that it is never imported.
"""
from __future__ import annotations

import importlib.metadata
import json
import subprocess
import sys
from pathlib import Path

import pytest

from test_serial_flight import assert_flown_over_serial, fly_over_serial

ROOT = Path(__file__).resolve().parents[1]
PRETRAINED = ROOT / "policies" / "pretrained" / "hrl-sac.pt"
LEFT_OUT = ("gymnasium", "cv2", "tensorboard")
NEVER_IMPORTED = ("gymnasium", "cv2", "tensorboard", "matplotlib", "policies", "sitl_bridge", "simulation")

pytestmark = pytest.mark.slow


def pip(python: Path, *args: str) -> None:
    subprocess.run([str(python), "-m", "pip", "install", "--quiet", "--disable-pip-version-check", *args],
                   check=True, capture_output=True, text=True, timeout=900)


TORCH_RUNTIME = ("torch", "filelock", "fsspec", "jinja2", "markupsafe", "mpmath", "networkx", "sympy",
                 "typing_extensions")
"""torch and what it needs to run (its requirements, and theirs)."""


def link_torch(folder: Path) -> Path:
    """``folder`` filled with links to this environment's torch and its runtime requirements (their packages and
    their metadata): on a venv's path (a .pth file) pip counts torch as installed, as it is after ``pip install
    torch==2.13.0``, without copying and compiling its gigabyte again."""
    folder.mkdir()
    for name in TORCH_RUNTIME:
        distribution = importlib.metadata.distribution(name)
        for top in {Path(str(entry)).parts[0] for entry in distribution.files or ()}:
            if top not in ("..", "__pycache__") and not (folder / top).exists():
                (folder / top).symlink_to(distribution.locate_file(top))
    return folder


@pytest.fixture(scope="module")
def onboard(tmp_path_factory) -> Path:
    """The bin folder of a fresh venv holding torch (this environment's, the CPU build the project pins, linked by
    ``link_torch``) and ``pip install ROOT``."""
    base = tmp_path_factory.mktemp("onboard")
    venv = base / "venv"
    subprocess.run([sys.executable, "-m", "venv", str(venv)], check=True, timeout=300)
    python = venv / "bin" / "python"
    site = subprocess.run([str(python), "-c", "import sysconfig; print(sysconfig.get_paths()['purelib'])"],
                          check=True, capture_output=True, text=True).stdout.strip()
    (Path(site) / "torch-runtime.pth").write_text(f"{link_torch(base / 'torch-runtime')}\n")
    pip(python, str(ROOT))
    return venv / "bin"


def test_the_training_extra_is_not_installed(onboard):
    found = subprocess.run([str(onboard / "python"), "-c", "import importlib.util, json; print(json.dumps("
                            f"{{m: importlib.util.find_spec(m) is not None for m in {list(LEFT_OUT)!r}}}))"],
                           capture_output=True, text=True, check=True, cwd=onboard)
    assert json.loads(found.stdout) == {module: False for module in LEFT_OUT}


def test_the_runtime_loads_a_policy_and_imports_nothing_of_training_or_the_simulator(onboard):
    info = subprocess.run([str(onboard / "hrlsac"), "policy", "info", str(PRETRAINED)], capture_output=True,
                          text=True, timeout=300, cwd=onboard)
    assert info.returncode == 0, info.stderr
    assert "hrl-sac" in info.stdout.lower()
    script = ("import sys, json, hrlsac_cli, autonomy.mission_cli, autonomy.runner, autonomy.mavsdk_link\n"
              "from autonomy.policy import load_policy\n"
              f"policy = load_policy({str(PRETRAINED)!r})\n"
              f"print(json.dumps(sorted({{m.split('.')[0] for m in sys.modules}} & {set(NEVER_IMPORTED)!r})))")
    loaded = subprocess.run([str(onboard / "python"), "-c", script], capture_output=True, text=True, timeout=300,
                            cwd=onboard)
    assert loaded.returncode == 0, loaded.stderr
    assert json.loads(loaded.stdout.strip().splitlines()[-1]) == []


@pytest.mark.parametrize("command", [["train", "--out", "run"], ["mission", "replay", "m.yaml", "--policy", "p.pt"]])
def test_a_workstation_command_names_the_extra_it_needs(onboard, command):
    result = subprocess.run([str(onboard / "hrlsac"), *command], capture_output=True, text=True, timeout=300,
                            cwd=onboard)
    assert result.returncode == 2
    assert result.stderr.strip().endswith("which an on-board install leaves out: pip install 'hrlsac[train]'")
    assert len(result.stderr.strip().splitlines()) == 1


def test_the_onboard_install_flies_a_mission_over_a_serial_line(onboard, tmp_path):
    """``hrlsac mission run`` of the on-board install against this checkout's simulated vehicle, over a serial line
    (a pseudo-terminal): ``--connect serial:...`` needs pyserial (pymavlink imports it for a serial connection), a
    base dependency. The whole mission, as tests/test_serial_flight.py checks it; the runner over real UDP is
    tests/test_runner_udp.py's."""
    assert_flown_over_serial(*fly_over_serial(tmp_path, runner=[str(onboard / "hrlsac")]))
