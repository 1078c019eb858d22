"""tagloc: fiducial-tag localization for indoor service robots whose odometry drifts.

Layers (each imports only from the ones before it): ``geometry`` -> ``frames`` -> ``camera``
-> ``tags`` -> ``mapping`` -> ``localize`` -> ``supervise`` -> ``sim`` -> ``eval`` -> ``io``
-> ``cli``.
See the README for the conventions (frame names, covariance order, quaternion order, time units).
"""

__version__ = "0.1.0"
