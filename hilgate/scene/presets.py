"""Modem presets: ``model: s100`` on a link, a packaged ``models/s100.yaml`` or a file of the user's.

A preset holds modem keys only (:data:`MODEM_KEYS`); the link's own keys override it one level deep
(:func:`merge`).  A preset file is read only if it is a small ``.yaml`` file under the scene's
directory or a ``--preset-dir``, so a scene cannot make hilgate read (and quote in an error) any file
its user may not.
"""

from __future__ import annotations

import os
import stat

from .checks import Fields, base_dir, quote, text
from .yaml_nodes import Node, SceneError, load_text, read_limited, size_text

__all__ = ["MODEM_KEYS", "preset_names", "load_preset", "merge"]

MODEM_KEYS = (
    "bitrate_bps", "tx_delay_s", "rx_delay_s", "tx_jitter_s", "rx_jitter_s", "fifo_bytes", "range_m",
    "error", "mac", "packet", "duplex", "promiscuous", "ack_bytes", "ack_turnaround_s", "acoustic",
    "firmware", "limits",
)
PRESET_SUFFIXES = (".yaml", ".yml")
MAX_PRESET_BYTES = 64 * 1024


def preset_names() -> list[str]:
    import importlib.resources  # here: with tempfile and shutil it is 2 MB of every process, needed by scenes with presets

    folder = importlib.resources.files("hilgate.models")
    return sorted(p.name[:-5] for p in folder.iterdir() if p.name.endswith(".yaml"))


def load_preset(name_node: Node, path: str, scene_dir: str, preset_dirs: tuple[str, ...] = ()) -> Node:
    """A packaged preset by name, or a preset file the scene may read (see :func:`_preset_file`)."""
    name = text(name_node, path)
    if name in preset_names():
        import importlib.resources

        resource = importlib.resources.files("hilgate.models") / f"{name}.yaml"
        node = load_text(resource.read_text(encoding="utf-8"), f"models/{name}.yaml")
    elif name.endswith(PRESET_SUFFIXES) or "/" in name or os.sep in name:
        file, real, info = _preset_file(name_node, path, name, scene_dir, preset_dirs)
        try:
            node = load_text(read_limited(real, MAX_PRESET_BYTES, "the preset", expect=info), file, MAX_PRESET_BYTES)
        except SceneError as exc:
            if exc.line or exc.file != real:
                raise
            raise name_node.error(path, exc.message) from None
    else:
        raise name_node.error(path, f"unknown modem model {quote(name)}; presets: {', '.join(preset_names())} "
                                    "(or a .yaml file of your own in the scene's directory)")
    if node is None or not node.is_map:
        raise SceneError(node.file if node else name, node.line if node else 0, "", "a modem preset must be a mapping of link keys")
    Fields(node, "", MODEM_KEYS)
    return node


def _preset_file(node: Node, path: str, name: str, scene_dir: str,
                 preset_dirs: tuple[str, ...]) -> tuple[str, str, os.stat_result]:
    """Where a preset file is, checked before it is opened: a ``.yaml``/``.yml`` regular file of at most
    64 KB whose real path (symbolic links resolved) lies under the scene's directory or a
    ``--preset-dir``.  Anything else (``/etc/shadow``, ``/dev/zero``, a FIFO) is refused unread, so no
    error can show a line of it.  Returns (the path as named, its real path, its stat)."""
    if "\0" in name:
        raise node.error(path, "a path cannot contain a NUL character")
    if not name.endswith(PRESET_SUFFIXES):
        raise node.error(path, "a preset file must end in .yaml or .yml")
    file = os.path.normpath(os.path.join(base_dir(node), name))
    real = os.path.realpath(file)
    roots = [os.path.realpath(folder) for folder in (scene_dir, *preset_dirs)]
    if not any(_inside(real, root) for root in roots):
        raise node.error(path, f"preset {quote(name)} is outside the scene's directory {scene_dir}"
                               + (" and the --preset-dir directories" if preset_dirs else "")
                               + " (add its directory with --preset-dir)")
    try:
        info = os.stat(real)
    except OSError as exc:
        raise node.error(path, f"cannot read preset {quote(name)}: {exc.strerror or exc}") from None
    if not stat.S_ISREG(info.st_mode):
        raise node.error(path, f"preset {quote(name)} is not a regular file")
    if info.st_size > MAX_PRESET_BYTES:
        raise node.error(path, f"preset {quote(name)} is larger than {size_text(MAX_PRESET_BYTES)}")
    return file, real, info


def merge(base: Node, override: Node) -> Node:
    """Key-by-key override, one level into nested mappings (``error``, ``mac``)."""
    if not (base.is_map and override.is_map):
        return override
    merged = dict(base.value)
    for key, value in override.items():
        if key == "error" and key in merged and _error_kind(merged[key]) != _error_kind(value):
            merged[key] = value  # another kind of error model: none of the preset's keys apply
            continue
        merged[key] = merge(merged[key], value) if key in merged else value
    return Node(merged, override.file, override.line)


def _error_kind(node: Node) -> object:
    kind = node.value.get("kind") if node.is_map else None
    return "expr" if kind is None else kind.value


def _inside(path: str, folder: str) -> bool:
    return path == folder or path.startswith(folder.rstrip(os.sep) + os.sep)
