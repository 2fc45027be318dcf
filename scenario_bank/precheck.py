"""Bounded checks of untrusted Scenic text, run before anything parses it.

Everything here is a single linear pass over the text with fixed limits: no
recursion, no parser, no import of the rest of dv2s-gym, so the user's process
may run it on any input (the full allowlist, :mod:`scenario_bank.safety`, parses
and runs where the script is compiled). :func:`precheck_text` refuses:

* more than :data:`MAX_SCRIPT_BYTES` bytes, :data:`MAX_LINES` lines, a physical
  line longer than :data:`MAX_LINE_CHARS` characters or a logical line (one
  statement, continued over brackets or backslashes) longer than
  :data:`MAX_LOGICAL_LINE_CHARS` (Scenic's parser is pure Python: one huge
  expression takes minutes to parse);
* brackets nested deeper than :data:`MAX_NESTING` (counted in code and inside
  f-strings, whose fields are code; deep nesting overflows the parser's stack)
  and runs of more than :data:`MAX_OPERATOR_RUN` prefix operators (``- - - x``,
  ``not not x``), which recurse the same way without brackets;
* bytes that are not strict UTF-8, a byte-order mark, NUL and other control
  characters (but tab, newline, carriage return and form feed);
* a PEP 263 coding declaration naming anything but UTF-8 (``# -*- coding: utf-7 -*-``
  makes Python read different code than a text check sees);
* Unicode bidirectional controls (``Trojan Source``: the code read differs from
  the code shown), zero-width and other invisible format characters, and
  Unicode line separators that Python does not treat as line ends but editors do.

Each refusal is an :class:`UnsafeScenarioError` (:class:`PrecheckError`) naming
the line, the problem and the fix.
"""

from __future__ import annotations

import re
import unicodedata
from dataclasses import dataclass
from typing import List, Union

from scenario_bank.errors import DV2SError, WrongTypeError

__all__ = [
    "MAX_SCRIPT_BYTES",
    "MAX_LINES",
    "MAX_LINE_CHARS",
    "MAX_LOGICAL_LINE_CHARS",
    "MAX_NESTING",
    "MAX_OPERATOR_RUN",
    "SafetyFinding",
    "UnsafeScenarioError",
    "PrecheckError",
    "precheck_text",
]

MAX_SCRIPT_BYTES = 128 * 1024
"""Largest script accepted: 15 times the biggest shipped or corpus script (about 9 KB). Scenic's parser
takes about 0.3 ms per character, so this bounds a parse to under a minute."""
MAX_LINES = 5000
"""Most lines a script may have."""
MAX_LINE_CHARS = 1000
"""Longest physical line (the corpus's longest is 195)."""
MAX_LOGICAL_LINE_CHARS = 4000
"""Longest statement, over all the physical lines it continues on (the corpus's longest is 1375, a docstring).
Parsing one statement costs more per character than many short ones: 4000 characters take a few seconds."""
MAX_NESTING = 50
"""Deepest nesting of brackets (``()``, ``[]``, ``{}``); the corpus nests 4 deep, and Scenic's parser
already runs out of recursion at about 25."""
MAX_OPERATOR_RUN = 20
"""Most prefix operators (``-``, ``+``, ``~``, ``not``) in a row."""

_CODING = re.compile(rb"^[ \t\f]*#.*?coding[:=][ \t]*([-\w.]+)")
_UTF8_NAMES = {"utf_8", "utf8", "u8", "utf"}
_ALLOWED_CONTROLS = {"\t", "\n", "\r", "\f"}
_EXTRA_LINE_BREAKS = {"\u0085", "\u2028", "\u2029", "\x1c", "\x1d", "\x1e", "\x0b"}
_OPEN, _CLOSE = "([{", ")]}"
_PREFIX_OPERATORS = set("-+~")
_STRING_PREFIX = re.compile(r"[rRbBuUfF]{0,2}$")


@dataclass(frozen=True)
class SafetyFinding:
    """One reason a script is unsafe: where, what and why."""

    line: int
    construct: str
    reason: str

    def __str__(self) -> str:
        return f"line {self.line}: {self.construct}: {self.reason}"


