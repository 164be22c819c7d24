"""docs/architecture.md names every package and module of `wbc`, and no module that no longer exists.

Its index ("Every module") lists each `wbc/...py` file and each package folder `wbc/.../` in backticks; a module added
without a line there, or removed with its line left, fails here with the list of them.
"""

import re

from import_graph import MODULE_FILES, PACKAGE

ROOT = PACKAGE.parent
DOC = ROOT / "docs" / "architecture.md"
NAMED = re.compile(r"`(wbc/(?:[\w]+/)*(?:[\w]+\.py)?)`")


def doc_problems(doc_text: str, modules: list[str]) -> list[str]:
    """What the doc lacks of `modules` (``wbc/a/b.py``, a package as ``wbc/a/``) and what it lists beyond them."""
    named = set(NAMED.findall(doc_text))
    out = []
    missing = [m for m in modules if m not in named]
    if missing:
        out.append("docs/architecture.md does not name these modules of wbc; add each to the index ('Every module', "
                   "its docstring's first lines) and, for a package, to the layout: " + ", ".join(missing))
    stale = sorted(named - set(modules))
    if stale:
        out.append("docs/architecture.md names modules that do not exist; remove or rename them: " + ", ".join(stale))
    return out


def _modules() -> list[str]:
    out = []
    for path in MODULE_FILES:
        rel = path.relative_to(ROOT).as_posix()
        out.append(rel[: -len("__init__.py")] if path.name == "__init__.py" else rel)
    return out


def test_the_architecture_doc_names_every_module_and_package():
    problems = doc_problems(DOC.read_text(encoding="utf-8"), _modules())
    assert not problems, "\n".join(problems)


def test_a_missing_or_stale_module_is_listed():
    text = "| `wbc/` | the package |\n| `wbc/arena/compare.py` | run and compare |\n| `wbc/old.py` | gone |\n"
    assert doc_problems(text, ["wbc/", "wbc/arena/", "wbc/arena/compare.py", "wbc/arena/plot_style.py"]) == [
        "docs/architecture.md does not name these modules of wbc; add each to the index ('Every module', its "
        "docstring's first lines) and, for a package, to the layout: wbc/arena/, wbc/arena/plot_style.py",
        "docs/architecture.md names modules that do not exist; remove or rename them: wbc/old.py",
    ]
