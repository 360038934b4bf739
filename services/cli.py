"""onebox: a depth camera on a stand finds a red box on a table.

Every process and tool is a subcommand; ``onebox COMMAND --help`` explains each.
"""

from __future__ import annotations

import argparse
import difflib
import importlib
import importlib.metadata
import logging
import os
import sys

from onebox.errors import OneboxError

# name: (module, one line). Modules are imported only when their command runs, so that
# ``onebox --help`` does not load MuJoCo or Rerun.
COMMANDS: dict[str, tuple[str, str]] = {
    "router": ("services.router", "the Zenoh router every process on this host connects to"),
    "sim": ("services.sim", "simulate the table, the box and both cameras; publish what they see"),
    "locator": ("services.locator", "find the box in each depth picture; publish detections"),
    "points": ("services.points", "turn depth and colour into camera/points"),
    "viewer": ("services.viewer", "show everything live in Rerun (the seed's RViz)"),
    "view": ("services.view", "show an .mcap recording in Rerun, or write an .rrd"),
    "record": ("services.record", "record keys into an .mcap file (ros2 bag record)"),
    "snapshot": ("services.snapshot", "record one capture into an .mcap file and exit"),
    "replay": ("services.replay", "publish an .mcap recording back onto its keys (ros2 bag play)"),
    "info": ("services.info", "summarise an .mcap recording (ros2 bag info)"),
    "export": ("services.export", "write an .mcap recording for ROS 2 or Foxglove tools"),
    "import": ("services.import_bag", "turn a real camera's ROS bag into a onebox recording"),
    "ros2": ("services.ros2", "bridge onebox keys and ROS 2 topics live, over rmw_zenoh"),
    "pixels": ("services.pixels", "print every pixel of the basic camera (make camera.pixels)"),
    "check": ("services.check", "list what is being published (make camera.check)"),
    "echo": ("services.echo", "print every message on a key, readable (ros2 topic echo)"),
    "hz": ("services.hz", "how often messages arrive on a key (ros2 topic hz)"),
    "bw": ("services.bw", "how many bytes a second a key carries (ros2 topic bw)"),
    "pub": ("services.pub", "publish a message typed from JSON (ros2 topic pub)"),
    "certs": ("services.certs", "make a CA and one certificate a process for config/secure/"),
}


def _top_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="onebox",
        description=__doc__,
        formatter_class=argparse.RawDescriptionHelpFormatter,
        allow_abbrev=False,
        epilog="commands:\n"
        + "\n".join(f"  {name:<10} {line}" for name, (_, line) in COMMANDS.items()),
    )
    parser.add_argument("command", metavar="COMMAND", help="one of the commands below")
    parser.add_argument("--version", action="store_true", help="print onebox's version and exit")
    return parser


def version() -> str:
    """The installed package's version, as pip knows it."""
    try:
        return importlib.metadata.version("onebox")
    except importlib.metadata.PackageNotFoundError:
        return "unknown (not installed: run `pip install -e .` in the checkout)"


def unknown_command(name: str) -> str:
    """The error for a command that does not exist, with the nearest one when there is one."""
    close = difflib.get_close_matches(name, COMMANDS, n=1)
    hint = f": did you mean `onebox {close[0]}`?" if close else ""
    return f"unknown command {name!r}{hint} (`onebox --help` lists them all)"


def command_parser(name: str) -> tuple[argparse.ArgumentParser, object]:
    """The parser of one command and its module."""
    module = importlib.import_module(COMMANDS[name][0])
    parser = argparse.ArgumentParser(
        prog=f"onebox {name}",
        description=module.__doc__,
        formatter_class=argparse.RawDescriptionHelpFormatter,
        allow_abbrev=False,  # `--rat 0` is a mistake to report, never `--rate 0`
    )
    module.add_arguments(parser)
    return parser, module


def main(argv: list[str] | None = None) -> int:
    """Entry point of the ``onebox`` console script."""
    argv = sys.argv[1:] if argv is None else argv
    if not argv or argv[0] in {"-h", "--help"}:
        _top_parser().print_help()
        return 0 if argv else 2
    if argv[0] == "--version":
        print(f"onebox {version()}")
        return 0
    name, rest = argv[0], argv[1:]
    if name not in COMMANDS:
        _top_parser().error(unknown_command(name))
    logging.basicConfig(
        level=os.environ.get("ONEBOX_LOG", "INFO").upper(),
        format="%(levelname)s [%(name)s] %(message)s",
    )
    logging.getLogger("OpenGL").setLevel(logging.WARNING)  # PyOpenGL chatters at INFO on import
    from onebox.bus import install_signal_handlers

    install_signal_handlers()
    try:
        parser, module = command_parser(name)
        args = parser.parse_args(rest)
        code: int = module.main(args)  # type: ignore[attr-defined]
        return code
    except OneboxError as e:
        print(f"onebox {name}: {e}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        return 0
    except BrokenPipeError:
        # The reader went away (`onebox info run.mcap | head`): stop quietly, as a Unix tool does.
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        return 1


if __name__ == "__main__":
    sys.exit(main())
