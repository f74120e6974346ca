"""The house's size targets (issue 39, item 3), measured with ``ast`` alone: no function past cyclomatic
complexity 20, no module past 600 lines, no class past 300 lines, at most 8 modules at ``hilgate/``'s top.

Growth lands where it is easiest; these numbers make it land somewhere a newcomer can still walk. The
complexity is McCabe's, counted the way radon 6 counts it, so a number here is the number a reviewer's ``radon
cc`` prints (checked when this test was written: the same number for each of the 2 167 functions radon reported in
hilgate/, models/ and drivers/), without making radon a dependency: 1 per function, plus 1 per ``if``/``elif``,
conditional expression, ``assert``, loop (and its ``else``), ``except`` (and a ``try``'s ``else``), ``case``,
comprehension (and each of its ``if``s), and one per extra operand of ``and``/``or``; ``with`` adds nothing. A
function nested in another and a class's methods are counted each on their own (radon's closures).
"""

import ast
import os

import pytest

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
FOLDERS = ("hilgate", "models", "drivers")  # installed as hilgate, hilgate.models, hilgate.drivers

MAX_COMPLEXITY = 20
MAX_MODULE_LINES = 600
MAX_CLASS_LINES = 300
MAX_TOP_MODULES = 8

# Still past a target, by name (issue 39): each line is one leftover, visible here rather than excluded in bulk,
# with its measure when it was listed. Remove a line when its entry falls within the target
# (test_allow_list_has_no_stale_entries says when); never add a folder or a pattern.
ALLOWED_COMPLEXITY = {
    # on the frame's pass (tests/test_frame_path.py counts its calls): a split adds calls to every frame
    "hilgate/core/realtime.py:RealtimeScheduler._handle_inputs",  # 28
    "models/modem.py:SimModem.heard",  # 27
}
ALLOWED_MODULE_LINES: set[str] = set()
ALLOWED_CLASS_LINES = {
    # issue 39 item 2 (branch rooms): not split by its deadline (SimModem is on the frame's pass: a split must
    # keep its calls)
    "models/modem.py:SimModem",  # 345
}
ALLOWED_TOP_MODULES: set[str] = set()


def _decisions(node: ast.AST) -> int:
    """The decision points that ``node`` itself adds (its children are counted where they are visited)."""
    if isinstance(node, (ast.If, ast.IfExp, ast.Assert)):
        return 1
    if isinstance(node, (ast.For, ast.AsyncFor, ast.While)):
        return 1 + bool(node.orelse)
    if isinstance(node, ast.Try) or type(node).__name__ == "TryStar":
        return len(node.handlers) + bool(node.orelse)
    if isinstance(node, ast.BoolOp):
        return len(node.values) - 1
    if isinstance(node, ast.comprehension):
        return 1 + len(node.ifs)
    if isinstance(node, ast.match_case):
        return 1
    return 0


def complexity(function: ast.FunctionDef | ast.AsyncFunctionDef) -> int:
    """McCabe's number of ``function``: 1 plus every decision in its body outside nested functions and classes."""
    total = 1
    stack = list(ast.iter_child_nodes(function))
    while stack:
        node = stack.pop()
        if isinstance(node, (ast.ClassDef, ast.FunctionDef, ast.AsyncFunctionDef)):
            continue  # a function or class inside a function: counted on its own
        total += _decisions(node)
        if not isinstance(node, ast.Assert):  # an assert is one decision whatever its condition (radon's count)
            stack.extend(ast.iter_child_nodes(node))
    return total


def _source_files():
    for folder in FOLDERS:
        for dirpath, dirnames, files in os.walk(os.path.join(ROOT, folder)):
            dirnames[:] = sorted(d for d in dirnames if d != "__pycache__")
            for name in sorted(files):
                if name.endswith(".py"):
                    path = os.path.join(dirpath, name)
                    yield os.path.relpath(path, ROOT).replace(os.sep, "/"), path


def _parse(path: str) -> tuple[ast.Module, int]:
    with open(path, encoding="utf-8") as handle:
        text = handle.read()
    return ast.parse(text, path), len(text.splitlines())


