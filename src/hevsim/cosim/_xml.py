"""XML reading helpers shared by the SSD reader and the SIMULIA CSE importer: errors name the
file, the line or the element."""

from __future__ import annotations

import xml.etree.ElementTree as ET
from pathlib import Path

from hevsim.errors import ConfigError


def parse_xml(path: Path, text: bytes | None = None) -> ET.Element:
    """The root element of ``path`` (or of ``text``, read as if it came from ``path``)."""
    try:
        return ET.fromstring(text) if text is not None else ET.parse(path).getroot()
    except ET.ParseError as exc:
        line = exc.position[0]
        raise ConfigError(f"{path}: line {line}: not well-formed XML ({exc}).") from None
    except OSError as exc:
        raise ConfigError(f"{path}: cannot read ({exc.strerror}).") from None


def required(el: ET.Element, attr: str, where: str) -> str:
    """The non-empty attribute ``attr`` of ``el``."""
    v = el.get(attr)
    if v is None or v == "":
        raise ConfigError(f"{where}: element <{local_name(el.tag)}> lacks required attribute {attr!r}.")
    return v


def local_name(tag: str) -> str:
    """``"{namespace}tag"`` -> ``"tag"``."""
    return tag.rsplit("}", 1)[-1]


def number(v: str, what: str) -> float:
    """``v`` as a float; ``what`` names it in the error."""
    try:
        return float(v)
    except ValueError:
        raise ConfigError(f"{what}: {v!r} is not a number.") from None
