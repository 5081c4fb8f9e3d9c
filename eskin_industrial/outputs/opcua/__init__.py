"""OPC UA: the ``opcua`` output, a server of the bridge's grasp states for SCADA, MES,
historians and PLCs with an OPC UA client.

- :mod:`.options`: ``[opcua]`` (endpoint, security, limits);
- :mod:`.model`: the information model as data, the values of a snapshot;
- :mod:`.status`: the status codes that say "I don't know";
- :mod:`.build`: the model in asyncua's address space; :mod:`.nodeset`: its NodeSet2;
- :mod:`.server`: the server's thread and loop; :mod:`.handover`: snapshots to it;
- :mod:`.alarm`: the slip alarm's state; :mod:`.access`, :mod:`.users`, :mod:`.pki`:
  roles, users, certificates;
- :mod:`.sink`: the output kind.

asyncua (the ``opcua`` extra) is imported only when the output opens or a command
needs it; the model, the status rules and the options are pure code.
"""
