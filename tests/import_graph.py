"""The one reader of the package's import statements, shared by the tests that check the import rules.

Static: every import of every module is read from its source (function-local ones included: a local import that hides
an upward arrow is still that arrow), relative imports resolved, ``from a import b`` recorded with its names (``b``
may be a module), and the dynamic forms the package uses (``importlib.import_module("...")``, ``require("...")``)
counted as imports.
"""

from __future__ import annotations

import ast
from dataclasses import dataclass
from pathlib import Path

PACKAGE = Path(__file__).resolve().parent.parent / "wbc"
MODULE_FILES = sorted(PACKAGE.rglob("*.py"))


@dataclass(frozen=True)
class Import:
    """One import in a file.

    Attributes:
        module: the module named (``a`` of ``import a`` or ``from a import b``), relative imports resolved.
        names: what ``from module import ...`` took (empty for ``import module`` and the dynamic forms).
        line: its line.
        top_level: whether the statement is at the module's top level (not inside a function or a block).
    """

    module: str
    names: tuple[str, ...]
    line: int
    top_level: bool

    def modules(self) -> tuple[str, ...]:
        """The module and, for each name taken from it, ``module.name`` (which is a module when the name is one)."""
        return (self.module, *(f"{self.module}.{n}" for n in self.names if n != "*"))


def module_name(path: Path) -> str:
    """The dotted name of a file of the package (``wbc/a/__init__.py`` -> ``wbc.a``)."""
    rel = path.resolve().relative_to(PACKAGE.parent).with_suffix("")
    parts = rel.parts[:-1] if rel.name == "__init__" else rel.parts
    return ".".join(parts)


def imports(path: Path) -> list[Import]:
    """Every import of `path`, in the order of `ast.walk`."""
    name = module_name(path)
    package = name if path.name == "__init__.py" else name.rpartition(".")[0]
    return imports_of_text(path.read_text(encoding="utf-8"), package)


def imports_of_text(text: str, package: str) -> list[Import]:
    """Every import of a module's source `text`, in the order of `ast.walk`; relative ones resolved in `package`."""
    tree = ast.parse(text)
    top = set(map(id, tree.body))
    out = []
    for node in ast.walk(tree):
        at_top = id(node) in top
        if isinstance(node, ast.Import):
            out += [Import(a.name, (), node.lineno, at_top) for a in node.names]
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                parts = package.split(".")
                up = parts[: len(parts) - node.level + 1]
                base = ".".join([*up, base] if base else up)
            out.append(Import(base, tuple(a.name for a in node.names), node.lineno, at_top))
        elif (isinstance(node, ast.Call) and node.args and isinstance(node.args[0], ast.Constant)
              and isinstance(node.args[0].value, str)
              and ((isinstance(node.func, ast.Attribute) and node.func.attr == "import_module")
                   or (isinstance(node.func, ast.Name) and node.func.id in ("import_module", "require")))):
            out.append(Import(node.args[0].value, (), node.lineno, True))
    return out


def graph() -> dict[str, set[str]]:
    """Module -> the package's modules it imports (a name taken from a package counts when it is a module).

    A module's own ancestors are left out: importing ``a.b`` always runs ``a/__init__.py`` first, which is the
    package's structure and not an import the module chose.
    """
    names = {module_name(p): p for p in MODULE_FILES}
    out: dict[str, set[str]] = {m: set() for m in names}
    for name, path in names.items():
        ancestors = {".".join(name.split(".")[:n]) for n in range(1, name.count(".") + 1)}
        for imp in imports(path):
            for target in imp.modules():
                if target in names and target != name and target not in ancestors:
                    out[name].add(target)
    return out


def cycles(edges: dict[str, set[str]]) -> list[list[str]]:
    """The strongly connected components of more than one module (Tarjan's algorithm, iterative)."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    found: list[list[str]] = []
    counter = 0
    for root in sorted(edges):
        if root in index:
            continue
        work = [(root, iter(sorted(edges[root])))]
        index[root] = low[root] = counter
        counter += 1
        stack.append(root)
        on_stack.add(root)
        while work:
            node, children = work[-1]
            child = next(children, None)
            if child is not None:
                if child not in index:
                    index[child] = low[child] = counter
                    counter += 1
                    stack.append(child)
                    on_stack.add(child)
                    work.append((child, iter(sorted(edges[child]))))
                elif child in on_stack:
                    low[node] = min(low[node], index[child])
                continue
            work.pop()
            if work:
                low[work[-1][0]] = min(low[work[-1][0]], low[node])
            if low[node] == index[node]:
                component = []
                while True:
                    member = stack.pop()
                    on_stack.discard(member)
                    component.append(member)
                    if member == node:
                        break
                if len(component) > 1:
                    found.append(sorted(component))
    return found
