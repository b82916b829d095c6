"""What one image, one worker process and the service may take, set where they are checked
(``starnav.detect.read``, ``starnav.runtime.pools.limit_memory``, ``starnav.service``) and
offered as options (``starnav serve --max-pixels-mp --max-job-mb --max-queued
--url-timeout``), written once here: a light module, which the command line's parser reads
without loading the readers or the web stack."""

MAX_PIXELS = 200_000_000  # the largest real sensors (100-200 MP); callers may set another
MAX_BYTES_PER_PIXEL = 6  # decoded: 16-bit RGB (float64 grey, 8 bytes, only at 3/4 of the pixels)
DEFAULT_WORKER_MEMORY_MB = 4000.0  # a worker solving a 200 MP image (decoded, detected, written)
DEFAULT_MAX_QUEUED = 100  # jobs waiting for a worker before uploads are answered 503 busy
DEFAULT_URL_DEADLINE_S = 30.0  # a whole URL fetch: connect, TLS, request, headers, body
DEFAULT_URL_FETCHES = 4  # URL fetches at once; as many again may wait a moment for a slot
DEFAULT_MAX_UPLOAD_MB = 100.0  # the largest request body the service reads
