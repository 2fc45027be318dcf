"""Scenic 2 -> 3 rules beyond ``new`` and monitors, applied on tokens by :mod:`scenario_bank.scenic2`.

Two groups, found by comparing Scenic 2.1.0 (``syntax/translator.py``, ``syntax/veneer.py``) with
Scenic 3.1.1 (``scenic.gram``, ``veneer.py``) and by running both versions on the same snippets:

*Syntax* (:func:`syntax_edits`): Scenic 2 forms Scenic 3.1.1 refuses, always rewritten.

* ``terminate after N`` and ``do B for N`` without a unit: Scenic 2 read seconds; Scenic 3 says
  "duration must specify a unit". ``seconds`` is appended.
* ``mutate a, b, 2`` / ``mutate 2``: Scenic 2 took a trailing number as the scale; Scenic 3 writes
  ``mutate a, b by 2`` / ``mutate by 2``. A non-name target (``mutate cars[0]``) is noted.
* ``constructor Name(...)``: Scenic 2's old spelling of ``class``.

*Meaning* (:func:`meaning_edits`): forms both versions parse but read differently; applied only to a
script found to be Scenic 2 (a syntax rule or a bare creation fired), so Scenic 3 code is never touched.

* ``offset by V`` / ``offset along H by V`` as specifiers: Scenic 3 also sets ``parentOrientation`` to
  ego's, so an object without ``facing`` takes ego's heading instead of its class default (a Car's road
  direction). Rewritten ``at ego offset by V`` (the operator: same position, no orientation).
* ``beyond X by D [from Z]``: Scenic 3 sets ``parentOrientation`` (to the global frame), dropping the
  class default heading. Rewritten ``at X offset along (angle from Z to X) by (0, D)`` (the position
  Scenic 2 computed) when ``X`` and ``Z`` are plain names or literals; otherwise noted.
* ``apparently facing H [from P]``: Scenic 3 adds the angle to ``parentOrientation`` (a Car's class
  default is the road direction), Scenic 2 used it as the global heading. ``, with parentOrientation 0``
  is appended.
* ``left of X by D`` (also ``right of``, ``ahead of``, ``behind``) with ``X`` an object: Scenic 3 measures
  ``D`` from X's edge, Scenic 2 measured it from X's centre (a bug fix in Scenic 3.0). ``D`` becomes
  ``D - X.width / 2`` (``length`` for ahead/behind) when ``X`` is ``ego`` or a name the script binds to a
  new object; for a name of unknown kind it is noted (points and vectors mean the same in both).
* ``with heading H`` -> ``facing H`` and a class body's ``heading: E`` -> ``parentOrientation: E``: what
  Scenic 3's 2D mode does itself; rewriting makes the script also compile in 3D mode.

Checked and left alone (same meaning in 2D mode, which the env and the bank use): ``on R`` (Scenic 3
places the base on the region, but 2D mode zeroes ``baseOffset``), ``visible``/``not visible``, ``can
see`` (2D mode restores centre-only, occlusion-free checks), ``in R``, ``following``, ``facing``,
``facing toward``, ``require[p]``, ``workspace``, ``interrupt when``, ``do ... until``, ``x @ y``. The
simulation-time API is the same in both versions: ``simulation().currentTime`` counts steps,
``.timestep`` is seconds per step, ``.currentRealTime``, ``.objects``, ``.agents`` all exist in both;
what differs is the step length between simulators, so each ``simulation().currentTime`` of a Scenic 2
script gets a note (its authors assumed CARLA's 0.1 s steps).
"""

from __future__ import annotations

import tokenize
from typing import List, Optional, Sequence, Set, Tuple

__all__ = ["Edit", "syntax_edits", "meaning_edits"]

Edit = Tuple[int, int, int, str, str]
"""``(row, col_start, col_end, replacement, why)``: one same-line replacement (1-based row)."""

Tok = tokenize.TokenInfo

_OPEN, _CLOSE = "([{", ")]}"
_UNITS = ("seconds", "steps")
_SPEC_START = {"at", "offset", "left", "right", "ahead", "behind", "beyond", "visible", "not", "in", "on",
               "following", "facing", "apparently", "with", "above", "below", "contained"}