class UnsafeScenarioError(DV2SError, ValueError):
    """A script failed the safety check; ``findings`` lists why."""

    def __init__(self, findings: List[SafetyFinding], label: str = "<script>") -> None:
        self.findings = findings
        lines = "; ".join(str(f) for f in findings[:5])
        more = f" (and {len(findings) - 5} more)" if len(findings) > 5 else ""
        super().__init__(
            f"{label} failed the safety check: {lines}{more}. Scenic scripts run by dv2s-gym may only use Scenic's "
            "driving domain and world models, math and a few safe builtins: no imports beyond Scenic models and "
            "math, no file/process/network access, no exec/eval/getattr, no names or attributes starting with '_'; "
            "rewrite the lines named (the check applies to every script, trusted or not)."
        )


class PrecheckError(UnsafeScenarioError):
    """The text failed a bounded check done before parsing (size, encoding, nesting, invisible characters)."""

    def __init__(self, finding: SafetyFinding, label: str = "<script>") -> None:
        self.findings = [finding]
        ValueError.__init__(self, f"{label} failed the safety check: {finding}.")


def _refuse(label: str, line: int, construct: str, reason: str) -> PrecheckError:
    return PrecheckError(SafetyFinding(line, construct, reason), label)


def _decode(data: bytes, label: str) -> str:
    if len(data) > MAX_SCRIPT_BYTES:
        raise _refuse(label, 1, f"{len(data)} bytes", f"the script is larger than {MAX_SCRIPT_BYTES // 1024} KiB; "
                      "split it or remove generated bulk (Scenic scenarios are a few KB)")
    if data.startswith((b"\xef\xbb\xbf", b"\xff\xfe", b"\xfe\xff")):
        raise _refuse(label, 1, "byte-order mark", "scripts must be plain UTF-8 without a byte-order mark; "
                      "save the file as UTF-8 (no BOM)")
    try:
        return data.decode("utf-8", errors="strict")
    except UnicodeDecodeError as error:
        line = data.count(b"\n", 0, error.start) + 1
        raise _refuse(label, line, f"byte {data[error.start]:#04x}",
                      "the script is not valid UTF-8; save it as UTF-8") from None


def _check_coding(text: str, label: str) -> None:
    # PEP 263: a declaration counts on the first two lines only; refuse one naming anything but UTF-8.
    for number, line in enumerate(text.split("\n", 2)[:2], start=1):
        match = _CODING.match(line.encode("utf-8", "surrogatepass"))
        if match:
            name = match.group(1).decode("ascii", "replace").lower().replace("-", "_")
            if name not in _UTF8_NAMES:
                raise _refuse(label, number, f"coding: {match.group(1).decode('ascii', 'replace')}",
                              "only UTF-8 source is accepted (another source encoding makes Python read "
                              "different code than the text shows); remove the coding declaration")
        if line.strip() and not line.lstrip().startswith("#"):
            break


def _check_character(char: str, line: int, label: str) -> None:
    code = ord(char)
    if code < 0x20 or code == 0x7F or 0x80 <= code < 0xA0 or char in _EXTRA_LINE_BREAKS:
        if char in _ALLOWED_CONTROLS:
            return
        what = "NUL byte" if code == 0 else f"control character U+{code:04X}"
        raise _refuse(label, line, what, "scripts may not contain control characters or Unicode line "
                      "separators (they hide code from readers and checks); delete it")
    if code < 0x80:
        return
    category = unicodedata.category(char)
    if category in ("Cf", "Cs", "Co", "Cn") or unicodedata.bidirectional(char) in (
            "LRE", "RLE", "LRO", "RLO", "PDF", "LRI", "RLI", "FSI", "PDI"):
        name = unicodedata.name(char, "unassigned")
        raise _refuse(label, line, f"U+{code:04X} {name}".strip(),
                      "invisible, bidirectional-control or unassigned characters may make the code shown "
                      "differ from the code run; delete it")


