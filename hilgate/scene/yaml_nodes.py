"""YAML with a file and line on every value, so that every scene error can say where it is.

PyYAML's plain ``safe_load`` forgets positions and silently keeps the last of two duplicate keys.
Here the document is composed into nodes and turned into :class:`Node` objects that remember
``file:line``; scalars are still constructed by PyYAML's safe constructor (ints, floats, booleans,
null, strings exactly as ``safe_load`` reads them), anchors and ``<<`` merges work, and a duplicate
key is an error.

A scene is input from outside (and a daemon reads it on a reload), so every way YAML can be made to
eat time or memory is bounded here, and anything wrong is one :class:`SceneError` line:

- files larger than :data:`MAX_FILE_BYTES` are refused from their size, before they are read;
- nesting deeper than :data:`MAX_DEPTH` stops the composer (whose recursion would otherwise hit
  Python's limit) and the conversion (where aliases can nest further);
- aliases are expanded while converting, counting every node made: past :data:`MAX_NODES` ("billion
  laughs") the document is refused; an alias inside the node it names (``&r [*r]``) is refused;
- numbers longer than :data:`MAX_NUMBER_CHARS` characters are refused before Python converts them
  (a sexagesimal ``1:1:1:…`` or a 5 000-digit integer costs quadratic time or raises ValueError);
- every constructor failure (bad timestamp, unknown tag, bad base64) is a one-line error.
"""

from __future__ import annotations

import logging
import os
import re
import stat
from dataclasses import dataclass
from typing import Any, Iterator

import yaml
from yaml.nodes import MappingNode, ScalarNode, SequenceNode

__all__ = ["SceneError", "LimitError", "Node", "load_file", "load_text", "parse_scalar", "parse_value", "read_limited",
           "one_line", "size_text", "MAX_FILE_BYTES"]

log = logging.getLogger(__name__)

MAX_FILE_BYTES = 1 << 20      # 1 MiB: the largest shipped scene is 3 KB
MAX_DEPTH = 64                # mapping/list levels, aliases included
MAX_NODES = 100_000           # values made while expanding aliases and merges
MAX_NUMBER_CHARS = 1000       # a plain number longer than this is not a number anyone wrote
MAX_QUOTE = 256               # characters of a file name or key path kept in an error line
MAX_MESSAGE = 640             # characters of a message kept in an error line

_MERGE_TAG = "tag:yaml.org,2002:merge"
_VALUE_TAG = "tag:yaml.org,2002:value"
_NUMBER_TAGS = ("tag:yaml.org,2002:int", "tag:yaml.org,2002:float")
_COLLECTION_TAGS = ("tag:yaml.org,2002:map", "tag:yaml.org,2002:seq")


class SceneError(Exception):
    """A problem in a scene, printed as ``FILE:LINE: key.path: what is wrong`` — always one line of
    bounded length, whatever the file name, key or value it quotes."""

    def __init__(self, file: str, line: int, path: str, message: str):
        self.file = file
        self.line = line
        self.path = path
        self.message = message
        super().__init__(str(self))

    def __str__(self) -> str:
        file, path, message = one_line(self.file), one_line(self.path), one_line(self.message, MAX_MESSAGE)
        where = f"{file}:{self.line}" if self.line else file
        return f"{where}: {path}: {message}" if path else f"{where}: {message}"


class LimitError(SceneError):
    """The text breaks one of this module's limits (size, depth, values, number length): not a value
    anyone wrote, whether or not it is valid YAML."""


def one_line(text: str, limit: int = MAX_QUOTE) -> str:
    """``text`` with control and line-separator characters escaped, cut to ``limit`` characters:
    what a scene says can be quoted in an error without breaking it into lines or flooding a log."""
    text = str(text)
    if len(text) > limit:
        text = text[:limit] + "…"
    if text.isprintable():
        return text
    return "".join(c if c.isprintable() else c.encode("unicode_escape").decode("ascii") for c in text)


