"""The sky's state over a solved frame: clear / cloudy map, altitude-azimuth cells and the
limiting magnitude reached (``starnav.sky.state``), and its picture (``starnav.sky.plot``)."""

from starnav.sky.state import Site, SkyCell, SkyState, sky_state

__all__ = ["Site", "SkyCell", "SkyState", "sky_state"]
