"""The bridge: the per-node loop (``loop``: source -> pipeline -> register image ->
sinks), the process that runs every node's loop and supervises it (``runtime``), its
configuration (``config``: ``bridge.toml`` and the single-node command lines) and its
structured logs (``logs``)."""