class _Mark:
    """Where a token starts: its line, the only thing an error here quotes.  PyYAML's own ``Mark`` keeps
    six fields and the buffer for every token, some 4 MB while a 250-modem scene is composed."""

    __slots__ = ("line",)

    def __init__(self, line: int):
        self.line = line

    def __str__(self) -> str:
        return f"line {self.line + 1}"


class _Loader(yaml.SafeLoader):
    """SafeLoader that also reads YAML 1.2 floats such as ``2.25e7`` and ``1e-3`` (YAML 1.1 insists on
    a dot and a signed exponent, so PyYAML would read them as text and a scene would fail to load),
    and whose composer refuses to nest deeper than :data:`MAX_DEPTH` (its recursion would otherwise
    end in a RecursionError somewhere in PyYAML)."""

    _depth = 0

    def get_mark(self) -> Any:
        return _Mark(self.line)

    def compose_node(self, parent: Any, index: Any) -> Any:
        self._depth += 1
        try:
            if self._depth > MAX_DEPTH:
                raise _Limit(self.peek_event().start_mark, f"nested deeper than {MAX_DEPTH} levels")
            return super().compose_node(parent, index)
        finally:
            self._depth -= 1


_Loader.add_implicit_resolver(
    "tag:yaml.org,2002:float",
    re.compile(r"^[-+]?(?:[0-9][0-9_]*\.?[0-9_]*|\.[0-9_]+)[eE][-+]?[0-9]+$"),
    list("-+0123456789."),
)


class _Limit(yaml.YAMLError):
    """A limit of this module was reached at ``mark``."""

    def __init__(self, mark: Any, message: str):
        super().__init__(message)
        self.mark = mark
        self.message = message


@dataclass
class Node:
    """A YAML value and where it was written. ``value`` is a dict of str → Node, a list of Node,
    or a plain scalar."""

    value: Any
    file: str
    line: int

    @property
    def is_map(self) -> bool:
        return isinstance(self.value, dict)

    @property
    def is_list(self) -> bool:
        return isinstance(self.value, list)

    def plain(self) -> Any:
        """The value with every Node stripped (for comparisons and error messages)."""
        if isinstance(self.value, dict):
            return {k: v.plain() for k, v in self.value.items()}
        if isinstance(self.value, list):
            return [v.plain() for v in self.value]
        return self.value

    def items(self) -> Iterator[tuple[str, "Node"]]:
        return iter(self.value.items())

    def error(self, path: str, message: str) -> SceneError:
        return SceneError(self.file, self.line, path, message)


def _short_tag(tag: str) -> str:
    return "!!" + tag[len("tag:yaml.org,2002:"):] if tag.startswith("tag:yaml.org,2002:") else tag


