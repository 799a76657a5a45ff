"""Reading TOML that may come from anyone: bounded in bytes, nesting and keys.

A scene or a study file may come from a colleague or a paper's supplement, and
``--set`` values from a script.  ``tomllib`` itself recurses once per nested
array or inline table (thousands of levels end in ``RecursionError``), and it
keeps every prefix of a dotted key (a 40 KB key ``x.x.x...`` of 20 000 parts
takes seconds and gigabytes).  So before ``tomllib`` sees a text it is read
whole from a regular file only, at most :data:`MAX_BYTES` of it, decoded as
UTF-8, and scanned (:func:`check_text`, linear, no recursion) for its nesting
and its keys; after parsing, :func:`check_depth` walks the tables
iteratively for the depth they really have.

Every refusal is a :class:`TomlLimitError` (a ``ValueError``) whose message
says the rule and what was found; the callers turn it into their own error
naming the file (``cosim.scene.load.SceneError``).
"""
from __future__ import annotations

import os
import re
import stat
import tomllib

__all__ = ["TomlLimitError", "MAX_BYTES", "MAX_DEPTH", "MAX_KEYS", "read_toml", "loads",
           "check_text", "check_depth"]

#: most bytes a scene or study file may hold (64 MiB: a drive table of a
#: million points is about 40 MB)
MAX_BYTES = 64 * 2**20
#: most levels of tables and arrays below the top level (shipped scenes use 8)
MAX_DEPTH = 32
#: most keys a file may write, each part of a dotted key or a table header
#: counting as one (shipped scenes write fewer than 300)
MAX_KEYS = 10_000


class TomlLimitError(ValueError):
    """A TOML input that is not read: not a regular file, too large, not
    UTF-8, nested too deep or holding too many keys.  ``key`` is the key path
    where the limit was passed, when it is known, else ``""``."""

    def __init__(self, message: str, key: str = ""):
        self.key = key
        super().__init__(message)


_KINDS = ((stat.S_ISDIR, "a directory"), (stat.S_ISFIFO, "a named pipe (FIFO)"),
          (stat.S_ISCHR, "a character device"), (stat.S_ISBLK, "a block device"),
          (stat.S_ISSOCK, "a socket"))


def read_bytes(path, limit: int = MAX_BYTES) -> bytes:
    """The bytes of a regular file, refused past ``limit``.

    The file is opened without blocking (a FIFO would otherwise wait for a
    writer) and checked to be a regular file before anything is read; at
    most ``limit + 1`` bytes are read.

    Raises
    ------
    OSError
        If the file cannot be opened or read.
    TomlLimitError
        If it is not a regular file, or holds more than ``limit`` bytes.
    """
    fd = os.open(path, os.O_RDONLY | getattr(os, "O_NONBLOCK", 0))
    try:
        mode = os.fstat(fd).st_mode
        if not stat.S_ISREG(mode):
            kind = next((name for test, name in _KINDS if test(mode)), "not a regular file")
            raise TomlLimitError(f"must be a regular file, got {kind}")
        chunks, size = [], 0
        while size <= limit:
            chunk = os.read(fd, min(limit + 1 - size, 1 << 20))
            if not chunk:
                break
            chunks.append(chunk)
            size += len(chunk)
    finally:
        os.close(fd)
    if size > limit:
        raise TomlLimitError(f"must hold at most {limit} bytes ({limit / 2**20:g} MiB, "
                             f"`cosim.io.tomlread.MAX_BYTES`), got more")
    return b"".join(chunks)


def decode(data: bytes) -> str:
    """UTF-8 text of ``data``; a :class:`TomlLimitError` naming the line and
    column of the first byte that is not UTF-8."""
    try:
        return data.decode("utf-8")
    except UnicodeDecodeError as exc:
        line = data.count(b"\n", 0, exc.start) + 1
        column = exc.start - (data.rfind(b"\n", 0, exc.start) + 1) + 1
        raise TomlLimitError(f"must be UTF-8 text (TOML is), got byte "
                             f"0x{data[exc.start]:02x} at line {line}, column {column}"
                             ) from None


# --------------------------------------------------------------- the scanner
_STRINGS = (r'"""(?:[^"\\]|\\[\s\S]|"(?!""))*""""{0,2}'     # multi-line basic
            r"|'''[\s\S]*?''''{0,2}"                          # multi-line literal
            r'|"(?:[^"\\\n]|\\.)*"'                           # basic
            r"|'[^'\n]*'"                                     # literal
            r"|#[^\n]*")                                      # comment
_TOKEN = re.compile(_STRINGS + r"|[\[\]{}=.,\n\"']")
#: what the scan skips where a key is expected, after `=` (a value), and in an
#: array: runs of characters that cannot matter there (a C loop, not Python's)
_KEY = re.compile(r"[^\"'#\[\]{}=.,\n]*")
_VALUE = re.compile(r"[^\"'#\[\]{},\n]*")
_ARRAY = re.compile(r"[^\"'#\[\]{}]*")


