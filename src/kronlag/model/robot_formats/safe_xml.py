"""Robot descriptions read as data: a hardened XML parser and located, one-line errors.

URDF, MJCF and SDF files are XML written by others.  :func:`read_xml` parses them with
``defusedxml`` (no entity expansion, no external entities or DTD fetches), within the size of
:data:`kronlag.core.limits.MAX_MODEL_FILE_BYTES` and a nesting of at most
:data:`MAX_XML_DEPTH` elements, and records the line of every element so that each message
names the file, the element and its line (``robot.urdf:42: <joint name="j1">: ...``).  Attribute
texts are only ever read as numbers (:func:`numbers`) or names: nothing is evaluated.  Xacro
macros are refused with the advice to run ``xacro`` first.
"""

from __future__ import annotations

import math
import xml.etree.ElementTree as ElementTree
from collections import Counter
from dataclasses import dataclass, field
from pathlib import Path

from defusedxml import DefusedXmlException
from defusedxml.ElementTree import DefusedXMLParser

from ...core.errors import ModelFileError
from ...core.limits import MAX_MODEL_FILE_BYTES

__all__ = ["XmlDocument", "read_xml", "MAX_XML_DEPTH", "MAX_XML_ELEMENTS", "XACRO_NAMESPACE"]

#: Deepest nesting of elements accepted (URDF nests 4 deep, MJCF bodies one level per link).
MAX_XML_DEPTH = 256

#: Most elements in one file (Talos' full URDF has about 2 000).
MAX_XML_ELEMENTS = 200_000

#: The namespace of xacro macros (``xmlns:xacro="http://www.ros.org/wiki/xacro"``).
XACRO_NAMESPACE = "http://www.ros.org/wiki/xacro"


class _LocatingBuilder(ElementTree.TreeBuilder):
    """A tree builder that records each element's line and bounds the depth and count of elements."""

    def __init__(self, source: str):
        super().__init__()
        self.source = source
        self.parser: DefusedXMLParser | None = None
        self.lines: dict[int, int] = {}
        self.depth = 0
        self.count = 0

    def start(self, tag, attributes):
        element = super().start(tag, attributes)
        line = self.parser.parser.CurrentLineNumber if self.parser is not None else 0
        self.depth += 1
        self.count += 1
        if self.depth > MAX_XML_DEPTH:
            raise ModelFileError(f"{self.source}:{line}: <{tag}>: elements nest more than {MAX_XML_DEPTH} deep")
        if self.count > MAX_XML_ELEMENTS:
            raise ModelFileError(f"{self.source}:{line}: more than {MAX_XML_ELEMENTS} elements")
        self.lines[id(element)] = line
        return element

    def end(self, tag):
        self.depth -= 1
        return super().end(tag)


@dataclass
class XmlDocument:
    """A parsed robot description: its root element, the line of each element and the
    elements the reader did not use (listed once by :meth:`skipped_summary`)."""

    source: str
    root: ElementTree.Element
    lines: dict[int, int]
    skipped: Counter = field(default_factory=Counter)

    def where(self, element: ElementTree.Element) -> str:
        """``FILE:LINE: <tag name="...">`` naming ``element``."""
        name = element.get("name")
        label = f"<{element.tag} name={name!r}>" if name is not None else f"<{element.tag}>"
        return f"{self.source}:{self.lines.get(id(element), '?')}: {label}"

    def error(self, element: ElementTree.Element, problem: str) -> ModelFileError:
        """A :class:`ModelFileError` ``FILE:LINE: <element>: problem``."""
        return ModelFileError(f"{self.where(element)}: {problem}")

    def skip(self, element: ElementTree.Element, parent: str = "") -> None:
        """Note that ``element`` (inside ``parent``) is not used."""
        self.skipped[f"{parent}/{element.tag}" if parent else element.tag] += 1

    def skipped_summary(self) -> str:
        """The skipped elements with their counts, ``""`` if none."""
        return ", ".join(f"{tag} ({count})" if count > 1 else tag for tag, count in sorted(self.skipped.items()))

    def number(self, element: ElementTree.Element, attribute: str, default: float | None = None) -> float:
        """The attribute as one finite number (``default`` if absent; an error if absent without one)."""
        values = self.numbers(element, attribute, 1, default=None if default is None else (default,))
        return values[0]

    def numbers(self, element: ElementTree.Element, attribute: str, count: int,
                default: tuple[float, ...] | None = None) -> tuple[float, ...]:
        """The attribute as ``count`` whitespace-separated finite numbers (``default`` if absent)."""
        text = element.get(attribute)
        if text is None:
            if default is None:
                raise self.error(element, f"needs the attribute {attribute}=\"...\" ({count} number"
                                          f"{'s' if count > 1 else ''})")
            return tuple(float(x) for x in default)
        values = numbers(text)
        if values is None or len(values) != count:
            raise self.error(element, f"{attribute}={text!r}: expected {count} finite number"
                                      f"{'s' if count > 1 else ''}")
        return values

    def required(self, element: ElementTree.Element, attribute: str) -> str:
        """The text of a required attribute (a name)."""
        text = element.get(attribute)
        if text is None or not text.strip():
            raise self.error(element, f"needs the attribute {attribute}=\"...\"")
        return text.strip()


