"""Identification of a rover's inner loops: the fit of the vehicle model to a log, priors, the excitation manoeuvre.

May import: ``core``, ``sim``, ``live`` (pymavlink set-up), ``logs``, ``profiles``, ``errors``; only ``commands`` imports it.
"""