_POINT_CLASSES = {"Point", "OrientedPoint", "Point2D", "OrientedPoint2D"}
_DIRECTIONAL = {"left": "width", "right": "width", "ahead": "length", "behind": "length"}


def _ends_statement(tok: Tok) -> bool:
    return tok.type in (tokenize.NEWLINE, tokenize.ENDMARKER) or tok.string == ";"


def _statement_starts(sig: Sequence[Tok]) -> List[int]:
    return [i for i in range(len(sig)) if i == 0 or _ends_statement(sig[i - 1])]


def _scan(sig: Sequence[Tok], i: int, stops: Set[str] = frozenset(), comma: bool = True) -> int:
    """Index of the first token from ``i`` ending an operand at bracket depth 0: the statement's end,
    a closing bracket of an enclosing group, a ``,`` (when ``comma``) or a word in ``stops``."""
    depth = 0
    while i < len(sig):
        tok = sig[i]
        if tok.type == tokenize.OP and tok.string in _OPEN:
            depth += 1
        elif tok.type == tokenize.OP and tok.string in _CLOSE:
            if depth == 0:
                return i
            depth -= 1
        elif depth == 0 and (_ends_statement(tok) or (comma and tok.string == ",")
                             or (tok.type == tokenize.NAME and tok.string in stops)):
            return i
        i += 1
    return i


def _text(lines: Sequence[str], sig: Sequence[Tok], a: int, b: int) -> Optional[str]:
    """Source text of tokens ``sig[a:b]`` when they sit on one line, else None."""
    if a >= b or sig[a].start[0] != sig[b - 1].end[0]:
        return None
    return lines[sig[a].start[0] - 1][sig[a].start[1]:sig[b - 1].end[1]]


def _insert_after(tok: Tok, text: str, why: str) -> Edit:
    return (tok.end[0], tok.end[1], tok.end[1], text, why)


def _replace(sig: Sequence[Tok], a: int, b: int, text: str, why: str) -> Edit:
    return (sig[a].start[0], sig[a].start[1], sig[b - 1].end[1], text, why)


def _is_numeric(toks: Sequence[Tok]) -> bool:
    """A constant number expression (``2``, ``-0.5``, ``1/2``)."""
    return bool(toks) and any(t.type == tokenize.NUMBER for t in toks) and all(
        t.type == tokenize.NUMBER or t.string in "+-*/()" for t in toks)


def _is_plain(toks: Sequence[Tok]) -> bool:
    """Safe to evaluate twice: names, attributes, numbers and tuples of them, no calls."""
    if not toks:
        return False
    for k, t in enumerate(toks):
        if t.type == tokenize.NAME:
            if k + 1 < len(toks) and toks[k + 1].string in ("(", "["):
                return False
        elif t.type != tokenize.NUMBER and t.string not in ".,()@+-*/":
            return False
    return True


def _is_vector_literal(toks: Sequence[Tok]) -> bool:
    """``(a, b)`` or ``a @ b`` at the top level."""
    if len(toks) >= 2 and toks[0].string == "(" and toks[-1].string == ")" \
            and _scan(toks, 1) < len(toks) - 1 and toks[_scan(toks, 1)].string == ",":
        return True
    depth = 0
    for t in toks:
        depth += t.string in _OPEN and t.type == tokenize.OP
        depth -= t.string in _CLOSE and t.type == tokenize.OP
        if depth == 0 and t.string == "@":
            return True
    return False