class _Builder:
    """Composes one document and converts it to :class:`Node` objects, within the module's limits."""

    def __init__(self, text: str, file: str):
        self.text = text
        self.file = file
        self.loader: _Loader | None = None
        self.made = 0                      # nodes made so far (aliases count each time they are used)
        self.open: set[int] = set()        # ids of the YAML nodes being converted (the current path)

    def error(self, line: int, message: str, path: str = "", kind: type[SceneError] = SceneError) -> SceneError:
        return kind(self.file, line, path, message)

    def build(self) -> Node | None:
        try:
            self.loader = _Loader(self.text)  # the reader checks every character here
            root = self.loader.get_single_node()
        except yaml.reader.ReaderError as exc:
            line = self.text.count("\n", 0, max(exc.position, 0)) + 1
            raise self.error(line, f"not valid YAML: control character #x{exc.character:02x} is not allowed "
                                   "(only tab, newline and printable characters)") from None
        except _Limit as exc:
            raise self.error(exc.mark.line + 1, exc.message, kind=LimitError) from None
        except yaml.MarkedYAMLError as exc:
            mark = exc.problem_mark or exc.context_mark
            line = mark.line + 1 if mark else 0
            raise self.error(line, f"not valid YAML: {exc.problem or exc.context}") from None
        except yaml.YAMLError as exc:
            raise self.error(0, f"not valid YAML: {exc}") from None
        except RecursionError:  # only if the caller's own stack was already deep
            raise self.error(0, "nested too deeply", kind=LimitError) from None
        finally:
            if self.loader is not None:
                self.loader.dispose()
        if root is None:
            return None
        return self.convert(root, "", 0)

    def convert(self, node: yaml.Node, path: str, depth: int) -> Node:
        line = node.start_mark.line + 1
        self.made += 1
        if self.made > MAX_NODES:
            raise self.error(line, f"aliases expand to more than {MAX_NODES} values", path, LimitError)
        if depth > MAX_DEPTH:
            raise self.error(line, f"nested deeper than {MAX_DEPTH} levels (through aliases)", path, LimitError)
        if isinstance(node, ScalarNode):
            return Node(self.scalar(node, path), self.file, line)
        if node.tag not in _COLLECTION_TAGS:
            raise self.error(line, f"unsupported tag {_short_tag(node.tag)!r}", path)
        if id(node) in self.open:
            raise self.error(line, "an alias refers to the value that contains it (a recursive alias)", path)
        self.open.add(id(node))
        try:
            if isinstance(node, MappingNode):
                return Node(self.mapping(node, path, depth), self.file, line)
            return Node([self.convert(item, f"{path}[{i}]", depth + 1) for i, item in enumerate(node.value)],
                        self.file, line)
        finally:
            self.open.discard(id(node))

    def mapping(self, node: MappingNode, path: str, depth: int) -> dict[str, Node]:
        """The mapping's own keys, over those it merges with ``<<`` (earlier merges win over later
        ones, as YAML's merge key says); a key given twice in the mapping itself is an error."""
        own: dict[str, Node] = {}
        merged: dict[str, Node] = {}
        for key_node, value_node in node.value:
            if key_node.tag == _MERGE_TAG:
                for key, value in self.merge(value_node, path, depth).items():
                    merged.setdefault(key, value)
                continue
            key = self.key(key_node, path)
            key_path = f"{path}.{key}" if path else key
            if key in own:
                raise self.error(key_node.start_mark.line + 1, f"duplicate key (first given on line {own[key].line})",
                                 key_path)
            converted = self.convert(value_node, key_path, depth + 1)
            converted.line = key_node.start_mark.line + 1  # where a reader looks for it
            own[key] = converted
        if not merged:
            return own
        merged.update(own)
        return merged

    def merge(self, value_node: yaml.Node, path: str, depth: int) -> dict[str, Node]:
        sources = value_node.value if isinstance(value_node, SequenceNode) else [value_node]
        result: dict[str, Node] = {}
        for source in sources:
            if not isinstance(source, MappingNode):
                raise self.error(source.start_mark.line + 1, "a merge key (<<) takes a mapping or a list of mappings",
                                 path)
            for key, value in self.convert(source, path, depth + 1).value.items():
                result.setdefault(key, value)
        return result

    def key(self, key_node: yaml.Node, path: str) -> str:
        line = key_node.start_mark.line + 1
        if not isinstance(key_node, ScalarNode):
            raise self.error(line, "a key must be a plain value", path)
        if key_node.tag == _VALUE_TAG:  # a key spelt "=" (PyYAML's flatten_mapping made it text too)
            return key_node.value
        key = self.scalar(key_node, path)
        if isinstance(key, bool) or not isinstance(key, (str, int, float)):
            raise self.error(line, f"a key must be a name, not {one_line(repr(key), 60)}", path)
        return str(key)

    def scalar(self, node: ScalarNode, path: str) -> Any:
        line = node.start_mark.line + 1
        if node.tag in _NUMBER_TAGS and len(node.value) > MAX_NUMBER_CHARS:
            raise self.error(line, f"a number longer than {MAX_NUMBER_CHARS} characters", path, LimitError)
        if node.tag not in type(self.loader).yaml_constructors:
            raise self.error(line, f"unsupported tag {_short_tag(node.tag)!r}", path)
        try:
            return self.loader.construct_object(node, deep=True)
        except yaml.MarkedYAMLError as exc:
            raise self.error(line, f"bad value for {_short_tag(node.tag)}: {exc.problem or exc.context}", path) from None
        except Exception as exc:  # PyYAML's constructors trust their input: ``!!int ''`` is an IndexError,
            # ``!!timestamp not-a-date`` an AttributeError, ``!!timestamp 2024-13-45`` a ValueError
            reason = str(exc) if type(exc) is ValueError else "not a valid value"
            raise self.error(line, f"bad value for {_short_tag(node.tag)}: {reason}", path) from None


