"""Learning partial model (paper §3.7, Eqs. 12–13): gradient descent over model-space addresses, its laps run
as batches of parallel simulations (``twin.closed_loop.run_laps``); alignment to a lap time or a recorded run;
design studies; the live twin's re-alignment.

Importing ``tuner`` loads nothing heavy (``python -m tuner`` handles Ctrl-C from its first instant); import the
modules: ``tuner.gradient``, ``tuner.objective``, ``tuner.space``, ``tuner.align``, ``tuner.design``, …
"""
