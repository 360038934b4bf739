"""Print which of the project's modules imports which, and the five largest modules.

    python docs/import_graph.py [ROOT]

Reads the source with ``ast`` (nothing is imported), so it runs on any checkout, old or new:
``git worktree add /tmp/old COMMIT && python docs/import_graph.py /tmp/old``. Lines starting
with ``!`` are commands (modules with ``add_arguments`` and ``main``) importing another
command, which the layout forbids.
"""

from __future__ import annotations

import argparse
import ast
from pathlib import Path

PACKAGES = ("services", "onebox", "schemas", "tests", "benchmarks")


def is_command(path: Path) -> bool:
    text = path.read_text()
    return "\ndef add_arguments(" in text and "\ndef main(" in text


def module_name(root: Path, path: Path) -> str:
    parts = list(path.relative_to(root).with_suffix("").parts)
    if parts[-1] == "__init__":
        parts.pop()
    return ".".join(parts)


def imports(root: Path, path: Path, known: set[str]) -> set[str]:
    """The project's modules that ``path`` imports (``from pkg import mod`` counts as pkg.mod)."""
    found: set[str] = set()
    for node in ast.walk(ast.parse(path.read_text(), str(path))):
        if isinstance(node, ast.Import):
            names = [alias.name for alias in node.names]
        elif isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
            names = [f"{node.module}.{alias.name}" for alias in node.names] + [node.module]
        else:
            continue
        for name in names:
            while name and name not in known:
                name = name.rpartition(".")[0]
            if name:
                found.add(name)
    found.discard(module_name(root, path))
    return found


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("root", nargs="?", type=Path, default=Path(__file__).parent.parent)
    root = parser.parse_args().root.resolve()
    files = [p for pkg in PACKAGES for p in sorted((root / pkg).rglob("*.py"))]
    known = {module_name(root, p) for p in files}
    commands = {module_name(root, p) for p in files if is_command(p)}
    for path in files:
        name = module_name(root, path)
        if name.startswith(("tests", "benchmarks")) or name.endswith("__init__"):
            continue
        deps = sorted(imports(root, path, known))
        cross = name in commands and any(d in commands for d in deps)
        print(f"{'!' if cross else ' '} {name} -> {', '.join(deps) or '(nothing of ours)'}")
    test_side = [p for p in files if module_name(root, p).startswith("benchmarks")]
    from_tests = sorted(
        module_name(root, p)
        for p in test_side
        if any(d.startswith("tests") for d in imports(root, p, known))
    )
    print(f"\nbenchmarks importing tests/: {', '.join(from_tests) or 'none'}")
    sizes = sorted(
        (
            (len(p.read_text().splitlines()), module_name(root, p))
            for p in files
            if not module_name(root, p).startswith(("tests", "benchmarks"))
        ),
        reverse=True,
    )
    print("largest modules: " + ", ".join(f"{name} {lines}" for lines, name in sizes[:5]))


if __name__ == "__main__":
    main()
