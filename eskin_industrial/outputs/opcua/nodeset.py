"""The type model as a NodeSet2 XML file (``eskin-bus opcua nodeset -o FILE``): what an
engineering tool or another OPC UA stack imports to know our types before it
connects (``GraspStateEnumeration``, ``GraspSensorType``, ``SlipAlarmType``, in our
namespace with their fixed ids).

Made by building the types in an asyncua server that never listens, and asyncua's
exporter writing that namespace; the tests load the file in node-opcua's address
space, an independent stack.
"""

from __future__ import annotations

import asyncio
import logging
from pathlib import Path
from typing import Any

from . import model


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


def write_nodeset(path: str | Path) -> None:
    """Write the type model's NodeSet2 to ``path``."""
    quiet = logging.getLogger("asyncua")
    level = quiet.level
    quiet.setLevel(logging.ERROR)  # its exporter's notes about the standard nodes it skips
    try:
        asyncio.run(_export(Path(path)))
    finally:
        quiet.setLevel(level)
