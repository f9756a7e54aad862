"""The house's rules, read from the code's imports: each floor imports only from the floors below
it (scenarios 4 -> mpc 3 -> twin 2 -> dem 1), and from another package only through a package's
face (its ``__init__``), never a module file of another package."""

import ast
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
FLOORS = {"dem": 1, "twin": 2, "mpc": 3, "scenarios": 4}


def imports(path: Path):
    """(line, dotted module) of every absolute import in a file, including those inside functions."""
    tree = ast.parse(path.read_text(encoding="utf-8"))
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            for alias in node.names:
                yield node.lineno, alias.name
        elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
            yield node.lineno, node.module


def is_face(module: str) -> bool:
    """A package (a folder with an __init__.py), not a module file."""
    return (ROOT / module.replace(".", "/") / "__init__.py").is_file()


def violations(package: str) -> list[str]:
    out = []
    for path in sorted((ROOT / package).rglob("*.py")):
        for line, module in imports(path):
            top = module.split(".")[0]
            if top not in FLOORS or top == package:
                continue
            where = f"{path.relative_to(ROOT)}:{line} imports {module}"
            if FLOORS[top] > FLOORS[package]:
                out.append(f"{where}: floor {FLOORS[package]} may not import floor {FLOORS[top]}")
            elif not is_face(module):
                out.append(f"{where}: a module file of another package; import from its package's face")
    return out


@pytest.mark.parametrize("package", list(FLOORS))
def test_imports_go_down_the_floors_and_only_through_package_faces(package):
    assert violations(package) == []


def test_the_rule_can_fail(tmp_path, monkeypatch):
    """A module of twin importing mpc, and one of mpc importing twin's module file, are found."""
    fake = tmp_path / "twin"
    fake.mkdir()
    (fake / "__init__.py").write_text("")
    (fake / "bad.py").write_text("import mpc.nmpc\nfrom mpc import Controller\n")
    (tmp_path / "mpc").mkdir()
    (tmp_path / "mpc" / "__init__.py").write_text("")
    (tmp_path / "mpc" / "nmpc.py").write_text("from twin.bad import x\n")
    monkeypatch.setattr(sys.modules[__name__], "ROOT", tmp_path)
    assert len(violations("twin")) == 2
    assert violations("mpc") == ["mpc/nmpc.py:1 imports twin.bad: a module file of another package; "
                                 "import from its package's face"]