def syntax_edits(sig: Sequence[Tok], lines: Sequence[str]) -> Tuple[List[Edit], List[str]]:
    """Edits for the Scenic 2 forms Scenic 3.1.1 refuses (see the module docstring), and notes."""
    edits: List[Edit] = []
    notes: List[str] = []
    numbers = _numeric_names(sig)
    for i in _statement_starts(sig):
        tok = sig[i]
        if tok.type != tokenize.NAME or i + 1 >= len(sig):
            continue
        word, nxt = tok.string, sig[i + 1]
        if word == "terminate" and nxt.string == "after":
            end = _scan(sig, i + 2, comma=False)
            if end > i + 2 and sig[end - 1].string not in _UNITS:
                edits.append(_insert_after(sig[end - 1], " seconds",
                                           "Scenic 2 read 'terminate after N' as seconds; Scenic 3 needs the unit"))
        elif word == "do" and nxt.string not in ("choose", "shuffle"):
            k = _scan(sig, i + 1, stops={"for", "until"}, comma=False)
            if k < len(sig) and sig[k].string == "for":
                end = _scan(sig, k + 1, comma=False)
                if end > k + 1 and sig[end - 1].string not in _UNITS:
                    edits.append(_insert_after(sig[end - 1], " seconds",
                                               "Scenic 2 read 'do ... for N' as seconds; Scenic 3 needs the unit"))
        elif word == "mutate":
            edits_m, notes_m = _mutate(sig, i, numbers)
            edits += edits_m
            notes += notes_m
        elif word == "constructor" and nxt.type == tokenize.NAME:
            edits.append(_replace(sig, i, i + 1, "class", "Scenic 2's 'constructor' is 'class' in Scenic 3"))
    return edits, notes


def _numeric_names(sig: Sequence[Tok]) -> Set[str]:
    """Names a statement ``NAME = <number>`` binds (a ``mutate`` scale may be one)."""
    found = set()
    for i in _statement_starts(sig):
        if i + 2 < len(sig) and sig[i].type == tokenize.NAME and sig[i + 1].string == "=":
            end = _scan(sig, i + 2, comma=False)
            if _is_numeric(sig[i + 2:end]):
                found.add(sig[i].string)
    return found


def _mutate(sig: Sequence[Tok], i: int, numbers: Set[str]) -> Tuple[List[Edit], List[str]]:
    end = _scan(sig, i + 1, stops={"by"}, comma=False)
    if end < len(sig) and sig[end].string == "by":
        return [], []  # Scenic 3 form (Scenic 2 accepted it too)
    parts, k = [], i + 1
    while k < end:
        stop = _scan(sig, k, comma=True)
        parts.append((k, min(stop, end)))
        k = stop + 1
    if not parts:
        return [], []
    why = "Scenic 2 took a trailing number as the mutation scale; Scenic 3 writes 'mutate ... by S'"
    edits: List[Edit] = []
    a, b = parts[-1]
    last = sig[a:b]
    targets = parts
    if _is_numeric(last) or (len(last) == 1 and last[0].string in numbers):
        targets = parts[:-1]
        if targets:
            comma = sig[a - 1]
            edits.append((comma.start[0], comma.start[1], comma.end[1], " by", why))
        else:
            edits.append((sig[a].start[0], sig[a].start[1], sig[a].start[1], "by ", why))
    notes = [f"line {sig[x].start[0]}: not translated: Scenic 3 'mutate' takes object names only, not "
             f"{' '.join(t.string for t in sig[x:y])!r}; bind it to a name first"
             for x, y in targets if not (y == x + 1 and sig[x].type == tokenize.NAME)]
    return edits, notes


def _object_names(sig: Sequence[Tok]) -> Tuple[Set[str], Set[str]]:
    """(names bound to new objects, names bound to new points) by ``NAME = new Class ...``."""
    objects, points = {"ego"}, set()
    for i in range(len(sig) - 3):
        if sig[i].type == tokenize.NAME and sig[i + 1].string == "=" and sig[i + 2].string == "new" \
                and sig[i + 3].type == tokenize.NAME:
            (points if sig[i + 3].string in _POINT_CLASSES else objects).add(sig[i].string)
    return objects, points - objects


def _specifiers(sig: Sequence[Tok]) -> List[Tuple[int, int]]:
    """``(start, end)`` index ranges of each specifier of every ``new Class ...``."""
    found = []
    for i in range(len(sig) - 2):
        if not (sig[i].string == "new" and sig[i + 1].type == tokenize.NAME):
            continue
        k, specs = i + 2, []
        while sig[k].type == tokenize.NAME and sig[k].string in _SPEC_START:
            stop = _scan(sig, k)
            specs.append((k, stop))
            if stop >= len(sig) or sig[stop].string != ",":
                break
            k = stop + 1  # a specifier list may go on after ',' on the next line (a NEWLINE token here)
            if k < len(sig) and sig[k].type == tokenize.NEWLINE:
                k += 1
            if not (k < len(sig) and sig[k].type == tokenize.NAME and sig[k].string in _SPEC_START):
                break
        found += specs
    return found


