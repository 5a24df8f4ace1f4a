"""The learning partial model (paper §3.7, Eqs. 12–13) and the studies built on the twin, in rooms:

* :mod:`tuner.search`: the search space, the lap objective over an envelope, gradient descent (Eq. 12);
* :mod:`tuner.align`: alignment to a lap time or a recorded run, and diagnosis of a robot unlike its twin;
* :mod:`tuner.live`: the twin beside the running robot (compare each lap, re-align in the background);
* :mod:`tuner.studies`: design studies (their evidence, report and Ray cluster runner) and sensitivity sweeps;
* :mod:`tuner.sensitivity`: the model space's relations learned from laps (global sensitivity: Morris, Sobol');
* :mod:`tuner.recording`: rerun recordings of all of these.

Importing ``tuner`` loads nothing heavy (``python -m tuner`` handles Ctrl-C from its first instant).
"""
