"""The house rules ARCHITECTURE.md states, checked: imports between rooms run one way, and
no function is longer than a screen."""

import ast
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
# Lowest first: a room may import its own modules and any room before it, never one after it.
LAYERS = [
    ("files", "checks", "threads", "heap"),
    ("aside",),
    ("pgd",),
    ("data",),
    ("physics",),
    ("synth", "fitting"),
    ("diagnosis",),
    ("reporting",),
    ("pipeline",),
    ("app",),
    ("map", "inject", "basis"),  # the Hydra faces, on what app.py shares
]
RANK = {room: rank for rank, rooms in enumerate(LAYERS) for room in rooms}
MODULES = sorted((ROOT / "ptwin").rglob("*.py"))


def room(module: Path) -> str:
    parts = module.relative_to(ROOT / "ptwin").with_suffix("").parts
    return parts[0]


def imported_rooms(module: Path):
    for node in ast.walk(ast.parse(module.read_text())):
        names = []
        if isinstance(node, ast.Import):
            names = [alias.name for alias in node.names]
        elif isinstance(node, ast.ImportFrom) and node.module:
            names = (
                [node.module + "." + alias.name for alias in node.names] if node.module == "ptwin" else [node.module]
            )
        for name in names:
            if name.startswith("ptwin."):
                yield name.split(".")[1], node.lineno


@pytest.mark.parametrize("module", MODULES, ids=lambda m: str(m.relative_to(ROOT)))
def test_imports_run_from_higher_rooms_to_lower_ones(module):
    here = room(module)
    if here == "__init__" or module.name == "__main__.py":  # the package's re-export and the rooms' own faces
        return
    for other, line in imported_rooms(module):
        if other in RANK and other != here:
            assert RANK[other] < RANK[here], f"{module.relative_to(ROOT)}:{line} imports ptwin.{other} from {here}"


def test_no_function_is_longer_than_80_lines():
    long = []
    for module in [*MODULES, ROOT / "train.py"]:
        for node in ast.walk(ast.parse(module.read_text())):
            if isinstance(node, ast.FunctionDef | ast.AsyncFunctionDef) and node.end_lineno - node.lineno + 1 > 80:
                long.append(f"{module.relative_to(ROOT)}:{node.lineno} {node.name}")
    assert not long


def test_the_hydra_face_is_thin():
    assert len((ROOT / "train.py").read_text().splitlines()) <= 100
