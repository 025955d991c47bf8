"""griffe extension for the site: a docstring's doctest examples (``>>>`` blocks) render as Python
console code, and ``[..]`` in their output is not read as a Markdown link."""

import re

import griffe

_EXAMPLE = re.compile(r"(?m)^(?P<indent>[ \t]*)>>> .*(?:\n(?P=indent)(?!\s*$).*)*")


def fence(text: str) -> str:
    """Wrap every run of doctest lines (a ``>>>`` line up to the next blank line) in a pycon fence."""
    return _EXAMPLE.sub(lambda m: f"{m['indent']}```pycon\n{m[0]}\n{m['indent']}```", text)


class DoctestFences(griffe.Extension):
    def on_instance(self, *, obj, **kwargs):
        if obj.docstring is not None and ">>>" in obj.docstring.value:
            obj.docstring.value = fence(obj.docstring.value)
