"""The commissioning console: a web output kind (``[web]`` in the bridge configuration,
``--web HOST:PORT`` on the command line).  One aiohttp server for the bridge, on a
thread and an asyncio loop of its own (:mod:`.server`), serving the cell page, a page
per node (the live heat map, the centre of force, the scores and the paper's
indicators as trends, the state lane, the health flags) and the events page (each
slip and varying-force episode, with the raw scans around it as a recording CSV).
Commands (tare, acknowledge, enable) behind a login, under the one refusal rule.
The node's loop only stores the newest values (:mod:`.hub`); each browser is sent the
newest state at its own pace.  docs/web.md.
"""
