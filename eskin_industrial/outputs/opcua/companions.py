"""The companion specifications the model is built on, loaded into the server before
our own nodes: OPC 10000-100 (Devices, DI), Industrial Automation (IA,
which Machinery requires) and OPC 40001-1 (Machinery), the OPC Foundation's NodeSet2
files as they are published (``eskin_industrial/data/nodesets/``, with their licence).

The one thing left out on the way in: DI's nodes marked ``DesignToolOnly``
(``Configuration``, ``Tuning`` ... : browse names for engineering tools, with no
parent; a server does not hold them, and asyncua refuses a node with no parent).
"""

from __future__ import annotations

import logging
import xml.etree.ElementTree as ET
from importlib import resources
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from asyncua import Server

DI_URI = "http://opcfoundation.org/UA/DI/"
IA_URI = "http://opcfoundation.org/UA/IA/"
MACHINERY_URI = "http://opcfoundation.org/UA/Machinery/"
#: In the order they are loaded (each after what it requires).
NODESETS: tuple[tuple[str, str], ...] = (
    (DI_URI, "Opc.Ua.Di.NodeSet2.xml"),
    (IA_URI, "Opc.Ua.IA.NodeSet2.xml"),
    (MACHINERY_URI, "Opc.Ua.Machinery.NodeSet2.xml"),
)
_UANODESET = "{http://opcfoundation.org/UA/2011/03/UANodeSet.xsd}"


def nodeset_text(name: str) -> str:
    """One shipped NodeSet2 file, its ``DesignToolOnly`` nodes left out."""
    raw = resources.files("eskin_industrial").joinpath("data", "nodesets", name).read_bytes()
    ET.register_namespace("", _UANODESET[1:-1])
    root = ET.fromstring(raw)
    for node in [n for n in root if n.get("DesignToolOnly") == "true"]:
        root.remove(node)
    return ET.tostring(root, encoding="unicode")


async def load_companions(server: Server) -> dict[str, int]:
    """DI, IA and Machinery in ``server``; their namespace indexes by URI."""
    # the importer warns of the files' own duplicate parent references (a child two
    # types declare) and of DI's two OptionSet types with a DataTypeDefinition: each
    # file is loaded whole (strict mode raises on any node it cannot add), these
    # warnings are no fault of ours nor of a client's
    importer_log = logging.getLogger("asyncua.common.xmlimporter")
    level = importer_log.level
    importer_log.setLevel(logging.ERROR)
    try:
        for _uri, name in NODESETS:
            await server.import_xml(xmlstring=nodeset_text(name))
    finally:
        importer_log.setLevel(level)
    return {uri: await server.get_namespace_index(uri) for uri, _ in NODESETS}