def _functions(node: ast.AST, prefix=""):
    """(qualified name, node) of every function, method and nested function under ``node``."""
    for child in ast.iter_child_nodes(node):
        if isinstance(child, (ast.FunctionDef, ast.AsyncFunctionDef)):
            yield prefix + child.name, child
            yield from _functions(child, f"{prefix}{child.name}.")
        elif isinstance(child, ast.ClassDef):
            yield from _functions(child, f"{prefix}{child.name}.")
        else:
            yield from _functions(child, prefix)


def _classes(tree: ast.Module):
    for node in ast.walk(tree):
        if isinstance(node, ast.ClassDef):
            yield node.name, node


def measure():
    """Everything the targets speak of: {file: lines}, {file:function: complexity}, {file:class: lines}."""
    modules, functions, classes = {}, {}, {}
    for rel, path in _source_files():
        tree, lines = _parse(path)
        modules[rel] = lines
        for name, node in _functions(tree):
            functions[f"{rel}:{name}"] = complexity(node)
        for name, node in _classes(tree):
            key = f"{rel}:{name}"
            classes[key] = max(classes.get(key, 0), node.end_lineno - node.lineno + 1)
    return modules, functions, classes


def top_modules() -> list[str]:
    """hilgate/'s own modules at its top (``__init__`` and ``__main__`` are the package, not rooms of it)."""
    return sorted(name for name in os.listdir(os.path.join(ROOT, "hilgate"))
                  if name.endswith(".py") and name not in ("__init__.py", "__main__.py"))


MODULES, FUNCTIONS, CLASSES = measure()


def _over(measured: dict[str, int], limit: int, allowed: set[str]) -> list[str]:
    return [f"{name}: {value}" for name, value in sorted(measured.items()) if value > limit and name not in allowed]


def test_no_function_past_complexity_20():
    assert _over(FUNCTIONS, MAX_COMPLEXITY, ALLOWED_COMPLEXITY) == []


def test_no_module_past_600_lines():
    assert _over(MODULES, MAX_MODULE_LINES, ALLOWED_MODULE_LINES) == []


def test_no_class_past_300_lines():
    assert _over(CLASSES, MAX_CLASS_LINES, ALLOWED_CLASS_LINES) == []


def test_at_most_8_modules_at_hilgates_top():
    counted = [name for name in top_modules() if name not in ALLOWED_TOP_MODULES]
    assert len(counted) <= MAX_TOP_MODULES, counted


@pytest.mark.parametrize("measured, limit, allowed", [
    (FUNCTIONS, MAX_COMPLEXITY, ALLOWED_COMPLEXITY),
    (MODULES, MAX_MODULE_LINES, ALLOWED_MODULE_LINES),
    (CLASSES, MAX_CLASS_LINES, ALLOWED_CLASS_LINES),
], ids=["complexity", "module lines", "class lines"])
def test_allow_list_has_no_stale_entries(measured, limit, allowed):
    """An entry that no longer exceeds (or no longer exists) leaves the list, so the list stays the leftovers."""
    assert sorted(name for name in allowed if measured.get(name, 0) <= limit) == []


def test_top_allow_list_has_no_stale_entries():
    assert sorted(ALLOWED_TOP_MODULES - set(top_modules())) == []


def test_the_counter_counts_like_mccabe():
    source = '''
def f(a, b, items):
    if a and b or not a:
        pass
    elif b:
        pass
    for x in items:
        while x:
            x -= 1
        else:
            pass
    try:
        pass
    except ValueError:
        pass
    except KeyError:
        pass
    else:
        pass
    with open("x"):
        pass
    assert a
    y = [i for i in items if i if not i]
    z = 1 if a else 2
    match a:
        case 1:
            pass
        case _:
            pass
    def inner():
        if b:
            pass
    return lambda: a or b
'''
    function = ast.parse(source).body[0]
    # 1 + if(1) + and/or(2) + elif(1) + for(1) + while+else(2) + excepts+else(3) + with(0) + assert(1)
    # + comprehension and its 2 ifs(3) + ifexp(1) + 2 cases(2) + lambda's or(1) = 19; inner counts on its own
    assert complexity(function) == 19
    assert complexity(function.body[-2]) == 2
