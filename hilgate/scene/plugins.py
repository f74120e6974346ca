"""Plugins: user code that a scene may run, loaded only when it is listed.

A scene (``plugins:``) or the command line (``--plugin``) lists each plugin as either

- a ``.py`` file (relative to the scene's file, or to the working directory for ``--plugin``): it is
  executed with :func:`importlib.util.spec_from_file_location` under a private module name, so it
  never shadows, or is shadowed by, an installed module, and neither its folder nor the working
  directory is put on ``sys.path``; or
- an importable module name (an installed package), found on ``sys.path`` — but never in the working
  directory, which ``python -m hilgate`` would otherwise search first.

Nothing else is ever imported on a scene's behalf: a MAC protocol that is not built in must be a
class of a listed plugin.  A plugin is referred to by its module name, or by its file's name without
``.py``; a plugin's MAC classes are found by their ``name`` attribute too.
"""

from __future__ import annotations

import importlib
import importlib.util
import logging
import os
import re
import stat
import sys
from dataclasses import dataclass
from types import ModuleType

__all__ = ["Plugin", "PluginError", "load_plugin", "classes_of"]

log = logging.getLogger(__name__)

PRIVATE_PREFIX = "_hilgate_plugin_"
MODULE_NAME = re.compile(r"[A-Za-z_][A-Za-z0-9_]*(?:\.[A-Za-z_][A-Za-z0-9_]*)*")
FILE_NAME = re.compile(r"[A-Za-z_][A-Za-z0-9_]*")

_loaded_files: dict[tuple[str, int, int], "Plugin"] = {}  # (real path, mtime_ns, size) → plugin


class PluginError(Exception):
    """Why a plugin could not be loaded, in one line."""


@dataclass(frozen=True)
class Plugin:
    name: str            # how a scene refers to it: ``name:Class``
    source: str          # the file it was read from, or the module name
    module: ModuleType


def load_plugin(entry: str, base_dir: str) -> Plugin:
    """Load the plugin ``entry`` (a ``.py`` file relative to ``base_dir``, or a module name)."""
    if "\0" in entry:
        raise PluginError("a plugin cannot contain a NUL character")
    if entry.endswith(".py") or "/" in entry or os.sep in entry:
        return _load_file(os.path.normpath(os.path.join(base_dir, entry)))
    if os.path.isfile(os.path.join(base_dir, entry)):
        raise PluginError("a plugin file must be a .py file")
    if not MODULE_NAME.fullmatch(entry):
        raise PluginError("not a module name (package.module) nor a .py file")
    return _load_module(entry)


def _load_file(path: str) -> Plugin:
    if not path.endswith(".py"):
        raise PluginError("a plugin file must be a .py file")
    stem = os.path.basename(path)[:-3]
    if not FILE_NAME.fullmatch(stem):
        raise PluginError(f"a plugin file's name must be a Python name (letters, digits, _), not {stem!r}")
    real = os.path.realpath(path)
    try:
        info = os.stat(real)
    except OSError as exc:
        raise PluginError(f"cannot read {path}: {exc.strerror or exc}") from None
    if not stat.S_ISREG(info.st_mode):
        raise PluginError(f"{path} is not a regular file")
    key = (real, info.st_mtime_ns, info.st_size)
    if key in _loaded_files:
        return _loaded_files[key]
    import hashlib  # here, not at the top: OpenSSL's libcrypto is 3.7 MB of every simulation, few load plugins

    name = f"{PRIVATE_PREFIX}{stem}_{hashlib.sha1(real.encode()).hexdigest()[:10]}"
    spec = importlib.util.spec_from_file_location(name, real)
    if spec is None or spec.loader is None:
        raise PluginError(f"cannot load {path} as Python")
    module = importlib.util.module_from_spec(spec)
    previous = sys.modules.get(name)
    sys.modules[name] = module  # as an import would: dataclasses and pickle look a class's module up here
    try:
        spec.loader.exec_module(module)
    except BaseException as exc:  # the plugin's own code failed: say so, keep running
        if isinstance(exc, KeyboardInterrupt):
            raise
        _restore(name, previous)
        raise PluginError(f"{path} failed: {_describe(exc)}") from None
    plugin = Plugin(stem, real, module)
    _loaded_files[key] = plugin
    log.info("plugin %s loaded from %s", stem, real)
    return plugin


def _load_module(name: str) -> Plugin:
    top = name.partition(".")[0]
    if top not in sys.modules:
        try:
            spec = importlib.util.find_spec(top)
        except (ImportError, ValueError) as exc:
            raise PluginError(_describe(exc)) from None
        if spec is None:
            raise PluginError(f"no module named {top!r} (a plugin is an installed module or a .py file "
                              "relative to the scene)")
        if _in_working_directory(spec):
            raise PluginError(f"module {top!r} is found only in the working directory, which is never "
                              f"searched for plugins; list the file ({top}.py) instead")
    try:
        module = importlib.import_module(name)
    except BaseException as exc:
        if isinstance(exc, KeyboardInterrupt):
            raise
        raise PluginError(f"importing {name} failed: {_describe(exc)}") from None
    return Plugin(name, name, module)


def _in_working_directory(spec: importlib.machinery.ModuleSpec) -> bool:
    """Whether ``spec`` was found through the working directory's entry on ``sys.path`` (``''``, or the
    directory itself, which ``python -m`` puts first)."""
    cwd = os.path.realpath(os.getcwd())
    if not any(entry in ("", ".") or os.path.realpath(entry) == cwd for entry in sys.path if isinstance(entry, str)):
        return False
    places = list(spec.submodule_search_locations or [])
    if not places and spec.origin and os.path.isabs(spec.origin):
        places = [spec.origin]
    return bool(places) and all(os.path.realpath(os.path.dirname(p)) == cwd for p in places)


def _restore(name: str, previous: ModuleType | None) -> None:
    if previous is None:
        sys.modules.pop(name, None)
    else:
        sys.modules[name] = previous


def _describe(exc: BaseException) -> str:
    text = str(exc).strip().replace("\n", " ")
    return f"{type(exc).__name__}: {text}" if text else type(exc).__name__


def classes_of(plugin: Plugin, base: type) -> dict[str, type]:
    """The subclasses of ``base`` that the plugin defines itself (not those it imports), by name."""
    module = plugin.module
    return {attr: value for attr, value in vars(module).items()
            if isinstance(value, type) and issubclass(value, base) and value is not base
            and value.__module__ == module.__name__}


def origin_of(cls: type) -> str:
    """Where a plugin's class comes from, to find it again in another process: the plugin file's real
    path (its module name is private to the process that loaded it), or the installed module's name."""
    module = sys.modules.get(cls.__module__)
    # by name: a module built in memory has no file
    if cls.__module__.startswith(PRIVATE_PREFIX) and module is not None and getattr(module, "__file__", None):
        return os.path.realpath(module.__file__)
    return cls.__module__


def class_from_origin(origin: str, qualname: str) -> type:
    """The class :func:`origin_of` described, loaded (once) in this process the way the scene did."""
    plugin = load_plugin(origin, "/") if os.path.isabs(origin) else load_plugin(origin, os.getcwd())
    target: object = plugin.module
    for part in qualname.split("."):
        target = getattr(target, part, None)  # (by name: a dotted name the scene wrote)
    if not isinstance(target, type):
        raise PluginError(f"{origin} has no class {qualname}")
    return target
