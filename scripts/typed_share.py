"""The share of functions in somwidget/ with complete type hints (every parameter but self/cls, and the return).

Warp's @wp.kernel and @wp.func functions are left out (Warp types them already). Usage:
    python scripts/typed_share.py [--list] [root]
--list prints each function that lacks a hint (path:line name).
"""

from __future__ import annotations

import ast
import sys
from pathlib import Path


def _is_warp(node: ast.FunctionDef | ast.AsyncFunctionDef) -> bool:
    """Decorated @wp.kernel / @wp.func (also called: @wp.kernel(enable_backward=False))."""
    for d in node.decorator_list:
        target = d.func if isinstance(d, ast.Call) else d
        if isinstance(target, ast.Attribute) and target.attr in ("kernel", "func", "func_native", "func_grad"):
            return True
    return False


def _typed(node: ast.FunctionDef | ast.AsyncFunctionDef, method: bool) -> bool:
    a = node.args
    params = [*a.posonlyargs, *a.args, *a.kwonlyargs]
    if method and params and params[0].arg in ("self", "cls"):
        params = params[1:]
    params += [p for p in (a.vararg, a.kwarg) if p is not None]
    return node.returns is not None and all(p.annotation is not None for p in params)


def functions(root: Path) -> list[tuple[str, int, str, bool]]:
    """(path, line, name, typed) of every function under root, Warp's aside."""
    out = []
    for path in sorted(root.rglob("*.py")):
        tree = ast.parse(path.read_text(encoding="utf-8"), str(path))
        parents: dict[ast.AST, ast.AST] = {}
        for parent in ast.walk(tree):
            for child in ast.iter_child_nodes(parent):
                parents[child] = parent
        for node in ast.walk(tree):
            if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)) and not _is_warp(node):
                method = isinstance(parents.get(node), ast.ClassDef)
                out.append((str(path), node.lineno, node.name, _typed(node, method)))
    return out


def main(argv: list[str]) -> int:
    listing = "--list" in argv
    args = [a for a in argv if a != "--list"]
    root = Path(args[0] if args else Path(__file__).resolve().parent.parent / "somwidget")
    found = functions(root)
    typed = sum(t for *_, t in found)
    if listing:
        for path, line, name, t in found:
            if not t:
                print(f"{path}:{line} {name}")
    print(f"{typed} of {len(found)} functions typed in {root.name}/: {100 * typed / max(1, len(found)):.1f}%")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
