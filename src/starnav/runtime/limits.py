"""What one image and one worker process may take, set where they are checked
(``starnav.detect.read``, ``starnav.runtime.pools.limit_memory``) and offered as options
(``starnav serve --max-pixels-mp --max-job-mb``), written once here: a light module, which the
command line's parser reads without loading the readers."""

MAX_PIXELS = 200_000_000  # the largest real sensors (100-200 MP); callers may set another
MAX_BYTES_PER_PIXEL = 6  # decoded: 16-bit RGB (float64 grey, 8 bytes, only at 3/4 of the pixels)
DEFAULT_WORKER_MEMORY_MB = 4000.0  # a worker solving a 200 MP image (decoded, detected, written)