@dataclass
class _ScanState:
    """Where the scanner is and what it is inside of: a string, a comment, brackets, a statement."""

    label: str
    line: int = 1
    column: int = 0
    logical_start: int = 0  # index where the current statement began
    depth: int = 0  # bracket nesting
    quote: str = ""  # the open string's quote ("" outside strings)
    fstring_base: int = -1  # depth where the open f-string began (-1: not in an f-string)
    comment: bool = False
    escaped: bool = False  # the previous character in a string was a backslash
    continued: bool = False  # a backslash continues the line
    operator_run: int = 0  # prefix operators in a row
    word: str = ""  # the name or keyword being read
    last: str = ""  # the line's last character of code


def _scan(text: str, label: str) -> None:
    """One pass: characters, line lengths, logical-line length, bracket nesting and prefix-operator runs."""
    state = _ScanState(label)
    i, n = 0, len(text)
    while i < n:
        char = text[i]
        _check_character(char, state.line, label)
        if char == "\n":
            _end_line(state, i)
            i += 1
            continue
        _count_column(state, text, i)
        if state.comment:
            i += 1
        elif state.quote:
            i = _step_in_string(state, text, i)
        else:
            i = _step_in_code(state, text, i)
    _check_line_length(state)


def _check_line_length(state: _ScanState) -> None:
    """Refuse the line just read if it is longer than :data:`MAX_LINE_CHARS`."""
    if state.column > MAX_LINE_CHARS:
        raise _refuse(state.label, state.line, f"{state.column} characters", f"lines may be at most "
                      f"{MAX_LINE_CHARS} characters; break the line")


def _end_line(state: _ScanState, i: int) -> None:
    """At a line feed (index ``i``): check the line's length, decide whether the statement ends here, and
    start the next line (an unterminated one-line string ends; a backslash in one continues it)."""
    _check_line_length(state)
    # Scenic continues a statement after a trailing comma (``new Car at p,`` / ``with speed 3``)
    ends_statement = not state.quote.startswith(("'''", '"""')) and state.depth == 0 and not state.continued \
        and state.last != ","
    if state.quote and len(state.quote) == 1 and state.escaped:
        pass  # a backslash continues a one-line string on the next line
    elif state.quote and len(state.quote) == 1:
        state.quote, state.fstring_base = "", -1  # an unterminated one-line string: the parser will report it
        ends_statement = state.depth == 0 and not state.continued
    if ends_statement:
        state.logical_start = i + 1
    state.line, state.column = state.line + 1, 0
    state.comment, state.escaped, state.continued, state.last = False, False, False, ""


def _count_column(state: _ScanState, text: str, i: int) -> None:
    """A character other than a line feed: refuse a lone carriage return and a statement grown longer than
    :data:`MAX_LOGICAL_LINE_CHARS`; count the column."""
    if text[i] == "\r" and not text.startswith("\r\n", i):
        raise _refuse(state.label, state.line, "carriage return", "a carriage return not followed by a line feed "
                      "ends a line for Python but not for most readers; use \\n or \\r\\n line ends")
    state.column += 1
    if i - state.logical_start > MAX_LOGICAL_LINE_CHARS:
        raise _refuse(state.label, state.line, "statement", f"one statement may span at most "
                      f"{MAX_LOGICAL_LINE_CHARS} characters (huge expressions make the parser take minutes); "
                      "split it into several statements")


def _step_in_string(state: _ScanState, text: str, i: int) -> int:
    """Read one character inside a string (escapes, its closing quote, an f-string field's brackets); the
    index of the next character to read."""
    char = text[i]
    if state.escaped:
        state.escaped = False
    elif char == "\\":
        state.escaped = True
    elif text.startswith(state.quote, i):
        i += len(state.quote)
        state.quote = ""
        if state.fstring_base >= 0:
            state.depth, state.fstring_base = state.fstring_base, -1
        return i
    elif state.fstring_base >= 0 and char in _OPEN:
        state.depth += 1  # an f-string's fields are code the parser nests into
    elif state.fstring_base >= 0 and char in _CLOSE and state.depth > state.fstring_base:
        state.depth -= 1
    if state.depth > MAX_NESTING:
        raise _nesting(state.label, state.line)
    return i + 1


