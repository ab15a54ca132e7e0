"""stablemarks: on-line selection of stable visual landmarks under uncertainty.

A library (geometry, maps, stereo front end, plane fitting, landmark modeling and selection, joint
EKF) and the ``stablemarks`` command built on it. The library never imports the CLI or plotting.
"""

from .errors import StablemarksError

__version__ = "0.1.0"

__all__ = ["StablemarksError", "__version__"]
