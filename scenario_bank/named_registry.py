"""Adding to a table of named plug-ins (policies, samplers, worker backends, pipeline backends): one rule for all.

Each registry stays a plain module-level ``dict`` of its own (name -> factory or record) in the module that uses
it; :func:`register_named` is the one way entries are added to such a dict."""

from __future__ import annotations

from typing import Any, Dict, Type

__all__ = ["register_named"]


def register_named(table: Dict[str, Any], name: str, item: Any, *, what: str, error: Type[Exception],
                   overwrite: bool = False) -> None:
    """Put ``item`` into ``table`` under ``name``.

    ``what`` names the kind in messages (``"sampler"``, ``"worker backend"``); a name that is not a non-empty
    string, or one already in ``table`` without ``overwrite``, raises ``error`` saying so and how to replace it."""
    if not isinstance(name, str) or not name:
        raise error(f"{what} name {name!r} must be a non-empty string")
    if name in table and not overwrite:
        raise error(f"a {what} named {name!r} is already registered; pass overwrite=True to replace it")
    table[name] = item
