"""Upgrade Scenic 2 scripts to Scenic 3 syntax, reporting every rewrite.

Scenic 2 created objects with a bare class name (``ego = Car at p``,
``Car ahead of ego`` as a statement, ``Point on road`` inside an expression);
Scenic 3 needs ``new`` before the class. A Scenic 2 ``monitor Name:`` ran by
being defined; Scenic 3 writes ``monitor Name():`` and runs it only under
``require monitor Name()``, which is appended. The other rules (durations without
a unit, the old ``mutate`` and ``constructor`` forms, and the specifiers Scenic 3
reads differently: ``offset by``/``offset along``, ``beyond``, ``apparently facing``,
``left of``/``right of``/``ahead of``/``behind`` an object, ``with heading`` and class
``heading`` defaults) are in :mod:`scenario_bank.scenic2_rules`, which also lists what
was checked and needs no rewrite (``on``, ``visible``, ``simulation()`` and others).
The meaning rules only apply to a script found to be Scenic 2 (some syntax rule
fired), so a Scenic 3 script keeps its Scenic 3 meaning. The rules are applied on
Python tokens, so comments, strings, behaviours, ``compose`` and ``monitor`` blocks
and multi-line specifiers are handled as code is, and a Scenic 3 script (which
already says ``new``) comes out byte-for-byte unchanged.

What the translator does not rewrite it reports in :attr:`Upgrade.notes`
(never a silent change of meaning):

* ``requireVisible``: Scenic 2 required every object except ego to be visible
  from ego. Scenic 3 keeps that default only in 2D mode (``Object2D``, which
  the env and the bank compile with: ``mode2D=True``); a 3D compile drops it.
  The translator does not add ``with requireVisible True``; it notes it.
* a class name used as a value (``x = Car`` with nothing after it is creation in
  Scenic 2 and is rewritten; ``isinstance(o, Car)`` is a reference and is not).
* ``left of X``/``ahead of X``... when the script does not show whether ``X`` is an
  object (measured from its centre in Scenic 2, its edge in Scenic 3), ``beyond``
  with an operand that would be sampled twice, ``mutate`` of a non-name.
* a source the tokenizer cannot read is returned unchanged with the reason.
"""

from __future__ import annotations

import io
import re
import tokenize
from dataclasses import dataclass, field
from typing import Dict, List, Sequence, Set, Tuple

from scenario_bank.scenic2_rules import meaning_edits, syntax_edits

__all__ = ["Rewrite", "Upgrade", "upgrade_scenic2", "looks_like_scenic2", "OBJECT_CLASSES"]

OBJECT_CLASSES: frozenset = frozenset(
    {
        # core
        "Point", "OrientedPoint", "Object",
        # driving domain, highway-env model, CARLA, GTA, LGSVL, Webots, MetaDrive
        "Vehicle", "Car", "NPCCar", "Truck", "Bus", "Motorcycle", "Bicycle", "Pedestrian", "Obstacle",
        "Prop", "Trash", "Cone", "TrafficCone", "Barrier", "Box", "Chair", "Debris", "Garbage", "Kiosk",
        "VendingMachine", "Bench", "Advertisement", "Container", "Table", "ATM", "PlasticBag",
        "IronPlate", "Barrel", "CreasedBox", "Case", "Mailbox", "Gnome", "Iceguard", "BusStop",
        "EgoCar", "BoxCar", "NPCPedestrian", "ToyotaPrius", "MercedesCar",
        # the other classes of Scenic 3.1.1's simulator models (Webots, LGSVL, X-Plane, Newtonian, CARLA)
        "ApolloCar", "BmwX", "CitroenCZero", "Compact", "Ground", "Hill", "LGSVLObject", "LincolnMKZ",
        "NewtonianActor", "OilBarrel", "Plane", "PlantPot", "RangeRoverSportSVR", "SmallCar", "SolidBox",
        "Terrain", "Tractor", "TrafficWarning", "Van", "WebotsObject", "WorkBarrier", "CarlaActor",
        "MetaDriveActor",
    }
)
"""Class names that create an object when written bare in Scenic 2 (plus classes the script defines)."""

SPECIFIER_WORDS: frozenset = frozenset(
    {"at", "offset", "left", "right", "ahead", "behind", "beyond", "visible", "not", "in", "on",
     "following", "facing", "apparently", "with", "above", "below", "contained"}
)
"""Words that start a Scenic specifier; a class name followed by one is an instance creation."""

_BEFORE_CREATION = {"=", "(", "[", ",", "return", "yield", ":", "+", "-", "@", "in", "to", "from", "of",
                    "and", "or", "else", "lambda"}


