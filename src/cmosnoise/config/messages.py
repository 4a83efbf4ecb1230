"""Validation errors as one line a user can act on: ``key = value: what is allowed``."""

from __future__ import annotations

from pydantic import ValidationError


def _format_loc(loc) -> str:
    parts = []
    for p in loc:
        if isinstance(p, int):
            parts.append(f"[{p}]")
        elif str(p).startswith(("list[", "dict[", "function-")):
            continue  # pydantic's union-branch labels, not user keys
        else:
            parts.append(("." if parts else "") + str(p))
    return "".join(parts)


def format_validation_error(err: ValidationError) -> str:
    """One line per problem: ``key = value: what is allowed``."""
    lines = []
    seen = set()
    for e in err.errors():
        key = _format_loc(e.get("loc", ()))
        msg = e.get("msg", "invalid")
        msg = msg.removeprefix("Value error, ")
        if e.get("type") == "extra_forbidden":
            parent = key.rsplit(".", 1)[0] if "." in key else ""
            line = f"unknown key '{key}'" + (f" in section '{parent}'" if parent else "")
        elif "input" in e and not isinstance(e["input"], dict) and key:
            line = f"{key} = {e['input']!r}: {msg}"
        else:
            line = f"{key}: {msg}" if key else msg
        if line not in seen:
            seen.add(line)
            lines.append(line)
    return "invalid configuration: " + "; ".join(lines)


