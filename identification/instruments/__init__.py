"""The virtual instruments: recordings made with a known truth.

:mod:`~identification.instruments.tunnel` re-creates the paper's wind-tunnel
experiment and :mod:`~identification.instruments.flightlog` a flight
computer's log of an ascent; both fly the rocket by
:mod:`~identification.instruments.reference`, an integrator of its physics
written apart from the roll model the methods fit, so that a truth outside the
model class checks them.  :mod:`~identification.instruments.bundled` lists the
recordings shipped with the package and the commands that made them.
"""
