"""From image files to attitude: reading, star detection, rendering, WCS and annotation."""
