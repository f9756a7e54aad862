"""The house's rules, read from the code's imports: each floor imports only from the floors below
it (scenarios 4 -> mpc 3 -> twin 2 -> dem 1), and from another package only through a package's
face (its ``__init__``), never a module file of another package. And every data file in the
packages is installed with them, or named as the checkout's only."""

import ast
import sys
import tomllib
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


def module_of(path: Path, root: Path) -> str:
    parts = list(path.relative_to(root).with_suffix("").parts)
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def import_edges(root: Path) -> dict[str, set[str]]:
    """Module -> the project's modules it imports (at the top or inside functions; relative
    imports resolved; ``from pkg import name`` is an edge to ``pkg.name`` when that is a module)."""
    files = {module_of(p, root): p for pkg in FLOORS for p in (root / pkg).rglob("*.py")}
    edges = {}
    for mod, path in files.items():
        package = mod if path.name == "__init__.py" else mod.rpartition(".")[0]
        out = set()
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            if isinstance(node, ast.Import):
                targets = [a.name for a in node.names]
            elif isinstance(node, ast.ImportFrom):
                base = node.module or ""
                if node.level:
                    up = package.split(".")[: len(package.split(".")) - node.level + 1]
                    base = ".".join(up + ([base] if base else []))
                targets = [f"{base}.{a.name}" if f"{base}.{a.name}" in files else base for a in node.names]
            else:
                continue
            out |= {t for t in targets if t in files and t != mod}
        edges[mod] = out
    return edges


def cycles(edges: dict[str, set[str]]) -> list[list[str]]:
    """The strongly connected components of more than one module (Tarjan's algorithm)."""
    index, low, stack, on, out = {}, {}, [], set(), []

    def visit(v):
        index[v] = low[v] = len(index)
        stack.append(v)
        on.add(v)
        for w in sorted(edges.get(v, ())):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            comp = []
            while True:
                w = stack.pop()
                on.discard(w)
                comp.append(w)
                if w == v:
                    break
            if len(comp) > 1:
                out.append(sorted(comp))

    for v in sorted(edges):
        if v not in index:
            visit(v)
    return out


def test_no_two_modules_import_each_other():
    """No loop of imports between files, counting those inside functions (a loop hidden in a
    function is still two files that cannot be read one without the other)."""
    assert cycles(import_edges(ROOT)) == []


def test_the_loop_check_can_fail(tmp_path, monkeypatch):
    (tmp_path / "twin").mkdir()
    (tmp_path / "twin" / "__init__.py").write_text("")
    (tmp_path / "twin" / "a.py").write_text("def f():\n    from .b import g\n")
    (tmp_path / "twin" / "b.py").write_text("from twin import a\n")
    assert cycles(import_edges(tmp_path)) == [["twin.a", "twin.b"]]


#: data files in the package folders that are not installed: the checkout's tests and benchmarks
#: read them, the package does not
CHECKOUT_ONLY = {
    "scenarios/data/README.md": "says where the folder's data come from",
    "scenarios/data/molycop_ballsim_published.toml": "the published results the Moly-Cop test and benchmark "
                                                     "compare with",
    "scenarios/data/molycop_ballsim_425_published.toml": "the published results the second Moly-Cop case's test "
                                                         "and benchmark compare with",
}


def unshipped(root: Path) -> list[str]:
    """Data files (not Python) in the package folders that pyproject's package-data does not install
    (setuptools' globs, relative to each package's folder) and CHECKOUT_ONLY does not name. The
    test suite runs from the checkout, where every file is found; an installed grindtwin lacked
    twin/data/industrial_mill.json, and README's first command failed."""
    data = tomllib.loads((root / "pyproject.toml").read_text())["tool"]["setuptools"]["package-data"]
    shipped = {f for pkg, globs in data.items() for g in globs for f in (root / pkg.replace(".", "/")).glob(g)}
    found = [f for pkg in FLOORS for f in (root / pkg).rglob("*")
             if f.is_file() and f.suffix not in (".py", ".pyc") and "__pycache__" not in f.parts]
    return sorted(f.relative_to(root).as_posix() for f in found
                  if f not in shipped and f.relative_to(root).as_posix() not in CHECKOUT_ONLY)


def test_every_data_file_of_the_packages_is_installed():
    assert unshipped(ROOT) == []


def test_the_data_file_check_can_fail(tmp_path):
    (tmp_path / "pyproject.toml").write_text('[tool.setuptools.package-data]\n"twin.ore" = ["data/*.csv"]\n')
    for name in ("twin/ore/data/minerals.csv", "twin/data/industrial_mill.json"):
        (tmp_path / name).parent.mkdir(parents=True, exist_ok=True)
        (tmp_path / name).write_text("x")
    assert unshipped(tmp_path) == ["twin/data/industrial_mill.json"]