def _step_in_code(state: _ScanState, text: str, i: int) -> int:
    """Read one character of code (a comment's start, a continuation backslash, a string's opening quote,
    brackets, prefix operators); the index of the next character to read."""
    char = text[i]
    state.continued = False
    if not char.isspace() and char != "#":
        state.last = char
    if char in "'\"":
        return _open_string(state, text, i)
    if char == "#":
        state.comment = True
    elif char == "\\":
        state.continued = True
    elif char in _OPEN:
        state.depth += 1
        if state.depth > MAX_NESTING:
            raise _nesting(state.label, state.line)
    elif char in _CLOSE:
        state.depth = max(0, state.depth - 1)
    _count_operators(state, char)
    return i + 1


def _open_string(state: _ScanState, text: str, i: int) -> int:
    """A quote in code opens a string (triple-quoted if the quote is tripled; an f-string if the word before
    it is a string prefix with ``f``); the index after the opening quote."""
    char = text[i]
    state.quote = text[i:i + 3] if text.startswith(char * 3, i) else char
    if "f" in state.word.lower() and _STRING_PREFIX.match(state.word):
        state.fstring_base = state.depth
    state.word = ""
    return i + len(state.quote)


def _count_operators(state: _ScanState, char: str) -> None:
    """Count prefix operators (``-``, ``+``, ``~``, ``not``) in a row; refuse more than
    :data:`MAX_OPERATOR_RUN`."""
    if char.isalnum() or char == "_":
        state.word += char
    else:
        if state.word:
            state.operator_run = state.operator_run + 1 if state.word == "not" else 0
            state.word = ""
        if char in _PREFIX_OPERATORS:
            state.operator_run += 1
        elif not char.isspace() and char not in "([{":
            state.operator_run = 0
    if state.operator_run > MAX_OPERATOR_RUN:
        raise _refuse(state.label, state.line, "operator run", f"more than {MAX_OPERATOR_RUN} prefix operators "
                      "in a row (-, +, ~, not) overflow the parser; simplify the expression")


def _nesting(label: str, line: int) -> PrecheckError:
    return _refuse(label, line, "nesting", f"brackets may nest at most {MAX_NESTING} deep (deeper nesting "
                   "overflows the parser); flatten the expression")


def precheck_text(text: Union[str, bytes], name: str = "<script>") -> str:
    """The script's text, after bounded checks that need no parser; raises :class:`PrecheckError`.

    ``text`` may be bytes (a file's contents: decoded as strict UTF-8) or a string.
    Every check is one linear pass with fixed limits (see the module docstring), so
    this is safe to run on any input in the user's process before the text goes to
    the parser. ``name`` labels the error.
    """
    if isinstance(text, (bytes, bytearray, memoryview)):
        text = _decode(bytes(text), name)
    elif not isinstance(text, str):
        raise WrongTypeError(f"a script is text or bytes, not {type(text).__name__}")
    else:
        if len(text) > MAX_SCRIPT_BYTES:  # characters <= bytes: a cheap first bound
            raise _refuse(name, 1, f"{len(text)} characters", f"the script is larger than "
                          f"{MAX_SCRIPT_BYTES // 1024} KiB; split it or remove generated bulk")
        try:
            size = len(text.encode("utf-8"))
        except UnicodeEncodeError:  # a lone surrogate
            raise _refuse(name, 1, "surrogate", "the script is not valid Unicode text; save it as UTF-8") from None
        if size > MAX_SCRIPT_BYTES:
            raise _refuse(name, 1, f"{size} bytes", f"the script is larger than {MAX_SCRIPT_BYTES // 1024} KiB; "
                          "split it or remove generated bulk")
        if text.startswith("\ufeff"):
            raise _refuse(name, 1, "byte-order mark", "scripts must be plain UTF-8 without a byte-order mark; "
                          "delete the leading U+FEFF")
    lines = text.count("\n") + 1
    if lines > MAX_LINES:
        raise _refuse(name, MAX_LINES + 1, f"{lines} lines", f"scripts may have at most {MAX_LINES} lines; "
                      "split the script")
    _check_coding(text, name)
    _scan(text, name)
    return text
