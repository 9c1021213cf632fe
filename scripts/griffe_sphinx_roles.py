"""Griffe extension for the interprim site: Sphinx cross-reference roles in docstrings become links.

interprim's docstrings are numpydoc and cite other objects with Sphinx roles (``:func:`fit_prior```,
``:meth:`~interprim.models.primitive.stream.Stream.update```).  mkdocstrings does not read roles, so this extension
rewrites each one, once the package is loaded, into an *optional* mkdocs-autorefs reference: a link where the target
is documented on some page of the site, plain code otherwise (a private helper, a module without a page).
Names are resolved in the docstring's own scope (class, module, package), as Sphinx does; ``~`` shows the
last component only.  Used from ``mkdocs.yml`` (mkdocstrings' python handler, ``extensions:``).
"""

from __future__ import annotations

import html
import re

import griffe

_ROLE = re.compile(r":(?:py:)?(?:func|class|meth|mod|data|attr|obj|exc|const):`([^`]+)`")


def _resolve(obj, name: str) -> str:
    """Full path of ``name`` as seen from ``obj``'s scope (``name`` itself when it cannot be resolved)."""
    if name.startswith("interprim."):
        return name
    head, _, rest = name.partition(".")
    scope = obj
    while scope is not None:
        try:
            base = scope.resolve(head)
        except Exception:  # noqa: BLE001 - griffe raises several kinds for names it cannot see
            scope = scope.parent
            continue
        return base + ("." + rest if rest else "")
    return name


def _rewrite(obj, text: str) -> str:
    def sub(m: re.Match) -> str:
        target = m.group(1).strip()
        short = target.startswith("~")
        target = target.lstrip("~.")
        title = target.rsplit(".", 1)[-1] if short else target
        ident = _resolve(obj, target)
        return (f'<autoref identifier="{html.escape(ident, quote=True)}" optional>'
                f"<code>{html.escape(title)}</code></autoref>")

    return _ROLE.sub(sub, text)


def _walk(obj, seen):
    if id(obj) in seen:
        return
    seen.add(id(obj))
    if obj.docstring is not None and ":" in obj.docstring.value:
        obj.docstring.value = _rewrite(obj, obj.docstring.value)
    for member in obj.members.values():
        if not member.is_alias:
            _walk(member, seen)


class SphinxRoles(griffe.Extension):
    """Rewrite Sphinx roles in every docstring of a loaded package into optional autorefs."""

    def on_package(self, *, pkg, **kwargs):  # noqa: D401 - griffe event
        _walk(pkg, set())
