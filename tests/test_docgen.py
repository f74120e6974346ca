"""The generated reference (docs/commands.md's reference part, docs/scene-keys.md) is what
``tools/docgen.py`` writes from the code today: a new option, command or scene key fails here until
``python tools/docgen.py`` writes the pages again, so the reference never says something the code does not."""

import importlib.util
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parent.parent


def docgen():
    spec = importlib.util.spec_from_file_location("docgen", REPO / "tools" / "docgen.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


@pytest.mark.parametrize("page", ["commands.md", "scene-keys.md"])
def test_the_committed_reference_is_what_the_code_generates(page):
    generated = {path.name: text for path, text in docgen().pages().items()}
    committed = (REPO / "docs" / page).read_text(encoding="utf-8")
    assert committed == generated[page], f"docs/{page} is out of date: run python tools/docgen.py"


def test_every_command_and_every_driver_key_is_in_the_reference():
    from hilgate.cli import build_parser
    from hilgate.drivers.table import DRIVERS, scene_options

    commands = (REPO / "docs" / "commands.md").read_text(encoding="utf-8")
    for name, _, _ in docgen()._subcommands(build_parser()):
        assert f"### `hilgate {name}`" in commands
    keys = (REPO / "docs" / "scene-keys.md").read_text(encoding="utf-8")
    for name, driver in DRIVERS.items():
        line = next(line for line in keys.splitlines() if line.startswith(f"- `{name}`: "))
        for key, _, _ in scene_options(driver):
            assert f"`{key}` (" in line
