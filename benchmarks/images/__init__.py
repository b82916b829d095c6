"""Solving from pixels: rendered and real images, fisheyes, narrow fields, calibration."""
