"""The one stepper: the solver contract (methods yield their stages, one ``drive``), the
Runge-Kutta and Lie-group methods, the second-order and adaptive ones, the registry, the
stability bounds, the centralised run (``simulate``) and the whole model on one flat vector.
"""
