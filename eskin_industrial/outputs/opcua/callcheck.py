"""The Call service's requests checked as Part 4 (5.11.2) says, before asyncua runs a
method: asyncua runs any method node on any object, pads missing results Good, and
hands the arguments over unchecked.

For each CallMethodRequest, in this order:

- the object does not exist: BadNodeIdUnknown; it is no Object or ObjectType:
  BadNodeIdInvalid;
- the method does not exist, is no Method, or is not a component of the object (nor
  of its type definition or a supertype of it): BadMethodInvalid;
- fewer arguments than its InputArguments declare: BadArgumentsMissing; more:
  BadTooManyArguments;
- an argument of another built-in type, or a scalar for an array (or the reverse):
  BadInvalidArgument, with a result per argument (BadTypeMismatch for each such
  argument, Good for the others).

A data type that is abstract above the built-in ones (BaseDataType, Number, Integer,
UInteger) takes what it allows; a structure takes an ExtensionObject, an enumeration
an Int32.
"""

from __future__ import annotations

from collections.abc import Awaitable, Callable
from typing import Any

from asyncua import ua

from .uaconv import status_code

_HAS_COMPONENT = (ua.ObjectIds.HasComponent, ua.ObjectIds.HasOrderedComponent)
_NUMBERS = {ua.ObjectIds.Number: frozenset(range(2, 12)),  # SByte .. Double
            ua.ObjectIds.Integer: frozenset((2, 4, 6, 8)),
            ua.ObjectIds.UInteger: frozenset((3, 5, 7, 9))}
_ENUMERATION = ua.ObjectIds.Enumeration
_STRUCTURE = ua.ObjectIds.Structure
_BASE = ua.ObjectIds.BaseDataType
_OBJECTS = (ua.NodeClass.Object, ua.NodeClass.ObjectType)


def _ns0(nodeid: ua.NodeId) -> int | None:
    return nodeid.Identifier if nodeid.NamespaceIndex == 0 and isinstance(nodeid.Identifier, int) else None


class CallCheck:
    """The checks on one server's address space (asyncua's ``iserver.aspace``)."""

    def __init__(self, aspace: Any) -> None:
        self.aspace = aspace
        self._kinds: dict[ua.NodeId, int | None] = {}  #: a data type's built-in type (or abstract kind)

    def problem(self, m: ua.CallMethodRequest) -> ua.CallMethodResult | None:
        """The result a request is refused with, or None: it may run."""
        a = self.aspace
        if m.ObjectId not in a:
            return ua.CallMethodResult(StatusCode=status_code(ua.StatusCodes.BadNodeIdUnknown))
        if self._node_class(m.ObjectId) not in _OBJECTS:
            return ua.CallMethodResult(StatusCode=status_code(ua.StatusCodes.BadNodeIdInvalid))
        if (m.MethodId not in a or self._node_class(m.MethodId) != ua.NodeClass.Method
                or not self._is_method_of(m.MethodId, m.ObjectId)):
            return ua.CallMethodResult(StatusCode=status_code(ua.StatusCodes.BadMethodInvalid))
        declared = self._input_arguments(m.MethodId)
        given = m.InputArguments or []
        if len(given) < len(declared):
            return ua.CallMethodResult(StatusCode=status_code(ua.StatusCodes.BadArgumentsMissing))
        if len(given) > len(declared):
            return ua.CallMethodResult(StatusCode=status_code(ua.StatusCodes.BadTooManyArguments))
        results = [status_code(ua.StatusCodes.Good if self._fits(v, d) else ua.StatusCodes.BadTypeMismatch)
                   for v, d in zip(given, declared)]
        if all(r.is_good() for r in results):
            return None
        return ua.CallMethodResult(StatusCode=status_code(ua.StatusCodes.BadInvalidArgument),
                                   InputArgumentResults=results)

    def _node_class(self, nodeid: ua.NodeId) -> Any:
        dv = self.aspace.read_attribute_value(nodeid, ua.AttributeIds.NodeClass)
        return None if dv.Value is None else dv.Value.Value

    def _refs(self, nodeid: ua.NodeId) -> list[ua.ReferenceDescription]:
        return list(self.aspace[nodeid].references) if nodeid in self.aspace else []

    def _is_method_of(self, method: ua.NodeId, obj: ua.NodeId) -> bool:
        """A component of the object, or of its type definition or one of that's supertypes."""
        holders = [obj]
        for r in self._refs(obj):
            if r.IsForward and _ns0(r.ReferenceTypeId) == ua.ObjectIds.HasTypeDefinition:
                holders.extend(self._supertypes(r.NodeId))
        return any(r.IsForward and _ns0(r.ReferenceTypeId) in _HAS_COMPONENT and r.NodeId == method
                   for h in holders for r in self._refs(h))

    def _supertypes(self, type_id: ua.NodeId) -> list[ua.NodeId]:
        out, seen = [], set()
        t: ua.NodeId | None = type_id
        while t is not None and t not in seen:
            seen.add(t)
            out.append(t)
            t = next((r.NodeId for r in self._refs(t)
                      if not r.IsForward and _ns0(r.ReferenceTypeId) == ua.ObjectIds.HasSubtype), None)
        return out

    def _input_arguments(self, method: ua.NodeId) -> list[ua.Argument]:
        for r in self._refs(method):
            if (r.IsForward and _ns0(r.ReferenceTypeId) == ua.ObjectIds.HasProperty
                    and r.BrowseName.Name == "InputArguments"):
                dv = self.aspace.read_attribute_value(r.NodeId, ua.AttributeIds.Value)
                value = None if dv.Value is None else dv.Value.Value
                return [a for a in (value or []) if isinstance(a, ua.Argument)]
        return []

    def _kind(self, data_type: ua.NodeId) -> int | None:
        """The built-in type id (1 to 25) a data type is, an abstract kind (BaseDataType,
        Number, Integer, UInteger), or None: not known (taken as anything)."""
        if data_type in self._kinds:
            return self._kinds[data_type]
        kind = None
        for t in self._supertypes(data_type):
            i = _ns0(t)
            if i is None:
                continue
            if i == _ENUMERATION:
                kind = ua.VariantType.Int32.value
            elif i == _STRUCTURE or 1 <= i <= 25 or i in _NUMBERS:
                kind = i
            else:
                continue
            break
        self._kinds[data_type] = kind
        return kind

    def _fits(self, v: ua.Variant, arg: ua.Argument) -> bool:
        rank = arg.ValueRank
        if rank == -1 and v.is_array or rank >= 0 and not v.is_array:
            return False
        kind = self._kind(arg.DataType)
        if kind is None or kind == _BASE:
            return True
        if kind in _NUMBERS:
            return v.VariantType.value in _NUMBERS[kind]
        return v.VariantType.value == kind


def guard(iserver: Any, on_refused: Callable[[int], None] = lambda code: None) -> None:
    """Check every Call request before asyncua's method service (``iserver.method_service``)
    runs it; ``on_refused(code)`` for each call refused."""
    check = CallCheck(iserver.aspace)
    service = iserver.method_service
    call: Callable[[list[ua.CallMethodRequest]], Awaitable[list[ua.CallMethodResult]]] = service.call

    async def checked(methods: list[ua.CallMethodRequest]) -> list[ua.CallMethodResult]:
        out = []
        for m in methods or []:
            refused = check.problem(m)
            if refused is None:
                out.extend(await call([m]))
            else:
                on_refused(refused.StatusCode.value)
                out.append(refused)
        return out

    # (on the instance: every session of this server calls its one method service)
    service.call = checked