def check_text(text: str, max_depth: int = MAX_DEPTH, max_keys: int = MAX_KEYS) -> None:
    """Scan TOML text for what would make ``tomllib`` recurse too deep or work
    too long: more than ``max_depth`` nested arrays and inline tables, a key
    or table header of more than ``max_depth`` parts, more than ``max_keys``
    key parts in all.  Linear in the text (numbers inside arrays are skipped
    by the regular expression); strings and comments are skipped whole.

    This is a guard, not a parser: what it lets through may still be invalid
    TOML, which ``tomllib`` then reports.

    Raises
    ------
    TomlLimitError
    """
    stack: list[str] = []           # open "[" (arrays) and "{" (inline tables)
    expect_key, header = True, False
    parts, keys, pos = 1, 0, 0

    def line() -> int:
        return text.count("\n", 0, pos) + 1

    def too_deep(what: str):
        raise TomlLimitError(f"must nest at most {max_depth} levels of tables and arrays "
                             f"(`cosim.io.tomlread.MAX_DEPTH`), got {what} at line {line()}")

    def count_key():
        nonlocal keys, parts
        keys += parts
        if keys > max_keys:
            raise TomlLimitError(f"must hold at most {max_keys} keys "
                                 f"(`cosim.io.tomlread.MAX_KEYS`; each part of a dotted key "
                                 f"counts), got more by line {line()}")
        parts = 1

    while True:
        in_array = bool(stack) and stack[-1] == "["
        rx = _ARRAY if in_array else _KEY if (expect_key or header) else _VALUE
        m = _TOKEN.match(text, rx.match(text, pos).end())
        if m is None:
            return
        pos, c = m.end(), m.group()[0]
        if c in "\"'#":
            continue            # a string (a key or a value), a comment, or a stray quote
        if header:                                   # [a.b] or [[a.b]]
            if c == ".":
                parts += 1
                if parts > max_depth:
                    too_deep(f"a table header of more than {max_depth} parts")
            elif c in "]\n":
                header = False
                count_key()
                expect_key = c == "\n"
            continue
        if c == "\n":
            if not stack:
                expect_key, parts = True, 1
        elif c == ".":                               # only scanned where a key is
            parts += 1
            if parts > max_depth:
                too_deep(f"a dotted key of more than {max_depth} parts")
        elif c == "=":
            count_key()
            expect_key = False
        elif c == "[":
            if not stack and expect_key:
                header, parts = True, 1
                continue
            stack.append("[")
        elif c == "{":
            stack.append("{")
            expect_key, parts = True, 1
        elif c in "]}":
            if stack:
                stack.pop()
            expect_key = False
        elif c == ",":
            if stack and stack[-1] == "{":
                expect_key, parts = True, 1
        if len(stack) > max_depth:
            too_deep(f"more than {max_depth} nested arrays or inline tables")


_NESTED = frozenset((dict, list))


def check_depth(data, max_depth: int = MAX_DEPTH) -> None:
    """Walk parsed tables and arrays iteratively; refuse ones nested deeper than
    ``max_depth`` levels below the top (dotted keys inside nested inline tables
    can go deeper than the scan sees).

    Raises
    ------
    TomlLimitError
        Its ``key`` is the key path (its first ``max_depth`` parts) where the
        limit was passed.
    """
    todo = [(data, 0, ())]
    while todo:
        node, depth, path = todo.pop()
        if isinstance(node, dict):
            items = node.items()
        elif _NESTED.isdisjoint(map(type, node)):   # an array of numbers: C speed
            continue
        else:
            items = enumerate(node)
        for k, v in items:
            if isinstance(v, (dict, list)):
                sub = path + (f"{k}" if isinstance(node, dict) else f"[{k}]",)
                if depth + 1 > max_depth:
                    key = ".".join(sub).replace(".[", "[")
                    raise TomlLimitError(f"must nest at most {max_depth} levels of tables and "
                                         f"arrays (`cosim.io.tomlread.MAX_DEPTH`), got deeper",
                                         key)
                todo.append((v, depth + 1, sub))


def loads(text: str) -> dict:
    """``tomllib.loads`` after :func:`check_text`, then :func:`check_depth`.

    Raises
    ------
    TomlLimitError
    tomllib.TOMLDecodeError
    """
    check_text(text)
    data = tomllib.loads(text)
    check_depth(data)
    return data


def read_toml(path) -> dict:
    """Read a TOML file within the limits: a regular file of at most
    :data:`MAX_BYTES`, UTF-8, nested at most :data:`MAX_DEPTH` levels, with at
    most :data:`MAX_KEYS` keys.

    Raises
    ------
    OSError
        If it cannot be opened or read.
    TomlLimitError
        If it passes a limit.
    tomllib.TOMLDecodeError
        If it is not TOML.
    """
    return loads(decode(read_bytes(path)))
