"""From a scene file to a validated ``Scene``: the YAML reader and its limits, the groups and
their shapes (decomposed into simplices where asked), the initial states, the checks of the input
contract and the preflight that resolves the integrator.
"""
