"""OPC UA: the ``opcua`` output, a server of the bridge's grasp states for SCADA, MES,
historians and PLCs with an OPC UA client.

- :mod:`.options`: ``[opcua]`` (endpoint, security, limits);
- :mod:`.model`: the information model as data, the values of a snapshot;
- :mod:`.status`: the status codes that say "I don't know";
- :mod:`.build`: the model in asyncua's address space; :mod:`.nodeset`: its NodeSet2;
- :mod:`.server`: the server's life (thread, loop, turns, counters); :mod:`.handover`:
  snapshots to it; :mod:`.nodestate`: what it keeps of a node; :mod:`.report`: its
  counters and events; :mod:`.stacklog`: what asyncua logs;
- :mod:`.values`: the snapshots applied to the address space; :mod:`.calls`: the
  methods; :mod:`.alarm`: the slip alarm's state, :mod:`.alarm_events`: its events
  and Acknowledge;
- :mod:`.itemcheck`: the clients' monitored items checked (:mod:`.eventfilter`, their
  event filters; :mod:`.deadband`, their deadbands); :mod:`.callcheck`: their calls
  checked; :mod:`.typeinfo`: what both ask of the address space;
- :mod:`.wire`: the first message of a connection checked, refusals told;
- :mod:`.logins`: the security set up, logins counted; :mod:`.access`, :mod:`.users`,
  :mod:`.pki`: roles, users, certificates;
- :mod:`.sink`: the output kind.

asyncua (the ``opcua`` extra) is imported only when the output opens or a command
needs it; the model, the status rules and the options are pure code.
"""
