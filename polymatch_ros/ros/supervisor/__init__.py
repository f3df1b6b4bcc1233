"""What starts, watches, summarises and ends ROS processes: ``polymatch run`` (the
launch-free runner and its children), the lifecycle driver, the recorder child and
``polymatch set``.  It imports no node module: what it shares with the nodes is in ``wire``,
``config``, ``process`` and ``network``.
"""
