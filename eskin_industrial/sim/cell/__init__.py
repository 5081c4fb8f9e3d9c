"""The closed loop: a virtual cell in which the gripper reacts and the object is held
or dropped (docs/cell.md).

- ``objects.py``, ``task.py``: what the cell handles (mass, friction, crush force,
  footprint, drawn per seed) and what the arm does with it (lift, transport, pour,
  bump, place), as tables over time;
- ``physics.py``: friction between two fingers and the object (from pure Coulomb to
  strong velocity strengthening, a Stribeck fall and the pad's stick-slip where the law
  makes one), stepped in time (stick or slide, the distance slid, dropped, crushed);
  ``actuator.py``: the gripper's force with a dead time and a rate limit, within a
  gripper class's range, steps and error (``grippers.py``); ``render.py``: the taxel
  frames the node sends, from that state, with the scenes' sensor effects.  No I/O in
  any of them;
- ``world.py``: those together, advanced tick by tick (what both runs share);
- ``policy.py``: the PLC program (grip lightly, raise on slip, relax after a quiet
  time; "no verdict" is not "no slip"); ``recipes.py``: its forces per object, and the
  fixed grip a cautious integrator would set;
- ``gripper.py``: the gripper as a Modbus TCP device with a small register map;
- ``realtime.py``: the cell through the real chain (CAN node, bridge, Modbus TCP to the
  PLC stand-in, Modbus TCP to the gripper); ``virtual.py``: the same cell stepped in
  virtual time with the chain's measured latencies (``latency.py``);
- ``episodes.py``, ``scoring.py``, ``sweeps.py``, ``charts.py``: the closed-loop
  evaluation (``eskin-bus evaluate --closed-loop``).
"""
