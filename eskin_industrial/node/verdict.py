"""A detector update as an output shows it: no verdict while the sensor has a fault.

While a sensor fault is set (:data:`~eskin_industrial.frames.SENSOR_FAULTS`: DEAD_TAXELS,
FROZEN, RATE, STREAM) the node claims no state (:meth:`.NodeStatus.snapshot`): the
PLC's STATE reads 0 with DATA_VALID clear, Sparkplug's State ``no_contact`` with Data
Valid false.  A row of updates (``eskin-bus detect``'s output, the bridge's recorder,
``receive -o``) says the same through :func:`shown`: the detector goes on behind it
(its own states are the snapshot's ``detected_state``), but what it decides on held or
frozen readings, or on scans at a rate its windows were not counted in, is no
measurement.

Pure code: no I/O, no clock.
"""

from __future__ import annotations

import math

from ..detect.updates import Update
from ..frames import SENSOR_FAULTS

_NONE = math.nan  #: a figure that is none (the snapshot's None), as a row of floats writes it


def shown(update: Update, fault: int) -> Update:
    """``update`` as the outputs show it while the sensor's fault bits are ``fault``:
    itself with none; under one, no verdict: state code 0 (``no_contact``, as STATE
    reads when nothing is claimed), not valid, no indicators, scores or total force
    (NaN), the centre of force kept (the snapshot holds it too), the fault's bits
    joined to the flags."""
    fault &= SENSOR_FAULTS
    if not fault:
        return update
    return Update(update.t, _NONE, _NONE, 0, False, _NONE, update.xc, update.yc, update.flags | fault, _NONE, _NONE)


__all__ = ["shown"]
