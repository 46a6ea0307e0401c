"""The package's layout: no import cycle between cpapfit's subpackages; the stages never import the
synthetic subjects; the commands load the report and the synthetic subjects only where they are used."""

import ast
import subprocess
import sys
from collections import defaultdict
from pathlib import Path

PACKAGE = Path(__file__).resolve().parent.parent / "cpapfit"


SYNTHETIC_USERS = {"api.py", "commands.py", "io/phantom.py"}  # `cpapfit phantom` and `cpapfit.phantom`: make one, write it


def imported(path: Path) -> set[tuple[str, ...]]:
    """The cpapfit modules a module imports (relative imports), as paths of names under cpapfit."""
    folders = path.relative_to(PACKAGE).parts[:-1]
    return {(*folders[:len(folders) - node.level + 1], *node.module.split("."))
            for node in ast.walk(ast.parse(path.read_text()))
            if isinstance(node, ast.ImportFrom) and node.level and node.module}


def package_imports() -> dict[str, set[str]]:
    """{subpackage: the other subpackages its modules import (relative imports)}."""
    edges = defaultdict(set)
    for path in PACKAGE.rglob("*.py"):
        folders = path.relative_to(PACKAGE).parts[:-1]
        if not folders:
            continue
        for target in imported(path):
            if target[0] != folders[0] and (PACKAGE / target[0]).is_dir():
                edges[folders[0]].add(target[0])
    return edges


def test_no_two_subpackages_import_each_other():
    edges = package_imports()
    assert edges["align"] >= {"landmarks"} and edges["report"] >= {"evaluation"}  # the scan sees real imports
    assert [(a, b) for a in edges for b in edges[a] if a in edges.get(b, ())] == []


def test_only_the_phantom_command_and_api_import_the_synthetic_subjects():
    """`synthetic` makes subjects with the stages' kernels (template, renderer); no stage imports it."""
    users = {path.relative_to(PACKAGE).as_posix() for path in PACKAGE.rglob("*.py")
             if path.relative_to(PACKAGE).parts[0] != "synthetic" and any(t[0] == "synthetic" for t in imported(path))}
    assert users == SYNTHETIC_USERS
    assert package_imports()["synthetic"] >= {"template", "ict"}


def test_the_commands_load_neither_the_report_nor_the_synthetic_subjects_until_used():
    """`cpapfit register` and `landmarks` import `commands`; matplotlib and the subjects cost them ~0.6 s."""
    code = "import sys, cpapfit.commands; print(sorted({m.split('.')[0] if m.startswith('matplotlib') else m for m in sys.modules "
    code += "if m.startswith(('matplotlib', 'cpapfit.report', 'cpapfit.synthetic'))}))"
    run = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
    assert run.returncode == 0 and run.stdout.strip() == "[]", run.stdout + run.stderr
