"""The nodes' parameters: one table per node (name, type, range, default, runtime or not), the
checks and descriptors made from it, and the runtime gains an agent takes while it runs.
"""
