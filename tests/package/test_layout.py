"""The package's layout by role: imports run one way (hosts -> transport -> model -> backend), the engine never
imports a UI, and each of somwidget.frontend's folders holds what the README's map says it holds."""

from __future__ import annotations

import ast
from pathlib import Path

import helpers

PACKAGE = helpers.ROOT / "somwidget"
#: What each part may import from the package (besides itself). Hosts: web, notebook.
ALLOWED = {
    "backend": set(),
    "frontend.client": set(),
    "frontend.model": {"backend"},
    "frontend.transport": {"backend", "frontend.model"},
    "frontend.web": {"backend", "frontend.model", "frontend.transport", "frontend.client"},
    "frontend.notebook": {"backend", "frontend.model", "frontend.transport", "frontend.client"},
    # rooms sit above the model: a Session and a view hub each, a room's notebook view
    "frontend.studio": {"backend", "frontend.model", "frontend.transport", "frontend.web", "frontend.client",
                        "frontend.notebook"},
}


def _part(module: str) -> str | None:
    for part in sorted(ALLOWED, key=len, reverse=True):
        if module == part or module.startswith(part + "."):
            return part
    return None


def _imports(path: Path) -> set[str]:
    """The somwidget modules `path` imports (relative imports resolved), as dotted names under somwidget."""
    here = path.relative_to(PACKAGE).with_suffix("").parts
    package = here[:-1] if here[-1] != "__init__" else here[:-1]
    found = set()
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
        if isinstance(node, ast.ImportFrom):
            if node.level:
                base = package[: len(package) - (node.level - 1)] if node.level > 1 else package
                name = ".".join([*base, *(node.module.split(".") if node.module else [])])
            elif node.module and node.module.startswith("somwidget."):
                name = node.module[len("somwidget."):]
            else:
                continue
            found.add(name)
            found.update(f"{name}.{a.name}" for a in node.names)
        elif isinstance(node, ast.Import):
            found.update(a.name[len("somwidget."):] for a in node.names if a.name.startswith("somwidget."))
    return found


def test_imports_run_one_way():
    wrong = []
    for path in PACKAGE.rglob("*.py"):
        if "node_modules" in path.parts:
            continue
        own = _part(".".join(path.relative_to(PACKAGE).with_suffix("").parts))
        if own is None:
            continue
        for name in _imports(path):
            other = _part(name)
            if other is not None and other != own and other not in ALLOWED[own]:
                wrong.append(f"{path.relative_to(helpers.ROOT)} imports {name} ({own} may import "
                             f"{sorted(ALLOWED[own]) or 'nothing of the package'})")
    assert not wrong, "imports against the layout:\n" + "\n".join(sorted(wrong))


def test_no_ui_package_in_the_engine_or_the_model():
    ui = ("trame", "pyvista", "vtk", "ipywidgets", "anywidget", "aiohttp", "wslink")
    for folder in (PACKAGE / "backend", PACKAGE / "frontend" / "model"):
        for path in folder.rglob("*.py"):
            tree = ast.parse(path.read_text(encoding="utf-8"))
            top = [n for n in tree.body if isinstance(n, (ast.Import, ast.ImportFrom))]  # picture.py's are lazy
            for node in top:
                names = [a.name for a in node.names] if isinstance(node, ast.Import) else [node.module or ""]
                assert not any(n.split(".")[0] in ui for n in names), f"{path} imports a UI package: {names}"


def test_no_class_over_400_lines_and_no_module_over_600():
    """Sizes a newcomer can read: no class over 400 lines, no module over 600 (Warp's *_kernels.py aside)."""
    too_big = []
    for path in sorted(PACKAGE.rglob("*.py")):
        text = path.read_text(encoding="utf-8")
        name = path.relative_to(helpers.ROOT).as_posix()
        if text.count("\n") > 600 and not path.name.endswith("_kernels.py"):
            too_big.append(f"{name}: {text.count(chr(10))} lines")
        for node in ast.walk(ast.parse(text)):
            if isinstance(node, ast.ClassDef) and node.end_lineno - node.lineno + 1 > 400:
                too_big.append(f"{name}: class {node.name} {node.end_lineno - node.lineno + 1} lines")
    assert not too_big, too_big
