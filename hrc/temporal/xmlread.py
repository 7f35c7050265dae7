"""Streaming XML for network files: element events with line numbers, hardened against hostile input.

`stream_xml` calls ``start(tag, attrs, line)`` and ``end(tag, text, line)`` for each element (namespace
dropped from tags; ``text`` is the element's own character data, collected in pieces and joined once, so
text that arrives in a million small pieces costs linear time). Nothing but the caller's own state is
kept, so memory follows what the caller keeps, not the size of the document. A reader that needs speed
(GraphML) sets its own handlers on `hardened_parser` and runs `parse`; it then checks `MAX_DEPTH` itself.

Refused, each with one `NetworkFileError` line: malformed XML (expat's message and line), entity
declarations (GraphML needs none; this also rules out entity-expansion bombs, on top of expat's own
amplification limit), documents nested deeper than `MAX_DEPTH`, and encodings expat cannot read
(multi-byte ones other than UTF-8 and UTF-16, or unknown names).
"""

from __future__ import annotations

from collections.abc import Callable
from xml.parsers import expat

from hrc.errors import NetworkFileError

__all__ = ["MAX_DEPTH", "hardened_parser", "parse", "stream_xml"]

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
        raise NetworkFileError(file, "", f"cannot read the XML text: {err}", 1) from err


def stream_xml(data: bytes, file: str, start: Callable[[str, dict[str, str], int], None],
               end: Callable[[str, str, int], None]) -> None:
    """Parse ``data`` calling ``start`` / ``end`` per element; raises `NetworkFileError` (see the module
    docstring). Exceptions raised by the callbacks propagate unchanged."""
    parser = hardened_parser(file)
    texts: list[list[str]] = []

    def on_start(name: str, attrs: dict[str, str]) -> None:
        if len(texts) >= MAX_DEPTH:
            raise NetworkFileError(file, "", f"elements nested more than {MAX_DEPTH} deep",
                                   parser.CurrentLineNumber)
        texts.append([])
        start(name[name.rfind("}") + 1:], attrs, parser.CurrentLineNumber)

    def on_end(name: str) -> None:
        end(name[name.rfind("}") + 1:], "".join(texts.pop()), parser.CurrentLineNumber)

    def on_chars(text: str) -> None:
        if texts:
            texts[-1].append(text)

    parser.StartElementHandler = on_start
    parser.EndElementHandler = on_end
    parser.CharacterDataHandler = on_chars
    parse(parser, data, file)
