"""MkDocs hooks of the interprim site (``mkdocs.yml``: ``hooks:``).

- The home page, the benchmark results, the changelog, the contributors' guide and the licence are generated
  from the repository's own files (``README.md``, ``benchmarks/RESULTS.md``, ``CHANGELOG.md``, ``CONTRIBUTING.md``,
  ``LICENSE``), with their links rewritten from repository paths to site pages, so there is one copy of each
  text.
- ``<!-- interprim-cli-help -->`` in a page is replaced by the ``--help`` of every ``interprim`` command,
  taken from the parser itself (always in step with the code).

Nothing here touches the network.
"""

from __future__ import annotations

import os
import posixpath
import re
from pathlib import Path

from mkdocs.structure.files import File

ROOT = Path(__file__).resolve().parent.parent

# repository file -> site path, for links from any page to files outside docs/
_LINK_MAP = {
    "README.md": "index.md",
    "benchmarks/RESULTS.md": "benchmarks.md",
    "CHANGELOG.md": "changelog.md",
    "CONTRIBUTING.md": "contributing.md",
    "LICENSE": "license.md",
    "src/interprim/server/static/protocol.schema.json": "protocol.schema.json",
}

# generated site file -> (repository file, heading when the file is shown verbatim, or None for Markdown)
_GENERATED = {
    "index.md": ("README.md", None),
    "benchmarks.md": ("benchmarks/RESULTS.md", None),
    "changelog.md": ("CHANGELOG.md", None),
    "contributing.md": ("CONTRIBUTING.md", None),
    "license.md": ("LICENSE", "License"),
    "protocol.schema.json": ("src/interprim/server/static/protocol.schema.json", None),
}
_SOURCE_OF = {uri: src for uri, (src, _) in _GENERATED.items()}

_LINK = re.compile(r"\]\((?!https?://|#|mailto:)([^)\s]+)\)")


def _rewrite_links(text: str, source: str, page_uri: str) -> str:
    """Links written in the repository file ``source`` as links of the site page ``page_uri``.

    A link into docs/ becomes the page it names; a link to a file of ``_LINK_MAP`` becomes its site copy;
    anything else is left for MkDocs to check (and to fail the strict build if it is broken).
    """
    base = posixpath.dirname(source)
    page_dir = posixpath.dirname(page_uri)

    def sub(m: re.Match) -> str:
        target, _, anchor = m.group(1).partition("#")
        if not target:
            return m.group(0)
        path = posixpath.normpath(posixpath.join(base, target))
        if path in _LINK_MAP:
            site = _LINK_MAP[path]
        elif path.startswith("docs/"):
            site = path[len("docs/"):]
        else:
            return m.group(0)
        rel = posixpath.relpath(site, page_dir or ".")
        return "](" + rel + ("#" + anchor if anchor else "") + ")"

    return _LINK.sub(sub, text)


def _generated_content(source: str, heading: str | None) -> str:
    text = (ROOT / source).read_text(encoding="utf-8")
    if heading is not None:  # a plain-text file, shown verbatim
        return f"# {heading}\n\n```text\n{text.rstrip()}\n```\n"
    return text


def on_files(files, config):
    """Add the site files generated from repository files."""
    for uri, (source, heading) in _GENERATED.items():
        if files.get_file_from_path(uri) is not None:
            raise ValueError(f"docs/{uri} would hide the file generated from {source}; remove it")
        files.append(File.generated(config, uri, content=_generated_content(source, heading)))
    return files


_CLI_MARKER = "<!-- interprim-cli-help -->"


def _cli_help() -> str:
    import argparse

    old = os.environ.get("COLUMNS")
    os.environ["COLUMNS"] = "100"  # argparse wraps at the terminal width; fix it for a reproducible page
    try:
        from interprim.cli import build_parser

        parser = build_parser()
        out = ["## `interprim`", "", "```text", parser.format_help().rstrip(), "```", ""]
        sub = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
        for name, p in sub.choices.items():
            out += [f"## `interprim {name}`", "", "```text", p.format_help().rstrip(), "```", ""]
    finally:
        if old is None:
            os.environ.pop("COLUMNS", None)
        else:
            os.environ["COLUMNS"] = old
    return "\n".join(out)


def on_page_markdown(markdown, page, config, files):
    """Rewrite links to repository files; expand the command-line help marker."""
    uri = page.file.src_uri
    markdown = _rewrite_links(markdown, _SOURCE_OF.get(uri, "docs/" + uri), uri)
    if _CLI_MARKER in markdown:
        markdown = markdown.replace(_CLI_MARKER, _cli_help())
    return markdown
