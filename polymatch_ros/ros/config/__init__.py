"""The nodes' parameters: one table per node (name, type, range, default, runtime or not), the
checks and descriptors made from it, the typed configuration of each node (``configs``: the one
renderer of a node's command line, the one reader), what a node resolves from its scene
(``resolve``), and the runtime gains an agent takes while it runs.
"""
