"""Several "hosts" on one machine, for the lossy benchmark and the multi-host tests.

    namespaces  network namespaces joined by a bridge, loss rules, DDS packet capture
    runs        bounded processes ended by PID, one `polymatch run --only ...` per host
"""
