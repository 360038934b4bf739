"""Settings: a flag, then an environment variable, then config/onebox.toml, then the default.

The seed passed launch arguments as ``name:=value``; here ``ONEBOX_HFOV_DEG=90 honcho start`` or
``onebox sim --hfov-deg 90`` do the same. Every service adds its settings with :func:`add`, so
the precedence and the error for a bad value live in one place.
"""

from __future__ import annotations

import argparse
import functools
import importlib.resources
import os
import tomllib
from collections.abc import Callable
from pathlib import Path
from typing import Any

from onebox.errors import SettingError

PREFIX = "ONEBOX_"
"""Every setting's environment variable starts with this: ``ONEBOX_HFOV_DEG=90 honcho start``."""


def data_dir(name: str) -> Path:
    """``config`` or ``scene``: the checkout's own folder (where people edit) when onebox runs
    from a checkout, else the copy installed inside the package."""
    checkout = Path(__file__).resolve().parent.parent / name
    if checkout.is_dir():
        return checkout
    return Path(str(importlib.resources.files("onebox") / name))


CONFIG_DIR = data_dir("config")
SCENE_DIR = data_dir("scene")
SETTINGS_FILE = CONFIG_DIR / "onebox.toml"


@functools.cache
def _file_values(path: Path = SETTINGS_FILE) -> dict[str, Any]:
    """Every setting in the file, flattened: the [section] headings only group them."""
    try:
        with path.open("rb") as f:
            tables = tomllib.load(f)
    except FileNotFoundError:
        return {}
    except tomllib.TOMLDecodeError as e:
        raise SettingError(f"{path} is not valid TOML: {e}") from e
    values: dict[str, Any] = {}
    for table in tables.values():
        if isinstance(table, dict):
            values.update(table)
    return values


def parse_bool(text: str) -> bool:
    """``true/false``, ``1/0``, ``yes/no``, ``on/off``, any case."""
    lowered = text.strip().lower()
    if lowered in {"1", "true", "yes", "on"}:
        return True
    if lowered in {"0", "false", "no", "off"}:
        return False
    raise argparse.ArgumentTypeError(f"expected true or false, got {text!r}")


def env_variable(name: str) -> str:
    """The environment variable of setting ``name``: ``hfov_deg`` is ``ONEBOX_HFOV_DEG``."""
    return PREFIX + name.upper()


def default(name: str, fallback: Any, kind: Callable[[str], Any]) -> Any:
    """The value of setting ``name`` before any flag: environment, then file, then ``fallback``."""
    env_name = env_variable(name)
    if env_name in os.environ:
        raw = os.environ[env_name]
        try:
            return kind(raw)
        except (ValueError, argparse.ArgumentTypeError) as e:
            raise SettingError(f"environment variable {env_name}={raw!r}: {e}") from e
    return _file_values().get(name, fallback)


def add(
    parser: argparse._ActionsContainer,
    name: str,
    fallback: Any,
    help: str,
    kind: Callable[[str], Any] | None = None,
) -> None:
    """Add ``--name-with-dashes`` whose default comes from the environment or the config file."""
    if kind is None:
        kind = parse_bool if isinstance(fallback, bool) else type(fallback)
    value = default(name, fallback, kind)
    # A yes/no setting also works as a bare flag: --gui is --gui true.
    extra: dict[str, Any] = {"nargs": "?", "const": True} if kind is parse_bool else {}
    parser.add_argument(
        f"--{name.replace('_', '-')}",
        dest=name,
        type=kind,
        default=value,
        metavar=name.upper(),
        help=f"{help} (default {value!r}; environment {env_variable(name)})",
        **extra,
    )
