"""Streaming XML for network files, hardened against hostile input.

`hardened_parser` gives an expat parser on which a reader sets its own element and text handlers (the
GraphML reader keeps only what it needs, collects text in pieces and joins it once, so memory follows the
network and text that arrives in a million pieces costs linear time); `parse` runs it. Refused, each with
one `NetworkFileError` line: malformed XML (expat's message and line), entity declarations (GraphML needs
none; this also rules out entity-expansion bombs, on top of expat's own amplification limit, and external
entities), and encodings expat cannot read (multi-byte ones other than UTF-8 and UTF-16, or unknown
names). Readers refuse elements nested deeper than `MAX_DEPTH` themselves.
"""

from __future__ import annotations

from xml.parsers import expat

from hrc.errors import NetworkFileError
from hrc.temporal.limits import show

__all__ = ["MAX_DEPTH", "hardened_parser", "parse"]

MAX_DEPTH = 64
"""Deepest element nesting accepted (GraphML network files need 4)."""


def hardened_parser(file: str) -> expat.XMLParserType:
    """An expat parser (namespaces split with ``}``, text buffered) that refuses entity declarations;
    the caller sets its element and text handlers and runs it with `parse`."""
    parser = expat.ParserCreate(namespace_separator="}")

    def on_entity(*_args: object) -> None:
        raise NetworkFileError(file, "", "entity declarations are not allowed in a network file",
                               parser.CurrentLineNumber)

    parser.EntityDeclHandler = on_entity
    parser.buffer_text = True
    return parser


def parse(parser: expat.XMLParserType, data: bytes, file: str) -> None:
    """Run ``parser`` over ``data``; expat's and the codecs' errors become `NetworkFileError` lines."""
    try:
        parser.Parse(data, True)
    except expat.ExpatError as err:
        raise NetworkFileError(file, "", f"not well-formed XML: {expat.errors.messages[err.code]}",
                               err.lineno) from err
    except (LookupError, ValueError) as err:  # an encoding expat cannot read ("foo", "utf-32", ...)
        raise NetworkFileError(file, "", f"cannot read the XML text: {show(str(err))}", 1) from err
