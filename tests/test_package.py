"""Package surface: exports, logger, CLI info, packaging metadata."""

from __future__ import annotations

import json
import logging
import subprocess
import sys
from pathlib import Path

import pytest

import taplan
from taplan.cli import main

ROOT = Path(__file__).resolve().parents[1]


def test_library_logger_has_only_a_null_handler():
    handlers = logging.getLogger("taplan").handlers
    assert len(handlers) == 1 and isinstance(handlers[0], logging.NullHandler)


def test_public_names_are_exported():
    for name in taplan.__all__:
        assert hasattr(taplan, name), name
    assert issubclass(taplan.InvalidLimitsError, taplan.TaplanError)
    assert issubclass(taplan.UnknownNameError, taplan.TaplanError)


def test_info_prints_model_limits_home_and_poses(capsys):
    assert main(["info"]) == 0
    out = capsys.readouterr().out
    assert "l_joint1" in out and "r_joint7" in out
    assert "Home pose" in out and "left_ee at home" in out and "right_ee at home" in out


def test_info_json_is_consistent_with_the_api(capsys, teleavatar):
    assert main(["info", "--json"]) == 0
    payload = json.loads(capsys.readouterr().out)
    assert payload["joint_names"] == list(teleavatar.joint_names)
    assert payload["home"] == teleavatar.home.tolist()
    assert payload["ee_poses_at_home"]["left_ee"] == teleavatar.frame_pose(teleavatar.home, "left_ee").tolist()


def test_console_script_runs_as_module():
    result = subprocess.run([sys.executable, "-m", "taplan", "info"], capture_output=True, text=True, check=False)
    assert result.returncode == 0, result.stderr
    assert "TeleAvatar" in result.stdout or "teleavatar" in result.stdout


def test_cli_errors_exit_nonzero(capsys, tmp_path):
    assert main(["info", "--urdf", str(tmp_path / "none.urdf")]) == 2
    assert "not found" in capsys.readouterr().err


def test_pyproject_declares_the_design_card_dependencies():
    tomllib = pytest.importorskip("tomllib")
    project = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]
    deps = " ".join(project["dependencies"])
    for package in ("pin", "numpy", "qpsolvers", "proxsuite", "daqp", "toppra", "ruckig", "casadi", "pyyaml"):
        assert package in deps, package
    assert {"bench", "dev"} <= set(project["optional-dependencies"])
    assert project["scripts"]["taplan"] == "taplan.cli:main"
    assert (ROOT / "taplan" / "py.typed").exists()


def test_readme_commands_are_the_ones_ci_runs():
    readme = (ROOT / "README.md").read_text()
    ci = (ROOT / ".ci" / "run").read_text()
    test_command = ".venv/bin/python -m pytest -q"
    assert test_command in readme and test_command in ci
    assert 'pip install -e ".[dev,bench]"' in readme and '-e ".[dev,bench]"' in ci
    assert ".venv/bin/taplan demo" in readme
