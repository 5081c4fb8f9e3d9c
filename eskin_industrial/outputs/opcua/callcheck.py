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

from .typeinfo import BASE, NUMBERS, TypeInfo
from .uaconv import status_code

_HAS_COMPONENT = (ua.ObjectIds.HasComponent, ua.ObjectIds.HasOrderedComponent)
_OBJECTS = (ua.NodeClass.Object, ua.NodeClass.ObjectType)


class CallCheck:
    """The checks on one server's address space."""

    def __init__(self, types: TypeInfo) -> None:
        self.types = types

    def problem(self, m: ua.CallMethodRequest) -> ua.CallMethodResult | None:
        """The result a request is refused with, or None: it may run."""
        t = self.types
        if m.ObjectId not in t:
            return ua.CallMethodResult(StatusCode=status_code(ua.StatusCodes.BadNodeIdUnknown))
        if t.attribute(m.ObjectId, ua.AttributeIds.NodeClass) not in _OBJECTS:
            return ua.CallMethodResult(StatusCode=status_code(ua.StatusCodes.BadNodeIdInvalid))
        if (m.MethodId not in t or t.attribute(m.MethodId, ua.AttributeIds.NodeClass) != ua.NodeClass.Method
                or not self._is_method_of(m.MethodId, m.ObjectId)):
            return ua.CallMethodResult(StatusCode=status_code(ua.StatusCodes.BadMethodInvalid))
        declared = [a for a in (t.property_value(m.MethodId, "InputArguments") or []) if isinstance(a, ua.Argument)]
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

    def _is_method_of(self, method: ua.NodeId, obj: ua.NodeId) -> bool:
        """A component of the object, or of its type definition or one of that's supertypes."""
        t = self.types
        holders = [obj]
        for r in t.forward(obj, (ua.ObjectIds.HasTypeDefinition,)):
            holders.extend(t.supertypes(r.NodeId))
        return any(r.NodeId == method for h in holders for r in t.forward(h, _HAS_COMPONENT))

    def _fits(self, v: ua.Variant, arg: ua.Argument) -> bool:
        rank = arg.ValueRank
        if rank == -1 and v.is_array or rank >= 0 and not v.is_array:
            return False
        kind = self.types.kind(arg.DataType)
        if kind is None or kind == BASE:
            return True
        if kind in NUMBERS:
            return v.VariantType.value in NUMBERS[kind]
        return v.VariantType.value == kind


def guard(iserver: Any, on_refused: Callable[[int], None] = lambda code: None) -> None:
    """Check every Call request before asyncua's method service (``iserver.method_service``)
    runs it; ``on_refused(code)`` for each call refused."""
    check = CallCheck(TypeInfo(iserver.aspace))
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
