"""Studies behind the docs, apart from the solve pipeline: the boresight error of classic
star arrangements (``pointing``, docs/pointing.md) and the sensitivity of the celestial fix to
tilt and star errors (``locate``, docs/locate.md)."""