@dataclass(frozen=True)
class Rewrite:
    """One change: 1-based ``line``, the line ``before`` and ``after``, and ``why``."""

    line: int
    before: str
    after: str
    why: str

    def __str__(self) -> str:
        return f"line {self.line}: {self.before.strip()!s} -> {self.after.strip()!s} ({self.why})"


@dataclass
class Upgrade:
    """The result of :func:`upgrade_scenic2`: the new ``source``, its rewrites and notes."""

    source: str
    rewrites: List[Rewrite] = field(default_factory=list)
    notes: List[str] = field(default_factory=list)

    @property
    def changed(self) -> bool:
        """True when at least one rewrite was applied."""
        return bool(self.rewrites)

    def report(self) -> List[str]:
        """One line per rewrite, then one per note (what a human should read)."""
        return [f"scenic2: {r}" for r in self.rewrites] + [f"scenic2 note: {n}" for n in self.notes]


def _tokens(source: str) -> List[tokenize.TokenInfo]:
    return list(tokenize.generate_tokens(io.StringIO(source).readline))


def _defined_classes(tokens: Sequence[tokenize.TokenInfo]) -> Set[str]:
    names = set()
    for i, tok in enumerate(tokens[:-1]):
        if tok.type == tokenize.NAME and tok.string in ("class", "constructor") and tokens[i + 1].type == tokenize.NAME:
            names.add(tokens[i + 1].string)
    return names


_SKIP = (tokenize.NL, tokenize.COMMENT, tokenize.INDENT, tokenize.DEDENT)


def _significant(tokens: Sequence[tokenize.TokenInfo]) -> List[tokenize.TokenInfo]:
    return [t for t in tokens if t.type not in _SKIP and t.type != tokenize.ENCODING]


def upgrade_scenic2(source: str, *, keep_scenic2_meaning: bool = True) -> Upgrade:
    """Rewrite Scenic 2 constructs in ``source`` to Scenic 3; see the module docstring for the rules.

    ``keep_scenic2_meaning`` (default): in a script found to be Scenic 2, also rewrite the specifiers
    Scenic 3 reads differently (:func:`scenario_bank.scenic2_rules.meaning_edits`) so it samples the
    scenes Scenic 2 did; False rewrites only the syntax Scenic 3 refuses.

    Idempotent: applying it to its own output changes nothing, and Scenic 3
    source comes back unchanged with no rewrites.
    """
    try:
        tokens = _tokens(source)
    except (tokenize.TokenError, IndentationError, SyntaxError) as error:
        return Upgrade(source, [], [f"not upgraded: the script cannot be tokenized ({error}); fix its syntax first"])
    classes = set(OBJECT_CLASSES) | _defined_classes(tokens)
    sig = _significant(tokens)
    lines = source.splitlines(keepends=True)
    # edits: (row, col_start, col_end, replacement, why)
    edits: List[Tuple[int, int, int, str, str]] = []
    created = 0
    for i, tok in enumerate(sig):
        if tok.type != tokenize.NAME:
            continue
        prev = sig[i - 1] if i > 0 else None
        nxt = sig[i + 1] if i + 1 < len(sig) else None
        if tok.string in classes:
            if prev is not None and prev.string in ("new", ".", "class", "def", "import", "isinstance", "constructor"):
                continue
            at_statement_start = prev is None or prev.type in (tokenize.NEWLINE,) or prev.string == ";"
            before_ok = at_statement_start or prev.string in _BEFORE_CREATION
            if not before_ok or nxt is None:
                continue
            next_is_spec = nxt.type == tokenize.NAME and nxt.string in SPECIFIER_WORDS
            ends = nxt.type in (tokenize.NEWLINE, tokenize.ENDMARKER) or nxt.string == ";"
            if next_is_spec or (ends and (at_statement_start or prev.string in ("=", "return"))):
                edits.append((tok.start[0], tok.start[1], tok.start[1], "new ",
                              f"Scenic 3 creates objects with 'new {tok.string}'"))
                created += 1
    monitors, monitor_notes = _old_monitors(sig)
    for row, name_end, name in monitors:
        edits.append((row, name_end, name_end, "()",
                      "Scenic 3 monitors take parentheses and are required explicitly"))
    more, syntax_notes = syntax_edits(sig, lines)
    edits += more
    notes: List[str] = list(monitor_notes) + syntax_notes
    changed: Dict[int, Tuple[str, List[str]]] = {}  # row -> (original line, reasons)
    lines = _apply(lines, edits, changed)
    appended: List[Rewrite] = []
    if monitors:
        if lines and not lines[-1].endswith("\n"):
            lines[-1] += "\n"
        for _, _, name in monitors:
            added = f"require monitor {name}()"
            lines.append(added + "\n")
            appended.append(Rewrite(len(lines), "", added,
                                    f"a Scenic 2 monitor ran by being defined; Scenic 3 runs {name} only when required"))
    if edits and keep_scenic2_meaning:  # also the forms whose meaning changed in Scenic 3
        sig3 = _significant(_tokens("".join(lines)))
        meaning, meaning_notes = meaning_edits(sig3, lines)
        # only a script written for Scenic 2 throughout (bare creations or old monitors, no 'new') means them
        # as Scenic 2 did; in one mixing 'new' with old forms they keep their Scenic 3 meaning, noted
        scenic2_throughout = bool(created or monitors) and not _uses_new(sig)
        if scenic2_throughout:
            lines = _apply(lines, meaning, changed)
            notes += meaning_notes
        else:
            notes += [f"line {row}: kept as Scenic 3 reads it, the script also uses 'new': {why}"
                      for row, _, _, _, why in sorted(meaning)]
    rewrites = [Rewrite(row, before.rstrip("\n"), lines[row - 1].rstrip("\n"), "; ".join(whys))
                for row, (before, whys) in sorted(changed.items())] + appended
    if created:
        notes.append(
            "requireVisible: Scenic 2 required objects to be visible from ego by default; Scenic 3 keeps "
            "that only in 2D mode (the env compiles with mode2D=True); no 'with requireVisible' was added"
        )
    return Upgrade("".join(lines), rewrites, notes)


