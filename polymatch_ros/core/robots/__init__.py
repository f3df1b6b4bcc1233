"""From the model's motion to robots' commands: commands and their limits, shaping (formation,
separation, drive), the formation offsets, the control-barrier safety filter and unicycle bases.
"""
