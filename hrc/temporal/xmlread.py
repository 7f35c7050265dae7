"""A minimal XML element tree that remembers line numbers (for one-line ``FILE:LINE`` errors)."""

from __future__ import annotations

from dataclasses import dataclass, field
from xml.parsers import expat

from hrc.errors import NetworkFileError

__all__ = ["XmlElement", "parse_xml"]


@dataclass
class XmlElement:
    tag: str  # local name, namespace dropped
    attrs: dict[str, str]
    line: int
    children: list[XmlElement] = field(default_factory=list)
    text: str = ""

    def find_all(self, tag: str) -> list[XmlElement]:
        return [c for c in self.children if c.tag == tag]


def parse_xml(data: bytes, file: str) -> XmlElement:
    """Parse ``data``; raises `NetworkFileError` with the line of a syntax error."""
    parser = expat.ParserCreate(namespace_separator="}")
    root: list[XmlElement] = []
    stack: list[XmlElement] = []

    def start(name: str, attrs: dict[str, str]) -> None:
        el = XmlElement(name.rsplit("}", 1)[-1], attrs, parser.CurrentLineNumber)
        if stack:
            stack[-1].children.append(el)
        else:
            root.append(el)
        stack.append(el)

    def end(name: str) -> None:
        stack.pop()

    def chars(text: str) -> None:
        if stack:
            stack[-1].text += text

    parser.StartElementHandler = start
    parser.EndElementHandler = end
    parser.CharacterDataHandler = chars
    try:
        parser.Parse(data, True)
    except expat.ExpatError as err:
        raise NetworkFileError(file, "", f"not well-formed XML: {expat.errors.messages[err.code]}",
                               err.lineno) from err
    return root[0]
