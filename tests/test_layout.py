"""The package's layout: no import cycle between cpapfit's subpackages."""

import ast
from collections import defaultdict
from pathlib import Path

PACKAGE = Path(__file__).resolve().parent.parent / "cpapfit"


def package_imports() -> dict[str, set[str]]:
    """{subpackage: the other subpackages its modules import (relative imports)}."""
    edges = defaultdict(set)
    for path in PACKAGE.rglob("*.py"):
        folders = path.relative_to(PACKAGE).parts[:-1]
        if not folders:
            continue
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.ImportFrom) and node.level and node.module:
                target = [*folders[:len(folders) - node.level + 1], *node.module.split(".")]
                if target[0] != folders[0] and (PACKAGE / target[0]).is_dir():
                    edges[folders[0]].add(target[0])
    return edges


def test_no_two_subpackages_import_each_other():
    edges = package_imports()
    assert edges["align"] >= {"landmarks"} and edges["report"] >= {"evaluation"}  # the scan sees real imports
    assert [(a, b) for a in edges for b in edges[a] if a in edges.get(b, ())] == []
