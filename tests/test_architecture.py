"""The package's layout rules, read from the source (no imports executed):

- no import cycle between jaxcal's modules (imports inside functions count too);
- no module imports another module's underscore name;
- nothing but the command line (`_cli/`) and its test door (`internal/cli.py`) imports
  the command line, and importing `jaxcal` or `jaxcal.internal` does not load it;
- tests, benchmarks and notebooks use only public names and `jaxcal.internal`.
"""

from __future__ import annotations

import ast
import json
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
PKG = ROOT / "jaxcal"


def _module_name(path: Path) -> str:
    parts = list(path.relative_to(ROOT).with_suffix("").parts)
    if parts[-1] == "__init__":
        parts = parts[:-1]
    return ".".join(parts)


MODULES = {_module_name(p): p for p in sorted(PKG.rglob("*.py"))}


def _resolve(module: str, level: int, target: str | None) -> str:
    is_package = MODULES[module].name == "__init__.py"
    base = module.split(".") if is_package else module.split(".")[:-1]
    if level > 1:
        base = base[: len(base) - (level - 1)]
    return ".".join(base + ([target] if target else []))


def _imports(module: str):
    """(imported module, imported name) for every relative import of `module`; a
    name that is itself a module (`from . import x`) resolves to that module."""
    tree = ast.parse(MODULES[module].read_text())
    for node in ast.walk(tree):
        if isinstance(node, ast.ImportFrom) and node.level > 0:
            src = _resolve(module, node.level, node.module)
            for alias in node.names:
                sub = f"{src}.{alias.name}"
                yield (sub, None) if sub in MODULES else (src, alias.name)


def test_modules_found():
    assert "jaxcal._model.equilibrium" in MODULES
    assert len(MODULES) > 40


def test_no_import_cycle():
    graph = {m: {t for t, _ in _imports(m) if t in MODULES} for m in MODULES}
    # A package's `__init__` imports its modules; a module importing its own package's
    # names would close a loop through it, so such edges count as cycles too.
    state: dict[str, int] = {}
    cycle: list[str] = []

    def visit(m: str, stack: list[str]) -> bool:
        state[m] = 1
        for t in sorted(graph[m]):
            if state.get(t) == 1:
                cycle.extend(stack[stack.index(t) :] + [m, t] if t in stack else [m, t])
                return True
            if t not in state and visit(t, [*stack, m]):
                return True
        state[m] = 2
        return False

    for m in sorted(graph):
        if m not in state and visit(m, []):
            break
    assert not cycle, " -> ".join(cycle)


def test_no_underscore_name_imported_from_another_module():
    bad = [
        f"{m} imports {name} from {src}"
        for m in MODULES
        for src, name in _imports(m)
        if name is not None and name.startswith("_") and name != "__version__"
    ]
    assert not bad, "\n".join(bad)


def test_library_never_imports_the_cli():
    allowed = ("jaxcal._cli", "jaxcal.internal.cli")
    bad = [
        f"{m} imports {src}"
        for m in MODULES
        if not m.startswith(allowed) and m != "jaxcal.__main__"
        for src, _ in _imports(m)
        if src == "jaxcal._cli" or src.startswith("jaxcal._cli.")
    ]
    assert not bad, "\n".join(bad)


def test_importing_the_library_does_not_load_the_cli():
    code = (
        "import sys, jaxcal, jaxcal.internal; "
        "print(sorted(m for m in sys.modules if m.startswith('jaxcal._cli')))"
    )
    out = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, check=True, cwd=ROOT
    )
    assert out.stdout.strip() == "[]"


def _external_sources():
    for folder in ("tests", "benchmarks", "notebooks"):
        for p in sorted((ROOT / folder).glob("*.py")):
            yield p, p.read_text()
    for p in sorted((ROOT / "notebooks").glob("*.ipynb")):
        cells = json.loads(p.read_text())["cells"]
        code = "\n".join("".join(c["source"]) for c in cells if c["cell_type"] == "code")
        yield p, "\n".join(ln for ln in code.splitlines() if not ln.lstrip().startswith(("%", "!")))


@pytest.mark.parametrize(
    "path,text", list(_external_sources()), ids=lambda v: getattr(v, "name", "")
)
def test_users_of_the_package_import_public_or_internal_names(path, text):
    bad = []
    for node in ast.walk(ast.parse(text)):
        if (
            isinstance(node, ast.ImportFrom)
            and node.module
            and node.module.split(".")[0] == "jaxcal"
        ):
            private_path = any(p.startswith("_") for p in node.module.split("."))
            private_name = any(a.name.startswith("_") for a in node.names)
            if private_path or private_name:
                bad.append(f"line {node.lineno}: from {node.module} import ...")
        if isinstance(node, ast.Import):
            bad += [f"line {node.lineno}: import {a.name}" for a in node.names if "._" in a.name]
        if isinstance(node, ast.Attribute) and isinstance(node.value, ast.Name):
            if (
                node.value.id == "jaxcal"
                and node.attr.startswith("_")
                and node.attr != "__version__"
            ):
                bad.append(f"line {node.lineno}: jaxcal.{node.attr}")
    assert not bad, f"{path.name}:\n" + "\n".join(bad)
