"""starnav as an HTTP service speaking astrometry.net's nova API (``starnav serve``)."""
