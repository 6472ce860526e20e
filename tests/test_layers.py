"""The package's import graph follows the data: shared models below the stages, no stage
importing another stage, no lower layer importing a stage or anything above it.

Every import is read from the source with :mod:`ast`, those inside functions too (the lazy
ones), so a test fails on the line that crosses a layer, not on a cycle at run time.
"""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

PACKAGE = Path(__file__).resolve().parent.parent / "sr3d_cli"

# every top-level module or package of sr3d_cli, bottom to top; a unit may import its own
# modules and those of lower levels, and never a unit beside it on its own level
LEVELS = (
    ("__init__", "errors", "backends"),
    ("config",),
    ("geometry",),
    ("shape", "render", "onnx_model"),
    ("io",),
    ("segment", "reconstruct", "align", "repair", "grasp", "evaluate", "synth"),
    ("stages",),
    ("pipeline", "rerun_log", "pose_error"),
    ("cli",),
    ("__main__",),
)
LEVEL = {unit: level for level, units in enumerate(LEVELS) for unit in units}
STAGES = ("segment", "reconstruct", "align", "repair", "grasp")
LOWER = ("errors", "config", "geometry", "shape", "render", "onnx_model", "io")


def unit_of(module: str) -> str | None:
    """The top-level unit of a dotted name inside sr3d_cli (None: outside it); a name that
    is no module of it (``sr3d_cli.__version__``) is the package's own ``__init__``."""
    parts = module.split(".")
    if parts[0] != "sr3d_cli":
        return None
    if len(parts) == 1 or not ((PACKAGE / parts[1]).is_dir()
                               or (PACKAGE / f"{parts[1]}.py").is_file()):
        return "__init__"
    return parts[1]


def module_name(path: Path) -> str:
    parts = path.relative_to(PACKAGE.parent).with_suffix("").parts
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def imports(path: Path) -> list[tuple[int, str]]:
    """(line, module) of every import in a file, relative ones resolved; ``from a import b``
    counts as ``a.b`` (b may be a module)."""
    name = module_name(path)
    package = name if path.name == "__init__.py" else name.rpartition(".")[0]
    found = []
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"), str(path))):
        if isinstance(node, ast.Import):
            found += [(node.lineno, alias.name) for alias in node.names]
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                anchor = package.split(".")[:len(package.split(".")) - node.level + 1]
                base = ".".join(anchor + ([base] if base else []))
            found += [(node.lineno, f"{base}.{alias.name}") for alias in node.names]
    return found


def crossings() -> list[str]:
    """Every import that breaks a rule, as ``file:line: what``."""
    bad = []
    for path in sorted(PACKAGE.rglob("*.py")):
        here = unit_of(module_name(path))
        if here not in LEVEL:
            bad.append(f"{path.relative_to(PACKAGE.parent)}: {here} has no level in LEVELS")
            continue
        for line, target in imports(path):
            there = unit_of(target)
            if there is None or there == here:
                continue
            where = f"{path.relative_to(PACKAGE.parent)}:{line}: {here} imports {target}"
            if there not in LEVEL:
                bad.append(f"{where} (a unit with no level)")
            elif LEVEL[there] > LEVEL[here]:
                bad.append(f"{where} (a higher level)")
            elif LEVEL[there] == LEVEL[here]:
                bad.append(f"{where} (a unit beside it)")
    return bad


def test_imports_follow_the_layers():
    assert crossings() == []


def test_every_stage_sits_above_the_shared_layers():
    for stage in STAGES:
        assert all(LEVEL[stage] > LEVEL[low] for low in LOWER), stage


@pytest.mark.parametrize("source, target, rule", [
    ("segment/training_free.py", "sr3d_cli.reconstruct.library", "a unit beside it"),
    ("geometry/plane.py", "sr3d_cli.segment", "a higher level"),
    ("shape/revolution_fit.py", "sr3d_cli.align", "a higher level"),
    ("render.py", "sr3d_cli.pipeline", "a higher level"),
])
def test_a_crossing_import_is_caught(tmp_path, monkeypatch, source, target, rule):
    """The check finds an import that crosses, written in a copy of the package (lazily, inside
    a function, as a stage would hide it)."""
    import shutil

    copy = tmp_path / "sr3d_cli"
    shutil.copytree(PACKAGE, copy, ignore=shutil.ignore_patterns("__pycache__"))
    path = copy / source
    path.write_text(path.read_text(encoding="utf-8")
                    + f"\n\ndef _crossing():\n    import {target}\n", encoding="utf-8")
    monkeypatch.setitem(globals(), "PACKAGE", copy)
    found = crossings()
    assert len(found) == 1 and target in found[0] and rule in found[0]