def _uses_new(sig: Sequence[tokenize.TokenInfo]) -> bool:
    """Whether the script already creates an object with Scenic 3's ``new``."""
    return any(tok.string == "new" and nxt.type == tokenize.NAME for tok, nxt in zip(sig, sig[1:]))


def _apply(lines: List[str], edits: Sequence[Tuple[int, int, int, str, str]],
           changed: Dict[int, Tuple[str, List[str]]]) -> List[str]:
    """``lines`` with the same-line ``edits`` applied; ``changed`` collects each row's original and reasons."""
    lines = list(lines)
    by_line: Dict[int, List[Tuple[int, int, str, str]]] = {}
    for row, c0, c1, text, why in edits:
        by_line.setdefault(row, []).append((c0, c1, text, why))
    for row in sorted(by_line):
        original = lines[row - 1]
        before, whys = changed.setdefault(row, (original, []))
        new = original
        added = []
        for c0, c1, text, why in sorted(by_line[row], reverse=True):
            new = new[:c0] + text + new[c1:]
            if why not in whys and why not in added:
                added.insert(0, why)
        whys.extend(added)
        lines[row - 1] = new
    return lines


def _old_monitors(sig: Sequence[tokenize.TokenInfo]) -> Tuple[List[Tuple[int, int, str]], List[str]]:
    """Scenic 2 monitors (``monitor Name:``): top-level ones are rewritten, nested ones reported."""
    found: List[Tuple[int, int, str]] = []
    notes: List[str] = []
    for i, tok in enumerate(sig[:-2]):
        if tok.type == tokenize.NAME and tok.string == "monitor" and sig[i + 1].type == tokenize.NAME \
                and sig[i + 2].string == ":" and (i == 0 or sig[i - 1].type == tokenize.NEWLINE):
            if tok.start[1] == 0:
                found.append((sig[i + 1].start[0], sig[i + 1].end[1], sig[i + 1].string))
            else:
                notes.append(f"line {tok.start[0]}: not translated: Scenic 2 monitor {sig[i + 1].string!r} "
                             "inside a block; add '()' and a 'require monitor' yourself")
    return found, notes


_SCENIC2_ERRORS = re.compile(
    r"(Scenic 2 syntax|invalid syntax|unexpected token|2\.0-style|monitor must be converted|ScenicParseError|"
    r"instance creation|specifier|duration must specify a unit)", re.IGNORECASE
)


def looks_like_scenic2(source: str, compile_error: str = "") -> bool:
    """True when ``source`` uses Scenic 2 syntax the upgrader rewrites.

    Decided from the syntax (a bare class creation or an old-style monitor, found
    on tokens, so comments and strings do not count); ``compile_error``, when
    given, must also be an error such syntax produces (a parse error), so a script failing for another reason is not
    called Scenic 2.
    """
    upgrade = upgrade_scenic2(source)
    if not upgrade.rewrites:
        return False
    return not compile_error or bool(_SCENIC2_ERRORS.search(compile_error))
