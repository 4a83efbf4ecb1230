"""A Sphinx directive that writes a command's usage and options from the command line itself, so a page cannot
drift from the code:

```{cmosnoise-command} simulate
```
"""

from __future__ import annotations

import click
from docutils import nodes
from docutils.parsers.rst import Directive
from docutils.statemachine import StringList


def _command(name: str) -> click.Command:
    import typer.main

    from cmosnoise.app.cli import app

    group = typer.main.get_command(app)
    cmd = getattr(group, "commands", {}).get(name)
    if cmd is None:
        raise ValueError(f"cmosnoise has no command {name!r}")
    return cmd


_KINDS = {"Path": "path", "int": "integer", "float": "number", "str": "text", "bool": "flag"}


def _kind(p) -> str:
    """What an option takes, from its annotation (Typer's parameters carry it; a List is repeatable)."""
    ann = getattr(getattr(p, "type_descriptor", None), "annotation", None)
    text = ann.__name__ if isinstance(ann, type) else str(ann).replace("typing.", "")
    repeat = "List[" in text or "list[" in text
    for k, v in _KINDS.items():
        if k in text:
            return v + (", repeatable" if repeat else "")
    return text


def _cell(text: str) -> str:
    return " ".join(str(text).split()).replace("|", "\\|")


def command_markdown(name: str) -> list[str]:
    """The usage and the options of ``cmosnoise NAME`` as Markdown lines (the pages are MyST: a directive's
    content is parsed as Markdown)."""
    cmd = _command(name)
    ctx = type(cmd).context_class(cmd, info_name=f"cmosnoise {name}")
    usage = " ".join(cmd.collect_usage_pieces(ctx))
    lines = ["```text", f"cmosnoise {name} {usage}", "```", "", "| option | takes | what it does |", "|---|---|---|"]
    for p in cmd.params:
        if p.name == "help":
            continue
        if p.param_type_name == "argument":
            lines.append(f"| `{p.name.upper()}` | argument | {_cell(p.help or '')} |")
            continue
        names = ", ".join(f"`{o}`" for o in [*p.opts, *getattr(p, "secondary_opts", [])])
        kind = "flag" if getattr(p, "is_flag", False) else _kind(p)
        default = "" if p.default in (None, False, ()) or callable(p.default) else f" (default: `{p.default}`)"
        lines.append(f"| {names} | {kind} | {_cell(p.help or '')}{default} |")
    return lines


class CommandDirective(Directive):
    required_arguments = 1
    has_content = False

    def run(self):
        name = self.arguments[0]
        lines = command_markdown(name)
        node = nodes.section()
        node.document = self.state.document
        self.state.nested_parse(StringList(lines, source=f"cmosnoise {name}"), self.content_offset, node)
        return node.children


def setup(app):
    app.add_directive("cmosnoise-command", CommandDirective)
    return {"parallel_read_safe": True, "parallel_write_safe": True}
