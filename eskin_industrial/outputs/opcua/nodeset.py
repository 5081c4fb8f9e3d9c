"""The type model as a NodeSet2 XML file (``eskin-bus opcua nodeset -o FILE``): what an
engineering tool or another OPC UA stack imports to know our types before it
connects (``GraspStateEnumeration``, ``GraspSensorType``, ``SlipAlarmType``, in our
namespace with their fixed ids), with its ``<Models>`` header requiring DI and
Machinery, whose types it uses.

Made by building the types in an asyncua server that never listens, and asyncua's
exporter writing that namespace; the tests load the file in node-opcua's address
space, an independent stack.
"""

from __future__ import annotations

import asyncio
import logging
import xml.etree.ElementTree as ET
from importlib import resources
from pathlib import Path
from typing import Any
from xml.sax.saxutils import quoteattr

from ... import __version__
from . import model

_UA = "{http://opcfoundation.org/UA/2011/03/UANodeSet.xsd}"
_STANDARD = "http://opcfoundation.org/UA/"


def escape(text: str) -> str:
    """An attribute's value, its quotes not included."""
    return quoteattr(text)[1:-1]


async def _export(path: Path) -> None:
    from asyncua import Server

    from .build import build_types
    from .companions import load_companions

    server = Server()
    await server.init()
    idx = await server.register_namespace(model.NAMESPACE_URI)
    await load_companions(server)  # the types ours are built on (DI, Machinery)

    def no_call(name: str) -> Any:
        async def call(parent: Any, *args: Any) -> Any:  # never called: the server does not run
            return []

        return call

    await build_types(server, idx, no_call)
    await server.export_xml_by_ns(str(path), [idx], export_values=True)  # EnumStrings, InputArguments
    server.iserver.method_service.stop()
    text = path.read_text(encoding="utf-8")
    path.write_text(text.replace("</NamespaceUris>", "</NamespaceUris>\n" + models_header(), 1), encoding="utf-8")


def models_header() -> str:
    """``<Models>``: ours, requiring what it is built on (asyncua's exporter writes
    none): DI and Machinery in the versions shipped, and the standard model in the
    newest version they require, so that an importer knows what to load first."""
    from .companions import DI_URI, MACHINERY_URI, NODESETS

    shipped: dict[str, dict[str, str]] = {}
    standard: dict[str, str] = {}
    for _uri, name in NODESETS:
        root = ET.fromstring(resources.files("eskin_industrial").joinpath("data", "nodesets", name).read_bytes())
        for m in root.iter(_UA + "Model"):
            shipped[m.get("ModelUri", "")] = dict(m.attrib)
            for req in m.iter(_UA + "RequiredModel"):
                if req.get("ModelUri") == _STANDARD and req.get("PublicationDate", "") > standard.get(
                        "PublicationDate", ""):
                    standard = dict(req.attrib)

    def required(attrs: dict[str, str]) -> str:
        keys = ("ModelUri", "Version", "PublicationDate")
        return "<RequiredModel " + " ".join(f'{k}="{escape(attrs[k])}"' for k in keys if k in attrs) + " />"

    return (f'  <Models>\n    <Model ModelUri="{escape(model.NAMESPACE_URI)}" Version="{escape(__version__)}">\n'
            + "".join(f"      {required(a)}\n" for a in (standard, shipped[DI_URI], shipped[MACHINERY_URI]))
            + "    </Model>\n  </Models>")


def write_nodeset(path: str | Path) -> None:
    """Write the type model's NodeSet2 to ``path``."""
    quiet = logging.getLogger("asyncua")
    level = quiet.level
    quiet.setLevel(logging.ERROR)  # its exporter's notes about the standard nodes it skips
    try:
        asyncio.run(_export(Path(path)))
    finally:
        quiet.setLevel(level)
