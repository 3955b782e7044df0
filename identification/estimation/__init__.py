"""The estimation core: linear Gaussian state-space models and maximum likelihood on them.

:mod:`~identification.estimation.statespace` is the Kalman filter, its
likelihood, the smoother and the simulation smoother;
:mod:`~identification.estimation.likelihood` fits a model written on it (its
parameter map, its system for given parameters) by maximum likelihood, with
the Hessian and the covariance of the estimates.  The tunnel's ``ml`` method and
the ``flight`` method are two such models.
"""
