"""The rooms and the arrows between them (docs/architecture.md), checked by walking every import with
``ast``: a wrong-way import fails here, not in a review."""

import ast
import os

import pytest

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
FOLDERS = {"hilgate": "hilgate", "models": "hilgate.models", "drivers": "hilgate.drivers"}

# room → the rooms it may import (besides itself, the standard library and third-party packages)
ALLOWED = {
    "hilgate.models": set(),
    "hilgate.core": {"hilgate.models"},  # only the broadcast address
    "hilgate.drivers": {"hilgate.core"},
    "hilgate.gli": {"hilgate.core"},
    "hilgate.scene": {"hilgate.core", "hilgate.models", "hilgate.drivers"},  # drivers: their option checks
    "hilgate.channel": {"hilgate.core", "hilgate.models"},  # BELLHOP as a program, its files, the cache
    "hilgate.sim": {"hilgate.core", "hilgate.models", "hilgate.scene", "hilgate.channel"},
    "hilgate.report": {"hilgate.core"},
    "hilgate.ros2": {"hilgate.core", "hilgate.gli"},  # gli: the Zenoh door's per-client bounds
    "hilgate.web": {"hilgate.core", "hilgate.report"},  # report: the trace reader the player uses, causes' words
    "hilgate.daemon": {"hilgate.core", "hilgate.models", "hilgate.scene", "hilgate.sim", "hilgate.gli",
                       "hilgate.drivers", "hilgate.ros2", "hilgate.web", "hilgate.channel"},
}


def modules():
    for folder, package in FOLDERS.items():
        for dirpath, dirnames, files in os.walk(os.path.join(ROOT, folder)):
            dirnames[:] = [d for d in dirnames if d != "__pycache__"]
            for name in files:
                if name.endswith(".py"):
                    path = os.path.join(dirpath, name)
                    rel = os.path.relpath(path, os.path.join(ROOT, folder))[:-3].replace(os.sep, ".")
                    module = package if rel == "__init__" else f"{package}.{rel.removesuffix('.__init__')}"
                    yield path, module, name == "__init__.py"


def imports_of(path: str, module: str, is_package: bool):
    tree = ast.parse(open(path, encoding="utf-8").read(), path)
    package = module if is_package else module.rpartition(".")[0]
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            for alias in node.names:
                yield node.lineno, alias.name
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = package.split(".")
                base = base[: len(base) - (node.level - 1)]
                target = ".".join(base + ([node.module] if node.module else []))
            else:
                target = node.module or ""
            if node.module is None or node.level and not node.module:
                for alias in node.names:  # from . import x: x may be a module
                    yield node.lineno, f"{target}.{alias.name}"
            else:
                yield node.lineno, target


def room_of(module: str) -> str | None:
    for room in sorted(ALLOWED, key=len, reverse=True):
        if module == room or module.startswith(room + "."):
            return room
    return None


def test_every_import_goes_the_right_way():
    wrong = []
    for path, module, is_package in modules():
        room = room_of(module)
        if room is None:
            continue  # hilgate/cli.py, hilgate/client.py, hilgate/__init__.py…: the top may import anything
        for line, target in imports_of(path, module, is_package):
            if not target.startswith("hilgate"):
                continue
            target_room = room_of(target)
            if target_room is None or target_room == room:
                if target_room is None and target not in ("hilgate", "hilgate.__version__"):
                    wrong.append(f"{os.path.relpath(path, ROOT)}:{line}: {room} imports {target}")
                continue
            if target_room not in ALLOWED[room]:
                wrong.append(f"{os.path.relpath(path, ROOT)}:{line}: {room} imports {target}")
    assert not wrong, "\n".join(wrong)


@pytest.mark.parametrize("name", ["hilgate.client.Link", "hilgate.scene.load_scene", "hilgate.models.modem.SimModem"])
def test_public_names_stay_importable(name):
    module, _, attribute = name.rpartition(".")
    assert getattr(__import__(module, fromlist=[attribute]), attribute)
