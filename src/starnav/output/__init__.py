"""Writers of a solve's answer for people and other programs: the FITS WCS (``wcs``), the
annotated picture (``annotate``) and the identified star map (``plot``)."""
