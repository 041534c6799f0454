"""blackbox: identify flexible-joint stiffness from static displacements, the FE code a black box."""

__version__ = "0.1.0"
