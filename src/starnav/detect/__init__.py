"""Image files to star centroids: reading, background, detection, sub-pixel centroids."""
