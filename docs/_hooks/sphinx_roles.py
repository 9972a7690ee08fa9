"""Griffe extension for the API pages: Sphinx roles in docstrings become inline code.

The docstrings of vjm_pin are read by humans in the source, in ``help()`` and on this site;
they write cross-references the Sphinx way (:class:`~vjm_pin.model.format.VjmModel`,
:func:`vjm_pin.model.beam.cantilever_compliance`). Markdown would show the role literally, so this
extension rewrites each role into inline code (``VjmModel`` for the ``~`` short form, the
full path otherwise) before mkdocstrings renders the docstring. Nothing in the package is
changed.
"""

from __future__ import annotations

import re

import griffe

ROLE = re.compile(
    r":(?:py:)?(?:class|func|meth|mod|attr|data|exc|obj|const):`(~?)([^`<]+?)(?:\s*<([^>]+)>)?`"
)


def rewrite(text: str) -> str:
    """``text`` with every Sphinx cross-reference role replaced by inline code."""

    def repl(m: re.Match) -> str:
        short, target, explicit = m.group(1), m.group(2).strip(), m.group(3)
        if explicit:  # :func:`title <path>` -> the title
            return f"`{target}`"
        if short:
            target = target.rsplit(".", 1)[-1]
        return f"`{target}`"

    return ROLE.sub(repl, text)


class SphinxRoles(griffe.Extension):
    """Rewrite Sphinx roles in every docstring (see the module docstring)."""

    def on_instance(self, *, obj, **kwargs) -> None:  # griffe ≥ 1
        if obj.docstring is not None:
            obj.docstring.value = rewrite(obj.docstring.value)
