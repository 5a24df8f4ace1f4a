"""Learning partial model (paper §3.7, Eqs. 12–13): batched gradient descent over model-space addresses.

Not implemented yet: see the learning-model issue. The package exists so the layout is fixed from the start.
"""