def meaning_edits(sig: Sequence[Tok], lines: Sequence[str]) -> Tuple[List[Edit], List[str]]:
    """Edits for forms both versions parse but read differently (see the module docstring), and notes."""
    edits: List[Edit] = []
    notes: List[str] = []
    objects, points = _object_names(sig)
    vectors = _vector_names(sig)
    for a, b in _specifiers(sig):
        words = [t.string for t in sig[a:min(b, a + 2)]]
        row = sig[a].start[0]
        if words == ["offset", "by"] or words == ["offset", "along"]:
            edits.append((row, sig[a].start[1], sig[a].start[1], "at ego ",
                          f"Scenic 3's '{' '.join(words)}' specifier also takes ego's orientation; 'at ego "
                          f"{' '.join(words)} ...' keeps Scenic 2's class-default heading"))
        elif words == ["apparently", "facing"]:
            edits.append(_insert_after(sig[b - 1], ", with parentOrientation 0",
                                       "Scenic 3 adds 'apparently facing' to parentOrientation; Scenic 2 "
                                       "used it as the global heading"))
        elif words == ["with", "heading"]:
            edits.append(_replace(sig, a, a + 2, "facing",
                                  "Scenic 3 derives heading from orientation: 'with heading' is 'facing'"))
        elif words and words[0] == "beyond":
            edit, note = _beyond(sig, lines, a, b, vectors)
            edits += [edit] if edit else []
            notes += [note] if note else []
        elif words and words[0] in _DIRECTIONAL and (words[0] == "behind" or words[1:] == ["of"]):
            edit, note = _directional(sig, lines, a, b, objects, points)
            edits += [edit] if edit else []
            notes += [note] if note else []
    edits += _class_heading_defaults(sig)
    notes += _step_counts(sig)
    return edits, notes


def _step_counts(sig: Sequence[Tok]) -> List[str]:
    """Notes on ``simulation().currentTime``: a step count whose step length is the simulator's."""
    rows = sorted({sig[i].start[0] for i in range(len(sig) - 4)
                   if sig[i].string == "simulation" and sig[i + 1].string == "(" and sig[i + 2].string == ")"
                   and sig[i + 3].string == "." and sig[i + 4].string == "currentTime"})
    return [f"line {row}: check: simulation().currentTime counts steps in Scenic 2 and 3 alike, but a step lasts "
            "the simulator's timestep (CARLA and LGSVL scripts assume 0.1 s; DV2S-v0 steps 1/policy_frequency s); "
            "simulation().currentRealTime is in seconds" for row in rows]


def _vector_names(sig: Sequence[Tok]) -> Set[str]:
    """Names a statement ``NAME = (a, b)`` or ``NAME = a @ b`` binds."""
    found = set()
    for i in _statement_starts(sig):
        if i + 2 < len(sig) and sig[i].type == tokenize.NAME and sig[i + 1].string == "=":
            if _is_vector_literal(sig[i + 2:_scan(sig, i + 2, comma=False)]):
                found.add(sig[i].string)
    return found


def _beyond(sig, lines, a, b, vectors: Set[str]) -> Tuple[Optional[Edit], Optional[str]]:
    by = _scan(sig, a + 1, stops={"by"})
    if by >= b or sig[by].string != "by":
        return None, None
    frm = _scan(sig, by + 1, stops={"from"})
    x, d = sig[a + 1:by], sig[by + 1:min(frm, b)]
    z = sig[frm + 1:b] if frm < b else None
    x_text, d_text = _text(lines, sig, a + 1, by), _text(lines, sig, by + 1, min(frm, b))
    z_text = _text(lines, sig, frm + 1, b) if z is not None else "ego"
    row = sig[a].start[0]
    if not (_is_plain(x) and (z is None or _is_plain(z)) and x_text and d_text and z_text):
        return None, (f"line {row}: not translated: 'beyond' sets parentOrientation in Scenic 3, dropping the "
                      "class-default heading Scenic 2 kept; add 'facing' if the heading matters")
    vector = _is_vector_literal(d) or (len(d) == 1 and d[0].string in vectors)
    offset = d_text if vector else f"(0, {d_text})"  # Scenic 2 read a number as a distance along the sight line
    new = f"at {x_text} offset along (angle from {z_text} to {x_text}) by {offset}"
    return _replace(sig, a, b, new, "Scenic 3's 'beyond' also sets parentOrientation; this is the position "
                                    "Scenic 2 computed, with its class-default heading"), None


