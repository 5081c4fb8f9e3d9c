"""What the checks of clients' requests ask of the address space (asyncua's
``iserver.aspace``): a node's class and references, a type's supertypes, the
built-in type a data type comes down to."""

from __future__ import annotations

from typing import Any

from asyncua import ua

#: The abstract numeric data types, and the built-in ones each takes.
NUMBERS = {ua.ObjectIds.Number: frozenset(range(2, 12)),  # SByte .. Double
           ua.ObjectIds.Integer: frozenset((2, 4, 6, 8)),
           ua.ObjectIds.UInteger: frozenset((3, 5, 7, 9))}
BASE = ua.ObjectIds.BaseDataType


def ns0(nodeid: ua.NodeId) -> int | None:
    """The numeric id of a node of the standard namespace, else None."""
    return nodeid.Identifier if nodeid.NamespaceIndex == 0 and isinstance(nodeid.Identifier, int) else None


class TypeInfo:
    """Questions to one address space; a data type's kind is kept once asked."""

    def __init__(self, aspace: Any) -> None:
        self.aspace = aspace
        self._kinds: dict[ua.NodeId, int | None] = {}

    def __contains__(self, nodeid: ua.NodeId) -> bool:
        return nodeid in self.aspace

    def attribute(self, nodeid: ua.NodeId, attr: ua.AttributeIds) -> Any:
        dv = self.aspace.read_attribute_value(nodeid, attr)
        return None if dv.Value is None else dv.Value.Value

    def refs(self, nodeid: ua.NodeId) -> list[ua.ReferenceDescription]:
        return list(self.aspace[nodeid].references) if nodeid in self.aspace else []

    def forward(self, nodeid: ua.NodeId, ref_types: tuple[int, ...]) -> list[ua.ReferenceDescription]:
        return [r for r in self.refs(nodeid) if r.IsForward and ns0(r.ReferenceTypeId) in ref_types]

    def property_value(self, nodeid: ua.NodeId, name: str) -> Any:
        """The value of the node's property ``name`` (None: none)."""
        for r in self.forward(nodeid, (ua.ObjectIds.HasProperty,)):
            if r.BrowseName.Name == name:
                return self.attribute(r.NodeId, ua.AttributeIds.Value)
        return None

    def supertypes(self, type_id: ua.NodeId) -> list[ua.NodeId]:
        """The type and its supertypes, nearest first."""
        out, seen = [], set()
        t: ua.NodeId | None = type_id
        while t is not None and t not in seen:
            seen.add(t)
            out.append(t)
            t = next((r.NodeId for r in self.refs(t)
                      if not r.IsForward and ns0(r.ReferenceTypeId) == ua.ObjectIds.HasSubtype), None)
        return out

    def kind(self, data_type: ua.NodeId) -> int | None:
        """The built-in type id (1 to 25) a data type is (an enumeration: Int32, a
        structure: ExtensionObject), an abstract kind (BaseDataType, Number, Integer,
        UInteger), or None: not known."""
        if data_type in self._kinds:
            return self._kinds[data_type]
        kind = None
        for t in self.supertypes(data_type):
            i = ns0(t)
            if i is None:
                continue
            if i == ua.ObjectIds.Enumeration:
                kind = ua.VariantType.Int32.value
            elif i == ua.ObjectIds.Structure or 1 <= i <= 25 or i in NUMBERS:
                kind = i
            else:
                continue
            break
        self._kinds[data_type] = kind
        return kind