def load_text(text: str, file: str = "<string>", limit: int = MAX_FILE_BYTES) -> Node | None:
    """Read YAML text into located nodes, or raise one :class:`SceneError`."""
    if len(text) > limit:
        raise LimitError(file, 0, "", f"larger than {size_text(limit)}; a scene or preset is a few KB")
    return _Builder(text, file).build()


def read_limited(path: str, limit: int, what: str = "file", expect: os.stat_result | None = None) -> str:
    """The text of the regular file at ``path``, at most ``limit`` bytes, else a :class:`SceneError`.

    Opened with O_NONBLOCK so that a FIFO swapped in after a caller's check cannot make the open
    wait for a writer; the file type and size are checked on the open descriptor (fstat) before a
    byte is read, and no more than ``limit + 1`` bytes are ever read.  ``expect``: the stat of the
    file the caller checked; a different file found at ``path`` now is refused."""
    try:
        # by name: a flag not every platform has
        fd = os.open(path, os.O_RDONLY | os.O_NONBLOCK | os.O_CLOEXEC | getattr(os, "O_NOCTTY", 0))
    except (OSError, ValueError) as exc:
        raise SceneError(path, 0, "", f"cannot read {what}: {_reason(exc)}") from None
    try:
        info = os.fstat(fd)
        if not stat.S_ISREG(info.st_mode):
            raise SceneError(path, 0, "", f"{what} is not a regular file")
        if expect is not None and (info.st_dev, info.st_ino) != (expect.st_dev, expect.st_ino):
            raise SceneError(path, 0, "", f"{what} was replaced while it was being read")
        if info.st_size > limit:
            raise SceneError(path, 0, "", f"{what} is larger than {size_text(limit)} ({info.st_size} bytes)")
        os.set_blocking(fd, True)
        chunks, size = [], 0
        while size <= limit:
            chunk = os.read(fd, min(1 << 16, limit + 1 - size))
            if not chunk:
                break
            chunks.append(chunk)
            size += len(chunk)
        if size > limit:
            raise SceneError(path, 0, "", f"{what} is larger than {size_text(limit)}")
    except OSError as exc:
        raise SceneError(path, 0, "", f"cannot read {what}: {_reason(exc)}") from None
    finally:
        os.close(fd)
    try:
        return b"".join(chunks).decode("utf-8")
    except UnicodeDecodeError as exc:
        raise SceneError(path, 0, "", f"not UTF-8 text: {exc.reason}") from None


def size_text(size: int) -> str:
    """``1 MB``, ``64 KB``: a limit as people say it."""
    if size >= 1 << 20 and size % (1 << 20) == 0:
        return f"{size >> 20} MB"
    return f"{size // 1024} KB" if size >= 1024 else f"{size} bytes"


def _reason(exc: BaseException) -> str:
    if isinstance(exc, OSError) and exc.strerror:
        return exc.strerror
    return str(exc) or type(exc).__name__


def load_file(path: str, limit: int = MAX_FILE_BYTES) -> Node | None:
    return load_text(read_limited(path, limit, "the scene"), path, limit)


def parse_value(text: str, what: str) -> Any:
    """A command-line value read as YAML (``10``, ``0.5``, ``[1, 2]``), within the limits of a file: a
    :class:`LimitError` naming ``what`` if it breaks one (20 000 nested brackets, a number of 100 000
    digits), the text itself if it is not YAML at all."""
    try:
        node = load_text(text, what)
    except LimitError:
        raise
    except SceneError:
        return text
    return None if node is None else node.plain()


def parse_scalar(text: str) -> Any:
    """A command-line value read the way YAML would read it (``3`` → 3, ``none`` → 'none', ``[1,2]``),
    within the same limits as a file; a value YAML cannot read stays text."""
    try:
        node = load_text(text, "--set")
    except SceneError:
        return text
    return None if node is None else node.plain()