def _directional(sig, lines, a, b, objects, points) -> Tuple[Optional[Edit], Optional[str]]:
    word = sig[a].string
    start = a + 1 if word == "behind" else a + 2
    by = _scan(sig, start, stops={"by"})
    ref = sig[start:min(by, b)]
    row = sig[a].start[0]
    dim = _DIRECTIONAL[word]
    if len(ref) != 1 or ref[0].type != tokenize.NAME:
        vector = _is_vector_literal(ref) or any(t.string in ("offset", "@", "position") for t in ref)
        if ref and not vector:  # 'X offset by V', 'a @ b', 'X.position' are vectors: same meaning
            return None, (f"line {row}: check: if `{' '.join(t.string for t in ref)}` is an object, Scenic 3 "
                          f"measures '{word}' from its edge, Scenic 2 from its centre (subtract its {dim} / 2)")
        return None, None
    name = ref[0].string
    if name in points or name not in objects:
        if name not in points:
            return None, (f"line {row}: check: if `{name}` is an object, Scenic 3 measures '{word} {name}' from "
                          f"its edge, Scenic 2 from its centre (subtract {name}.{dim} / 2 from the distance)")
        return None, None
    half = f"{name}.{dim} / 2"
    phrase = word if word == "behind" else f"{word} of"
    why = (f"Scenic 3 measures '{phrase} {name}' from {name}'s edge, Scenic 2 from its centre: "
           f"{half} is subtracted to keep Scenic 2's placement")
    if by >= b:
        return _insert_after(sig[start], f" by -{half}", why), None
    d = sig[by + 1:b]
    d_text = _text(lines, sig, by + 1, b)
    if d_text is None:
        return None, f"line {row}: not translated: multi-line distance after '{phrase} {name} by'"
    if _is_vector_literal(d) and d[0].string == "(":
        comma = _scan(sig, by + 2)
        first = _text(lines, sig, by + 2, comma)
        rest = _text(lines, sig, comma, b)
        if first is None or rest is None:
            return None, f"line {row}: not translated: vector distance after '{phrase} {name} by'"
        if dim == "width":
            new = f"({first} - {half}{rest}"
        else:
            second_end = _scan(sig, comma + 1)
            second = _text(lines, sig, comma + 1, second_end)
            tail = _text(lines, sig, second_end, b) or ")"
            new = f"({first}, {second} - {half}{tail}"
        return _replace(sig, by + 1, b, new, why), None
    if _is_vector_literal(d):
        return None, f"line {row}: not translated: vector distance after '{phrase} {name} by'"
    simple = len(d) == 1 or (len(d) > 2 and d[0].type == tokenize.NAME and d[1].string == "("
                             and _scan(sig, by + 3, comma=False) == b - 1)
    text = d_text if simple else f"({d_text})"
    return _replace(sig, by + 1, b, f"{text} - {half}", why), None


def _class_heading_defaults(sig: Sequence[Tok]) -> List[Edit]:
    """``heading: E`` (or ``heading[dynamic]: E``) property defaults in class bodies."""
    edits = []
    starts = _statement_starts(sig)
    for n, i in enumerate(starts):
        tok = sig[i]
        if tok.string != "heading" or tok.start[1] == 0 or i + 1 >= len(sig):
            continue
        # the enclosing block: the nearest earlier statement indented less must be a 'class' line
        owner = next((sig[j] for j in reversed(starts[:n]) if sig[j].start[1] < tok.start[1]), None)
        if owner is None or owner.string != "class":
            continue
        nxt = sig[i + 1]
        if nxt.string == ":" or (nxt.string == "[" and _closing_then_colon(sig, i + 1)):
            edits.append(_replace(sig, i, i + 1, "parentOrientation",
                                  "Scenic 3 classes default parentOrientation, not heading"))
    return edits


def _closing_then_colon(sig: Sequence[Tok], i: int) -> bool:
    k = _scan(sig, i + 1)
    return k + 1 < len(sig) and sig[k].string == "]" and sig[k + 1].string == ":"