def numbers(text: str) -> tuple[float, ...] | None:
    """The finite decimal numbers of a whitespace-separated text, ``None`` if any part is not one.

    >>> numbers("0 -1.5e-3  2")
    (0.0, -0.0015, 2.0)
    >>> numbers("${pi/2} 0") is None
    True
    """
    values = []
    for part in text.split():
        try:
            value = float(part)
        except ValueError:
            return None
        if not math.isfinite(value):
            return None
        values.append(value)
    return tuple(values)


def _read_bytes(path: Path) -> bytes:
    try:
        with open(path, "rb") as file:
            data = file.read(MAX_MODEL_FILE_BYTES + 1)
    except OSError as error:
        raise ModelFileError(f"{path}: cannot read the file: {error}") from None
    if len(data) > MAX_MODEL_FILE_BYTES:
        raise ModelFileError(f"{path}: the file is larger than {MAX_MODEL_FILE_BYTES} bytes")
    return data


def _refuse_xacro(document: XmlDocument) -> None:
    for element in document.root.iter():
        if str(element.tag).startswith("{" + XACRO_NAMESPACE + "}"):
            tag = element.tag.split("}")[1]
            raise ModelFileError(f"{document.source}:{document.lines.get(id(element), '?')}: <xacro:{tag}>: this is "
                                 f"a xacro file, which kronlag does not evaluate; run `xacro {document.source} > "
                                 "robot.urdf` first and load the URDF it writes")
        for attribute, value in element.attrib.items():
            if "${" in value or "$(" in value:
                raise document.error(element, f"{attribute}={value!r} is a xacro expression, which kronlag does not "
                                              f"evaluate; run `xacro {document.source} > robot.urdf` first")


def read_xml(path: str | Path) -> XmlDocument:
    """Parse the XML file ``path`` safely; every failure is one :class:`ModelFileError` line.

    Raises
    ------
    ModelFileError
        The file is unreadable, too large, not well-formed XML (with the line and column),
        declares entities or external references, nests too deep, or is xacro.
    """
    path = Path(path)
    source = str(path)
    if path.name.endswith(".xacro"):
        raise ModelFileError(f"{source}: this is a xacro file, which kronlag does not evaluate; run "
                             f"`xacro {source} > robot.urdf` first and load the URDF it writes")
    data = _read_bytes(path)
    builder = _LocatingBuilder(source)
    parser = DefusedXMLParser(target=builder, forbid_dtd=False, forbid_entities=True, forbid_external=True)
    builder.parser = parser
    try:
        parser.feed(data)
        root = parser.close()
    except ElementTree.ParseError as error:
        line, column = error.position
        reason = str(error).split(":")[0]
        raise ModelFileError(f"{source}:{line}: malformed XML at column {column + 1}: {reason}") from None
    except DefusedXmlException as error:
        what = f"the entity {error.name!r}" if getattr(error, "name", None) else "an external reference"
        raise ModelFileError(f"{source}:{parser.parser.CurrentLineNumber}: refused: the file declares {what} "
                             "(entity declarations and external references are not read: robot files are "
                             "data)") from None
    document = XmlDocument(source, root, builder.lines)
    _refuse_xacro(document)
    return document
