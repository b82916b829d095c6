"""Kernels of the identification stage (numba; plain Python under ``NUMBA_DISABLE_JIT=1``),
one module per idea:

- ``sky``: cone searches on the catalog's RA / Dec grid and the near-star grid, the field
  cone of a set of bearings, the catalog stars a prior attitude allows (tracking);
- ``evidence``: the false-match probability: the likelihood ratios of the points'
  positions, their brightness and a triangle's sides, and the bounds a screen uses;
- ``pairing``: the one-to-one pairing of bearings with the reprojected catalog stars (an
  exact linear assignment within each contested group);
- ``hypothesis``: the test of one hypothesis (attitude, agreement, mirror check) and the
  outcomes of a test and of a search;
- ``triangles``: the catalog triangle join on the pair table;
- ``patterns``: which pairings of a 4-star pattern's stars agree edge by edge with a
  catalog pattern's (the FOV search's look-up, ``pattern4``);
- ``search``: Mortari's triangle loop over an array of star triples (screen, then verify
  the best), shared by Pyramid, Triangle and tracking.

Every decision of the verification is written here once; the Python modules (``verify``,
``pyramid``, ``tracking``, ...) call these kernels, importing the module they need when
they first need it (numba takes ~0.2 s to load). This package's own module imports none.
"""
