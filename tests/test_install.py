"""A wheel of onebox works outside the checkout: its config/ and scene/ travel inside it."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

from onebox.testing.processes import ROOT


@pytest.fixture(scope="module")
def installed(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The wheel built from the checkout, unpacked into a folder of its own (no checkout)."""
    wheels = tmp_path_factory.mktemp("wheels")
    target = tmp_path_factory.mktemp("site")
    built = subprocess.run(
        [
            sys.executable,
            "-m",
            "pip",
            "wheel",
            "--no-deps",
            "-q",
            "-w",
            str(wheels),
            str(ROOT),
        ],
        capture_output=True,
        text=True,
        timeout=300,
        check=False,
    )
    assert built.returncode == 0, built.stderr
    [wheel] = wheels.glob("onebox-*.whl")
    unpacked = subprocess.run(
        [
            sys.executable,
            "-m",
            "pip",
            "install",
            "--no-deps",
            "-q",
            "--target",
            str(target),
            str(wheel),
        ],
        capture_output=True,
        text=True,
        timeout=300,
        check=False,
    )
    assert unpacked.returncode == 0, unpacked.stderr
    return target


def run_installed(site: Path, tmp_path: Path, *args: str) -> subprocess.CompletedProcess[str]:
    """``onebox ARGS`` from the installed copy, run from a folder that is not the checkout."""
    env = {**os.environ, "PYTHONPATH": str(site)}
    return subprocess.run(
        [sys.executable, "-m", "services.cli", *args],
        cwd=tmp_path,
        env=env,
        capture_output=True,
        text=True,
        timeout=120,
        check=False,
    )


def test_the_installed_copy_reads_its_own_config_and_scenes(installed, tmp_path):
    """The installed onebox finds client.json5, onebox.toml and the scene files it ships."""
    probe = run_installed(
        installed,
        tmp_path,
        "sim",
        "--scene",
        str(installed / "onebox" / "scene" / "pallet.toml"),
        "--write-scene",
        str(tmp_path / "pallet.toml"),
    )
    assert probe.returncode == 0, probe.stderr
    assert "[camera]" in (tmp_path / "pallet.toml").read_text()
    where = subprocess.run(
        [
            sys.executable,
            "-c",
            "import onebox.settings as s; print(s.CONFIG_DIR); print(s.SCENE_DIR)",
        ],
        cwd=tmp_path,
        env={**os.environ, "PYTHONPATH": str(installed)},
        capture_output=True,
        text=True,
        timeout=60,
        check=False,
    )
    config_dir, scene_dir = (Path(line) for line in where.stdout.split())
    assert config_dir == installed / "onebox" / "config", where.stderr
    assert {"client.json5", "router.json5", "onebox.toml"} <= {p.name for p in config_dir.iterdir()}
    assert {"one_box.toml", "one_box.xml", "pallet.toml", "clutter.toml"} <= {
        p.name for p in scene_dir.iterdir()
    }


def test_the_installed_copy_runs_a_router_with_its_config(installed, tmp_path):
    """`onebox router --help` and a bad flag work from the installed copy, with no checkout."""
    helped = run_installed(installed, tmp_path, "router", "--help")
    assert helped.returncode == 0 and "router" in helped.stdout, helped.stderr
    refused = run_installed(installed, tmp_path, "sim", "--hfov-deg", "wide")
    assert refused.returncode == 2 and "Traceback" not in refused.stderr
